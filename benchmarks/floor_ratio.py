"""End to end against the read floor on the kinds of bag issue 26 names, several runs.

The issue's three bags, and its ROS 1 cloud bag again with LZ4 chunks, as ROS 1's recorder
writes them with ``--lz4``.

Each bag goes through router, player (`--fast`), detector and mapper as separate processes (and
the odometry service for the lidar bag, which has no poses: its scans make them), against the
floor: `rosbags` alone reading and deserializing the same bag's sensor messages in a fresh
process (after one untimed pass, as the player has read the bag once before it times anything).
Floor and pipeline alternate, round after round, so a busy spell of this shared machine hits
both; the table gives medians, the spread of the ratio over the rounds, and each process's CPU
seconds per frame (start-up included), which says where the time goes.

    .venv/bin/python benchmarks/floor_ratio.py [--rounds 3] [--scale 1.0]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import tempfile
from pathlib import Path

from end_to_end import read_floor
from versus import ROOT, run_once

from wallmap.scene import Camera, write_scene_bag

CLOUD, IMAGE, SCAN = (f"sensor_msgs/msg/{t}" for t in ("PointCloud2", "Image", "LaserScan"))
PROCESSES = ("player", "detector", "mapper", "odometry", "router")


def write_depth_bag(path: Path, frames: int = 784) -> Path:
    """The issue's ROS 2 bag: a generated scene's 320x240 16UC1 depth images, mcap, 15 Hz."""
    write_scene_bag(
        path,
        seed=7,
        n_frames=frames,
        fmt="ros2-mcap",
        sensor="depth16",
        camera=Camera(width=320, height=240),
    )
    return path


def _write_cloud_bag(path: Path, frames: int, *, compress: bool) -> Path:
    """The issue's ROS 1 bag: a generated scene's 640x480 clouds at 30 Hz."""
    write_scene_bag(
        path,
        seed=7,
        n_frames=frames,
        fmt="ros1",
        sensor="pointcloud",
        camera=Camera(width=640, height=480),
        rate_hz=30.0,
        compress=compress,
    )
    return path


def bags(folder: Path, scale: float) -> dict[str, tuple[Path, str, bool]]:
    """The bags: name -> (path, sensor message type, poses by odometry)."""
    clouds = round(450 * scale)
    cloud = _write_cloud_bag(folder / "cloud.bag", clouds, compress=False)
    packed = _write_cloud_bag(folder / "cloud_lz4.bag", clouds, compress=True)
    depth, lidar = write_depth_bag(folder / "depth", round(784 * scale)), folder / "lidar.bag"
    write_scene_bag(
        lidar, seed=7, n_frames=round(1000 * scale), fmt="ros1", sensor="laserscan", rate_hz=15.0
    )
    return {
        "ROS 1, 640x480 PointCloud2": (cloud, CLOUD, False),
        "...the same, LZ4 chunks": (packed, CLOUD, False),
        "ROS 2 mcap, 320x240 depth 16UC1": (depth, IMAGE, False),
        "ROS 1, 2-D lidar, --odometry": (lidar, SCAN, True),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--scale", type=float, default=1.0, help="bag lengths, times the issue's")
    args = parser.parse_args()
    commit = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    floors: dict[str, list[float]] = {}
    runs: dict[str, list[dict[str, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        found = bags(Path(tmp), args.scale)
        frames = {}
        for _ in range(args.rounds):
            for name, (bag, msgtype, odometry) in found.items():
                floors.setdefault(name, []).append(read_floor(bag, msgtype))
                runs.setdefault(name, []).append(run_once(ROOT, bag, (), odometry=odometry))
                frames[name] = runs[name][-1]["frames"]
    print(f"commit {commit or '?'}, medians of {args.rounds} rounds, 2-core shared machine\n")
    print(
        "| bag | frames | floor s | pipeline s | floor / pipeline (spread) | CPU ms / frame: "
        + ", ".join(PROCESSES)
        + " |"
    )
    print("|---|---:|---:|---:|---|---|")
    for name, done in runs.items():
        ratios = sorted(f / r["seconds"] for f, r in zip(floors[name], done, strict=True))
        cpu = [
            f"{1e3 * statistics.median(r[p] for r in done) / frames[name]:.2f}"
            if p in done[0]
            else "-"
            for p in PROCESSES
        ]
        print(
            f"| {name} | {frames[name]:.0f} | {statistics.median(floors[name]):.2f} | "
            f"{statistics.median(r['seconds'] for r in done):.2f} | "
            f"{statistics.median(ratios):.2f} ({ratios[0]:.2f}-{ratios[-1]:.2f}) | "
            f"{', '.join(cpu)} |"
        )


if __name__ == "__main__":
    main()
