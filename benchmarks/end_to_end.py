"""End to end against the floor: a 30 Hz 640x480 PointCloud2 bag through the separate services.

The floor is what `rosbags` alone takes to read and deserialize the same clouds; the pipeline is
`wallmap player --fast` feeding a detector and a mapper (separate processes, a real router),
timed from the player's first frame to the mapper's acknowledgement of the last. Both numbers
come from the same run on the same bag, so the ratio is fair on a busy machine.

    .venv/bin/python benchmarks/end_to_end.py [--frames 90] [--repeats 3]
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rosbags.highlevel import AnyReader

from wallmap.launcher import free_loopback_port
from wallmap.scene import Camera, write_scene_bag


def read_sensor(bag: Path, msgtype: str = "sensor_msgs/msg/PointCloud2") -> float:
    """Seconds to read and deserialize every sensor message of ``msgtype``, and nothing else."""
    start = time.perf_counter()
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.msgtype == msgtype]
        for conn, _, raw in reader.messages(connections=conns):
            reader.deserialize(raw, conn.msgtype)
    return time.perf_counter() - start


def read_floor(bag: Path, msgtype: str = "sensor_msgs/msg/PointCloud2") -> float:
    """The floor, measured in a fresh process set up like the player's, after one untimed pass.

    The player reads the whole bag once (tf, poses) before it times anything, and keeps large
    buffers in the heap (``wallmap.common.allocator``), so the floor gets the same.
    """
    code = (
        "import sys, end_to_end as e; from wallmap.common.allocator import keep_large_buffers; "
        "keep_large_buffers(); p, t = e.Path(sys.argv[1]), sys.argv[2]; e.read_sensor(p, t); "
        "print(e.read_sensor(p, t))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(bag), msgtype],
        cwd=Path(__file__).parent,
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout)


def pipeline(bag: Path, whole_clouds: bool) -> tuple[float, int]:
    """Seconds the player reports for the bag with --fast, and the frames the mapper integrated."""
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    wallmap = [sys.executable, "-m", "wallmap"]
    zenoh = ["--connect", endpoint]
    procs = [subprocess.Popen([*wallmap, "router", "--listen", endpoint])]
    procs += [subprocess.Popen([*wallmap, name, *zenoh]) for name in ("mapper", "detector")]
    try:
        extra = ["--whole-clouds"] if whole_clouds else []
        out = subprocess.run(
            [*wallmap, "player", str(bag), "--fast", *extra, *zenoh],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    finally:
        for proc in reversed(procs):
            proc.terminate()
            proc.wait()
    found = re.search(r"in ([\d.]+) s .* integrated (\d+)", out)
    if not found:
        raise RuntimeError(out)
    return float(found[1]), int(found[2])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--repeats", type=int, default=3, help="runs of each, medians reported")
    parser.add_argument(
        "--compress", action="store_true", help="an LZ4 bag (the player decompresses what it reads)"
    )
    args = parser.parse_args()
    floors: list[float] = []
    runs: dict[bool, list[float]] = {False: [], True: []}
    integrated: dict[bool, list[int]] = {False: [], True: []}
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "vga.bag"
        info = write_scene_bag(
            bag,
            seed=7,
            n_frames=args.frames,
            fmt="ros1",
            sensor="pointcloud",
            camera=Camera(width=640, height=480),
            rate_hz=30.0,
            compress=args.compress,
        )
        size = bag.stat().st_size / 1e6
        for _ in range(args.repeats):  # interleaved, so a busy spell hits all of them alike
            floors.append(read_floor(bag))
            for whole in (False, True):
                seconds, frames = pipeline(bag, whole)
                runs[whole].append(seconds)
                integrated[whole].append(frames)
    floor = statistics.median(floors)
    kind = "LZ4-compressed" if args.compress else "uncompressed"
    print(
        f"{info.n_frames} frames, {kind} ROS 1 bag of {size:.0f} MB, "
        f"medians of {args.repeats} interleaved runs"
    )
    print(
        f"{'sent':<34} {'floor s':>8} {'pipeline s':>11} {'floor/pipeline':>15} {'integrated':>11}"
    )
    for whole, label in ((False, "one row per frame (negotiated)"), (True, "whole clouds")):
        seconds = statistics.median(runs[whole])
        print(
            f"{label:<34} {floor:>8.2f} {seconds:>11.2f} {floor / seconds:>15.2f}"
            f" {min(integrated[whole]):>11}"
        )


if __name__ == "__main__":
    main()
