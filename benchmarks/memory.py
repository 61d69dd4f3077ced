"""Memory of each service over a long bag: resident size sampled from /proc while it plays.

Several generated scenes are played one after the other into the same router, mapper and
detector (one drive is too short to show growth); each process's resident set size is sampled
every 0.2 s. Flat means the peak stays near the level reached after the first bag. Then one
player plays one long 640x480 cloud bag (gigabytes, read through its memory map): the pages it
reads must not stay in its resident set.

    .venv/bin/python benchmarks/memory.py [--bags 4] [--frames 600] [--cloud-frames 300]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from wallmap.launcher import free_loopback_port
from wallmap.scene import Camera, write_scene_bag


def rss_mb(pid: int) -> float:
    """Resident set size of a process in MB (0 once it has exited)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except FileNotFoundError:
        pass
    return 0.0


def sample(pids: dict[str, int], out: dict[str, list[float]], stop: threading.Event) -> None:
    while not stop.wait(0.2):
        for name, pid in pids.items():
            out[name].append(rss_mb(pid))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bags", type=int, default=4, help="scenes played one after the other")
    parser.add_argument("--frames", type=int, default=600)
    parser.add_argument("--cloud-frames", type=int, default=300, help="the long cloud bag's")
    args = parser.parse_args()
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    wallmap = [sys.executable, "-m", "wallmap"]
    zenoh = ["--connect", endpoint]
    with tempfile.TemporaryDirectory() as tmp:
        bags = [
            write_scene_bag(
                Path(tmp) / f"s{i}.bag",
                seed=900 + i,
                n_frames=args.frames,
                fmt="ros1",
                sensor="depth16",
            ).path
            for i in range(args.bags)
        ]
        procs = {"router": subprocess.Popen([*wallmap, "router", "--listen", endpoint])}
        procs |= {n: subprocess.Popen([*wallmap, n, *zenoh]) for n in ("mapper", "detector")}
        series: dict[str, list[float]] = {n: [] for n in (*procs, "player")}
        after_first: dict[str, float] = {}
        stop = threading.Event()
        pids = {n: p.pid for n, p in procs.items()}
        sampler = threading.Thread(target=sample, args=(pids, series, stop), daemon=True)
        sampler.start()
        frames = 0
        cloud = write_scene_bag(
            Path(tmp) / "cloud.bag",
            seed=7,
            n_frames=args.cloud_frames,
            fmt="ros1",
            sensor="pointcloud",
            camera=Camera(width=640, height=480),
        ).path
        try:
            for i, bag in enumerate(bags):
                player = subprocess.Popen(
                    [*wallmap, "player", str(bag), "--fast", *zenoh], stdout=subprocess.PIPE
                )
                pids["player"] = player.pid
                player.wait()
                frames += args.frames
                if i == 0:  # the last sample of each while alive (a player's ends at 0)
                    after_first = {n: v[-1] for n, s in series.items() if (v := _alive(s))}
            long_play = play_one(cloud, zenoh, pids, series)
        finally:
            stop.set()
            sampler.join()
            for proc in reversed(list(procs.values())):
                proc.terminate()
                proc.wait()
    print(f"{frames} frames in {len(bags)} bags, RSS in MB")
    print(f"{'service':<9} {'after bag 1':>12} {'peak':>8} {'at the end':>11}")
    for name, samples in series.items():
        if alive := _alive(samples):
            first = after_first.get(name, alive[0])
            print(f"{name:<9} {first:>12.1f} {max(alive):>8.1f} {alive[-1]:>11.1f}")
    half, peak, end = long_play
    print(f"\none player, {args.cloud_frames} frames of 640x480 clouds in one bag, RSS in MB")
    print(f"{'half way':>9} {'peak':>8} {'at the end':>11}")
    print(f"{half:>9.1f} {peak:>8.1f} {end:>11.1f}")


def play_one(
    bag: Path, zenoh: list[str], pids: dict[str, int], series: dict[str, list[float]]
) -> tuple[float, float, float]:
    """The player's RSS over one bag: half way through its samples, at its peak, and last.

    Sampled into a list of its own, put in the sampler's way for the while: the table above is
    of the depth bags' players.
    """
    depth_players, series["player"] = series["player"], []
    player = subprocess.Popen(
        [sys.executable, "-m", "wallmap", "player", str(bag), "--fast", *zenoh],
        stdout=subprocess.PIPE,
    )
    pids["player"] = player.pid
    player.wait()
    samples, series["player"] = series["player"], depth_players
    alive = _alive(samples)
    return alive[len(alive) // 2], max(alive), alive[-1]


def _alive(samples: list[float]) -> list[float]:
    """The samples taken while the process lived (``rss_mb`` gives 0 once it has exited)."""
    return [v for v in samples if v > 0]


if __name__ == "__main__":
    main()
