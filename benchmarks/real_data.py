"""Real scan-only recordings mapped with poses from `wallmap odometry`, and its gain on drift.

Part 1, the real bags of ../shared/data/real (no poses, no ground truth): per bag, the scans
integrated, the share of scan points (placed with the estimated poses) within 5 cm of a mapped
wall, duplicate walls (within 3 degrees and 10 cm, extents overlapping), the angle between the
two longest walls, and the time per scan; a picture of each map. Bags that cannot be mapped
are listed with the player's one-line reason.

Part 2, generated lidar scenes with drifting wheel odometry (/odom) and ground truth: the map
and the poses with the odometry, with scan matching alone, and with scan matching held onto the
mapped walls.

Both run the services' code in one process (`wallmap.offline.map_bag`, the walls fed back after
every frame); tests/e2e/test_real_data.py runs the same bags through the real services.

    .venv/bin/python benchmarks/real_data.py [--out docs/figures] [--seeds 600,601,602]
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from wallmap.common.map_consistency import (
    MappedWall,
    angle_between,
    distance_to_walls,
    duplicates,
)
from wallmap.common.map_query import MapQuery
from wallmap.common.messages import Pose
from wallmap.common.se2 import transform_points
from wallmap.config import configured
from wallmap.evaluation import evaluate_map
from wallmap.offline import map_bag, scan_rows
from wallmap.plot import write_picture
from wallmap.scene import load_truth, write_scene_bag
from wallmap.services.mapper import serving
from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.errors import PlayerError

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def real_bags(out: Path | None) -> None:
    """Part 1: one row per real bag."""
    print(
        f"{'bag':<36} {'walls':>6} {'scans':>9} {'on walls':>9} {'dups':>5} {'longest':>12}"
        f" {'angle':>6} {'ms/scan':>8}"
    )
    for bag in sorted(REAL.glob("*")):
        if bag.name == "README.md" or (bag.is_dir() and not (bag / "metadata.yaml").exists()):
            continue  # rgbd/ holds depth recordings: benchmarks/real_rgbd.py maps them
        try:
            with BagSource(bag, pose_source="none") as source:
                n_scans = source.frame_count
        except PlayerError as err:
            print(f"{bag.name:<36} not mapped: {err}")
            continue
        for use_walls in (False, True):
            poses: list[Pose] = []
            start = time.perf_counter()
            config = configured("up.odometry=true", f"odometry.use_walls={str(use_walls).lower()}")
            wall_map = map_bag(bag, config, poses=poses)
            per_scan = (time.perf_counter() - start) / max(n_scans, 1) * 1e3
            reply = serving.reply(wall_map, MapQuery(trajectory=True))
            walls = [MappedWall.from_reply(w) for w in reply.walls]
            placed = {p.stamp: (p.x, p.y, p.yaw) for p in poses}
            distance = np.concatenate(
                [
                    distance_to_walls(transform_points(xy, placed[t]), walls)
                    for t, xy in scan_rows(bag)
                ]
            )
            longest = sorted(walls, key=lambda w: -w.length)[:2]
            angle = angle_between(*longest) if len(longest) == 2 else math.nan
            label = f"{bag.name} ({'walls' if use_walls else 'no walls'})"
            print(
                f"{label:<36} {len(walls):>6} {wall_map.frames:>4}/{n_scans:<4}"
                f" {np.mean(distance <= 0.05):>9.1%} {len(duplicates(walls)):>5}"
                f" {'/'.join(f'{w.length:.1f}' for w in longest):>12} {angle:>6.2f}"
                f" {per_scan:>8.1f}"
            )
            if out is not None and use_walls:
                write_picture(out / f"real-{bag.stem}.png", reply, size=700)


def drift(seeds: list[int], frames: int) -> None:
    """Part 2: generated lidar scenes, pooled over the seeds."""
    rows: dict[str, list[tuple[object, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            bag = Path(tmp) / f"lidar-{seed}.bag"
            info = write_scene_bag(bag, seed=seed, n_frames=frames, fmt="ros1", sensor="laserscan")
            plan, trajectory, seen = load_truth(info.truth_path)
            start = trajectory.pose_at(0)
            tracked = ("up.odometry=true", f"odometry.initial_pose={list(start)}")
            for label, settings in (
                ("wheel odometry (/odom)", ("player.source.pose_source=odom",)),
                ("scan matching", (*tracked, "odometry.use_walls=false")),
                ("scan matching + walls", tracked),
                ("true poses (tf)", ("player.source.pose_source=tf",)),
            ):
                poses: list[Pose] = []
                wall_map = map_bag(bag, configured(*settings), poses=poses)
                score = evaluate_map(serving.reply(wall_map).walls, plan, seen)
                index = [int(np.argmin(np.abs(trajectory.stamps - p.stamp))) for p in poses]
                error = statistics.median(
                    math.hypot(p.x - trajectory.x[i], p.y - trajectory.y[i])
                    for p, i in zip(poses, index, strict=True)
                )
                rows.setdefault(label, []).append((score, error))
    print(f"\nseeds {','.join(map(str, seeds))}, {frames} frames each, medians over the seeds")
    print(
        f"{'poses':<24} {'precision':>9} {'recall':>7} {'dups':>5} {'offset cm':>10}"
        f" {'angle deg':>10} {'pose error cm':>14}"
    )
    for label, results in rows.items():
        scores = [s for s, _ in results]
        print(
            f"{label:<24}"
            f" {statistics.median(s.precision for s in scores):>9.3f}"
            f" {statistics.median(s.recall for s in scores):>7.3f}"
            f" {sum(s.duplicates for s in scores):>5}"
            f" {statistics.median(s.median_offset_m for s in scores) * 100:>10.2f}"
            f" {statistics.median(s.median_angle_deg for s in scores):>10.2f}"
            f" {statistics.median(e for _, e in results) * 100:>14.2f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="write a picture of each real bag's map here")
    parser.add_argument("--seeds", default="600,601,602", help="generated scenes for part 2")
    parser.add_argument("--frames", type=int, default=600, help="frames per generated scene")
    args = parser.parse_args()
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    if REAL.is_dir():
        real_bags(args.out)
    else:
        print(f"no real recordings at {REAL}: part 1 skipped")
    drift([int(s) for s in args.seeds.split(",")], args.frames)


if __name__ == "__main__":
    main()
