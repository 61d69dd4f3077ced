"""Mapping accuracy per kind of scene, with true poses and with drifting odometry.

Each scene kind (see ``wallmap.scene.SCENE_KINDS``) is generated for every seed,
recorded as a ROS 1 bag of 16-bit depth images, mapped in one process by the real detector
and mapper (``wallmap.offline.run_bag``) and scored against its ground truth: the walls,
and the rooms and doors where the scene has room truth (``wallmap.room_evaluation``). The
seeds default to 500-502, away from the ones the detector and mapper were tuned on (1-9) and
the ones the tests use. Results are in docs/accuracy.md.

    .venv/bin/python benchmarks/accuracy.py [--frames N] [--scenes a,b] [--seeds 500,501]
        [--poses tf,odom,slam] [--detector-noise-k K] [--set SECTION.KEY=VALUE] [--jobs 2]
        [--details] [--quick]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from wallmap.config import configured
from wallmap.evaluation import MapScore, evaluate_map
from wallmap.offline import rooms, run_bag, walls
from wallmap.room_evaluation import RoomScore, evaluate_rooms
from wallmap.scene import (
    SCENE_KINDS,
    FloorPlan,
    SceneInfo,
    load_truth,
    truth_path_for,
    write_scene_bag,
)

POSE_SOURCES = ("tf", "odom", "slam")
HEADER = """\
One row per scene kind and pose source, summed or taken the median over the seeds.
  poses      tf: true poses (map -> odom -> base_link); odom: drifting odometry alone
             (about 2 % and 1 deg per metre), scored in the map frame all the same;
             slam: the same odometry, corrected by the walls (wallmap mapper --slam)
  precision  mapped walls matching a true wall / mapped walls (pooled over the seeds)
  recall     true non-glass walls seen in >= 3 frames and matched / such walls (pooled)
  dups       true walls matched by two or more mapped walls (summed)
  angle      median angle error of the best matches, degrees (median over the seeds)
  offset     median offset error of the best matches, cm (median over the seeds)
  end pt     median end-point error of the best matches, cm (median over the seeds)
  mapped     walls served (offline.walls: confirmed ones) / true walls required for recall
  frames     depth frames mapped (summed); s: seconds spent mapping them (summed)
A match is within 5 deg and 15 cm; see wallmap/evaluation.py for the rules."""


@dataclass(frozen=True)
class Result:
    """One mapped bag, scored."""

    kind: str
    seed: int
    poses: str
    score: MapScore
    rooms: RoomScore | None  # None: the scene has no room truth
    frames: int
    seconds: float
    details: str


def _describe(score: MapScore, plan: FloorPlan, seen: dict[int, int]) -> str:
    """The walls that went wrong, with what makes them hard: length and frames seen."""
    by_id = {w.id: w for w in plan.walls}
    missed = ", ".join(
        f"{i} ({by_id[i].length:.1f} m, seen {seen.get(i, 0)})" for i in score.unmatched_true
    )
    return f"missed: {missed or '-'}; false: {score.unmatched_mapped or '-'}"


def run_scene(
    kind_name: str,
    seed: int,
    frames: int,
    poses: Sequence[str],
    settings: tuple[str, ...] = (),
    bags: Path | None = None,
    drift: tuple[float, float] = (0.02, 1.0),
) -> list[Result]:
    """Record one scene (or reuse it from ``bags``) and map it once per pose source."""
    kind = SCENE_KINDS[kind_name]
    with tempfile.TemporaryDirectory() as tmp:
        tag = "" if drift == (0.02, 1.0) else f"-drift{drift[0]:g},{drift[1]:g}"
        path = (bags or Path(tmp)) / f"{kind_name}-{seed}-{frames}{tag}.bag"
        if path.exists():
            plan, trajectory, seen = load_truth(truth_path_for(path))
            info = SceneInfo(path, truth_path_for(path), len(trajectory), plan, trajectory, seen)
        else:
            info = write_scene_bag(
                path,
                seed=seed,
                n_frames=frames,
                fmt="ros1",
                sensor="depth16",
                camera=kind.camera,
                plan=kind.plan(seed),
                odometry_drift=drift,
            )
        results = []
        for pose_source in poses:
            start = time.perf_counter()
            source = "odom" if pose_source == "slam" else pose_source
            config = configured(
                *settings,
                f"player.source.pose_source={source}",
                f"mapper.slam.enabled={str(pose_source == 'slam').lower()}",
            )
            pipeline = run_bag(info.path, config)
            seconds = time.perf_counter() - start
            score = evaluate_map(walls(pipeline.map), info.plan, info.seen_counts)
            details = _describe(score, info.plan, info.seen_counts)
            path = info.trajectory.positions
            room_score = (
                evaluate_rooms(
                    rooms(pipeline).to_map(), info.plan, path, pipeline.mapping.rooms.free
                )
                if info.plan.rooms
                else None
            )
            results.append(
                Result(
                    kind_name, seed, pose_source, score, room_score, info.n_frames, seconds, details
                )
            )
    return results


def _median(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return statistics.median(finite) if finite else math.nan


def table_row(kind: str, poses: str, results: Sequence[Result]) -> str:
    """A markdown table row for one (scene kind, pose source) over its seeds."""
    scores = [r.score for r in results]
    n_mapped = sum(s.n_mapped for s in scores)
    n_true = sum(s.n_true for s in scores)
    precision = sum(s.n_mapped_matched for s in scores) / n_mapped if n_mapped else 1.0
    recall = sum(s.n_true_matched for s in scores) / n_true if n_true else 1.0
    cells = [
        kind,
        poses,
        f"{precision:.3f}",
        f"{recall:.3f}",
        str(sum(s.duplicates for s in scores)),
        f"{_median([s.median_angle_deg for s in scores]):.2f}",
        f"{100 * _median([s.median_offset_m for s in scores]):.1f}",
        f"{100 * _median([s.median_endpoint_m for s in scores]):.1f}",
        f"{n_mapped}/{n_true}",
        str(sum(r.frames for r in results)),
        f"{sum(r.seconds for r in results):.1f}",
    ]
    return "| " + " | ".join(cells) + " |"


ROOMS_HEADER = """\
Rooms and doors (docs/rooms.md), for the scenes with room truth, pooled over the seeds:
  entered    rooms the robot entered (its path passes inside) found / entered
  IoU        of each entered room with the room it is matched to (0 if none): min, median
  seen       of each entered room's floor, the share within 0.3 m of floor the sensor saw free
             (rooms are made of seen floor, an open room's filled out up to 1.5 m towards the
             walls it faces: a room seen in part is served in part): min, median
  false      served rooms matching no true room; split: a second served room over one
  doors      true doors between entered rooms found (centre within 0.5 m) / such doors;
             joined: of those, joining the right rooms; centre, width: the largest errors, m"""


def rooms_row(kind: str, poses: str, results: Sequence[Result]) -> str:
    """A markdown table row of the rooms and doors of one (scene kind, pose source)."""
    scores = [r.rooms for r in results if r.rooms is not None]
    ious = [v for s in scores for v in s.entered_ious]
    seen = [v for s in scores for v in s.seen.values()]
    cells = [
        kind,
        poses,
        f"{sum(v > 0 for v in ious)}/{len(ious)}",
        f"{min(ious, default=math.nan):.2f}",
        f"{_median(ious):.2f}",
        f"{min(seen, default=math.nan):.2f}",
        f"{_median(seen):.2f}",
        str(sum(s.false for s in scores)),
        str(sum(s.split for s in scores)),
        f"{sum(s.doors_found for s in scores)}/{sum(s.truth_doors for s in scores)}",
        str(sum(s.doors_joined for s in scores)),
        f"{max((s.centre_err for s in scores), default=math.nan):.2f}",
        f"{max((s.width_err for s in scores), default=math.nan):.2f}",
    ]
    return "| " + " | ".join(cells) + " |"


def print_table(
    columns: str,
    kinds: Sequence[str],
    poses: Sequence[str],
    results: Sequence[Result],
    row: Callable[[str, str, Sequence[Result]], str],
) -> None:
    """A markdown table, one ``row`` per scene kind and pose source after scene and poses."""
    print(f"| scene | poses | {columns} |")
    print("|---|---|" + "---|" * (columns.count("|") + 1))
    for kind in kinds:
        for pose_source in poses:
            print(
                row(
                    kind,
                    pose_source,
                    [r for r in results if (r.kind, r.poses) == (kind, pose_source)],
                )
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600, help="frames per scene (600)")
    parser.add_argument("--scenes", default=",".join(SCENE_KINDS), help="scene kinds")
    parser.add_argument("--seeds", default="500,501,502", help="one scene of each kind per seed")
    parser.add_argument("--poses", default=",".join(POSE_SOURCES), help="pose sources")
    parser.add_argument(
        "--detector-noise-k",
        type=float,
        help="depth noise the detector assumes (default: its own, a Kinect's 1.425e-3)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="a configuration key for every map (as wallmap --set), repeatable",
    )
    parser.add_argument(
        "--odom-drift",
        default="0.02,1.0",
        help="how /odom drifts: position error per metre, heading error in degrees per metre",
    )
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--details", action="store_true", help="list the walls that went wrong")
    parser.add_argument("--quick", action="store_true", help="smoke run: 150 frames, one seed")
    parser.add_argument("--bags", type=Path, help="keep the scene bags here and reuse them")
    args = parser.parse_args()
    kinds = args.scenes.split(",")
    unknown = sorted(set(kinds) - set(SCENE_KINDS))
    if unknown:
        parser.error(f"unknown scene kind {unknown[0]!r}; known: {', '.join(SCENE_KINDS)}")
    seeds = [int(s) for s in args.seeds.split(",")]
    frames = args.frames
    if args.quick:
        seeds, frames = seeds[:1], min(frames, 150)
    poses = args.poses.split(",")
    drift_xy, drift_yaw = (float(v) for v in args.odom_drift.split(","))
    settings = tuple(args.set)
    if args.detector_noise_k is not None:
        settings += (f"detector.ransac.noise_k={args.detector_noise_k!r}",)

    if args.bags:
        args.bags.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = {
            (kind, seed): pool.submit(
                run_scene, kind, seed, frames, poses, settings, args.bags, (drift_xy, drift_yaw)
            )
            for kind in kinds
            for seed in seeds
        }
        results = [r for future in futures.values() for r in future.result()]

    print(HEADER)
    assumed = "default" if args.detector_noise_k is None else f"{args.detector_noise_k:g}"
    print(f"Seeds {','.join(map(str, seeds))}, up to {frames} frames per scene, ", end="")
    print(f"detector noise_k {assumed}, odometry drift {args.odom_drift}.\n")
    columns = (
        "precision | recall | dups | angle ° | offset cm | end pt cm | mapped/true | frames | s"
    )
    print_table(columns, kinds, poses, results, table_row)
    with_rooms = [k for k in kinds if any(r.rooms for r in results if r.kind == k)]
    if with_rooms:
        print(f"\n{ROOMS_HEADER}\n")
        columns = (
            "entered | IoU min | IoU median | seen min | seen median | false | split | doors | "
            "joined | centre m | width m"
        )
        print_table(columns, with_rooms, poses, results, rooms_row)
    if args.details:
        print()
        for r in results:
            rooms_line = f"; {r.rooms.summary()}" if r.rooms else ""
            print(f"{r.kind} seed {r.seed} {r.poses}: {r.details}{rooms_line}")
    print(f"\n{time.perf_counter() - start:.0f} s in all, {args.jobs} jobs")


if __name__ == "__main__":
    main()
