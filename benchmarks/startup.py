"""Start-up of each service: seconds from launching its process to its being ready.

Ready means: the router accepts a TCP connection on its port; the mapper and the detector have
logged ``ready:`` (subscribed, and the detector's compiled loops loaded); the player has opened
its bag, surveyed it, asked the detector which rows to send and logged ``sending`` (in real
time, and with ``--fast``, which loads the band stack's compiled loop first). Each is
started ``--rounds`` times beside a running router (the player also beside a mapper and a
detector); the table gives the median and the spread. numba's cache is warm, as it is after
``make`` (a machine's first detector compiles the loops once, about 10 s).

    .venv/bin/python benchmarks/startup.py [--rounds 5]
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from wallmap.launcher import free_loopback_port
from wallmap.scene import Camera, write_scene_bag

WALLMAP = [sys.executable, "-m", "wallmap"]
ENV = {**os.environ, "WALLMAP_LOG": "INFO"}


def until_line(
    command: list[str], marker: str, timeout: float = 60.0
) -> tuple[float, subprocess.Popen[str]]:
    """Launch ``command``; the seconds until a line of its log holds ``marker``."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        command, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=ENV
    )
    assert proc.stderr is not None
    for line in proc.stderr:
        if marker in line:
            return time.perf_counter() - start, proc
        if time.perf_counter() - start > timeout:
            break
    proc.kill()
    raise SystemExit(f"{' '.join(command)} never logged {marker!r}")


def router_ready(port: int) -> tuple[float, subprocess.Popen[str]]:
    """Launch a router on ``port``; the seconds until the port takes a connection."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        [*WALLMAP, "router", "--listen", f"tcp/127.0.0.1:{port}"],
        stderr=subprocess.DEVNULL,
        text=True,
    )
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.05).close()
            return time.perf_counter() - start, proc
        except OSError:
            time.sleep(0.005)


def stop(*procs: subprocess.Popen[str]) -> None:
    """End the processes, the services before their router."""
    for proc in procs:
        proc.terminate()
        proc.wait(timeout=15)


def one_round(bag: Path) -> dict[str, float]:
    """Every service started once; the seconds each took to be ready."""
    port = free_loopback_port()
    connect = ["--connect", f"tcp/127.0.0.1:{port}"]
    seconds: dict[str, float] = {}
    seconds["router"], router = router_ready(port)
    seconds["mapper"], mapper = until_line([*WALLMAP, "mapper", *connect], "ready:")
    seconds["detector"], detector = until_line([*WALLMAP, "detector", *connect], "ready:")
    play = [*WALLMAP, "player", str(bag), *connect]
    seconds["player, real time"], player = until_line(play, "sending")
    stop(player)
    # --fast loads the band stack's compiled loop before its first frame (numba's 0.3 s)
    seconds["player --fast"], player = until_line([*play, "--fast"], "sending")
    stop(player, detector, mapper, router)
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "depth"
        write_scene_bag(
            bag,
            seed=7,
            n_frames=60,
            fmt="ros2-mcap",
            sensor="depth16",
            camera=Camera(width=320, height=240),
        )
        rounds = [one_round(bag) for _ in range(args.rounds)]
    print(f"seconds from launch to ready, {args.rounds} rounds (warm page cache, numba cache)\n")
    print("| service | median s | min s | max s |")
    print("|---|---:|---:|---:|")
    for name in rounds[0]:
        times = [r[name] for r in rounds]
        print(f"| {name} | {statistics.median(times):.2f} | {min(times):.2f} | {max(times):.2f} |")


if __name__ == "__main__":
    main()
