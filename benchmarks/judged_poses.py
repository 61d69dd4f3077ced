"""Poses as real systems give them: the map with its poses judged against the walls, and without.

Part 1, the real Jackal run of ../shared/data/real (motion-capture poses, a few tens of ms off,
about a degree noisy; no ground truth): walls, fans (one surface mapped twice), the share of scan
points within 5 cm of a wall (placed with the poses the map used, as its trajectory gives them),
what the judge found, and the mapper's time per frame, judged and taken as they come, side by
side in one run. With ``--out``, a picture of each map over its scans.

Part 2, generated scenes whose poses are late, noisy and glitching, from each kind of pose
source the bag carries: precision, recall, duplicates, median offset against the scene's truth,
and the latency found.

Both run the services' code in one process (``wallmap.offline``); tests/e2e/test_judged_poses.py
runs the same cases through the real services.

    .venv/bin/python benchmarks/judged_poses.py [--out docs/figures]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from wallmap.common.map_consistency import MappedWall, distance_to_walls, fans
from wallmap.common.map_query import MapQuery
from wallmap.common.messages import Frame
from wallmap.common.se2 import transform_points
from wallmap.config import Config
from wallmap.evaluation import evaluate_map
from wallmap.offline import pipeline_for, played, scan_rows
from wallmap.plot import write_picture
from wallmap.scene import Glitch, PoseFaults, load_truth, write_scene_bag
from wallmap.scene.bags import tum_path_for
from wallmap.services.mapper import serving
from wallmap.services.mapper.pose_buffer import Lookup
from wallmap.services.pipeline import Pipeline

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
JACKAL = REAL / "jackal_arena_2026-02-17-15-54-31"
MOCAP = "pose:/vrpn_client_node/jackal/pose"


def configured(source: str | None, *, judged: bool = True, odometry: bool = False) -> Config:
    """The default configuration with a pose source, judged or not, or scan-matching odometry."""
    config = Config()
    judge = replace(config.mapper.judge, enabled=judged)
    player = replace(config.player, source=replace(config.player.source, pose_source=source))
    return replace(
        config,
        mapper=replace(config.mapper, judge=judge),
        player=player,
        up=replace(config.up, odometry=odometry),
    )


def timed_run(bag: Path, config: Config) -> tuple[Pipeline, list[float]]:
    """The recording through the pipeline as ``wallmap.offline.run_bag`` runs it, timing the
    mapper's part of each frame (pose lookup, judgement, map update) apart from detection."""
    pipeline = pipeline_for(config)
    mapper_ms: list[float] = []
    for message in played(bag, config, pipeline):
        if pipeline.tracker is None:
            _mapper_step(pipeline, message, mapper_ms)
        else:
            pipeline.step(message)
    return pipeline, mapper_ms


def _mapper_step(pipeline: Pipeline, frame: Frame, mapper_ms: list[float]) -> None:
    """One frame: detected, then mapped with the mapper's part timed."""
    observations = pipeline.detector.detect(frame)
    start = time.perf_counter()
    mapping = pipeline.mapping
    source = mapping.source_pose(frame.stamp)
    if not isinstance(source, Lookup):
        mapping.integrate(observations, source)
    mapper_ms.append(1e3 * (time.perf_counter() - start))


def explained(pipeline: Pipeline, bag: Path) -> tuple[list[MappedWall], float]:
    """The served walls, and the share of scan points within 5 cm of one, placed with the
    map's trajectory (interpolated at each scan, as a user of the map reply would)."""
    reply = serving.reply(pipeline.map, MapQuery(trajectory=True))
    walls = [MappedWall.from_reply(w) for w in reply.walls]
    stamps, x, y, yaw = np.array(reply.trajectory).T
    yaw = np.unwrap(yaw)
    near = []
    for stamp, xy in scan_rows(bag):
        pose = [float(np.interp(stamp, stamps, v)) for v in (x, y, yaw)]
        near.append(distance_to_walls(transform_points(xy, pose), walls) <= 0.05)
    return walls, float(np.mean(np.concatenate(near)))


def jackal(out: Path | None) -> None:
    """Part 1."""
    if not JACKAL.exists():
        print(f"(skipped: {JACKAL} is absent)")
        return
    runs = [
        ("motion capture, taken as it comes", configured(MOCAP, judged=False)),
        ("motion capture, judged (default)", configured(MOCAP)),
        ("scan matching (--odometry)", configured(None, odometry=True)),
    ]
    print(
        f"{'poses':<36} {'walls':>5} {'fans':>4} {'on walls':>8} {'latency':>8} "
        f"{'heading sd':>10} {'refused':>7} {'mapper ms/frame':>15}"
    )
    for label, config in runs:
        pipeline, mapper_ms = timed_run(JACKAL, config)
        walls, share = explained(pipeline, JACKAL)
        found = pipeline.mapping.judge.summary() if pipeline.mapping.judge else {}
        latency = f"{found['latency_s'] * 1e3:+.0f} ms" if found else "-"
        if found and not found["settled"]:
            latency = "guess"
        heading = f"{found['heading_sd_deg']:.2f} deg" if found else "-"
        refused = str(found.get("frames_refused", "-"))
        ms = f"{statistics.median(mapper_ms):.2f}" if mapper_ms else "-"
        print(
            f"{label:<36} {len(walls):>5} {len(fans(walls)):>4} {share:>8.1%} {latency:>8} "
            f"{heading:>10} {refused:>7} {ms:>15}"
        )
        if out is not None:
            name = "odometry" if config.up.odometry else "judged" if found else "trusted"
            points = _placed_scans(pipeline, JACKAL)
            reply = serving.reply(pipeline.map, MapQuery(trajectory=True))
            write_picture(out / f"jackal-{name}.png", reply, points=points)


def _placed_scans(pipeline: Pipeline, bag: Path) -> np.ndarray:
    """Every tenth scan, placed with the map's trajectory."""
    stamps, x, y, yaw = np.array(pipeline.map.path()).T
    yaw = np.unwrap(yaw)
    placed = []
    for k, (stamp, xy) in enumerate(scan_rows(bag)):
        if k % 10 == 0:
            pose = [float(np.interp(stamp, stamps, v)) for v in (x, y, yaw)]
            placed.append(transform_points(xy, pose))
    return np.vstack(placed)


SOURCES = ["tf", "odom", "pose:/amcl_pose", "tum"]  # odom also drifts (2 %, 1 deg/m): see --slam


def generated(latencies: list[float]) -> None:
    """Part 2."""
    print(
        f"{'source':<16} {'late':>6} {'found':>7} {'precision':>9} {'recall':>6} "
        f"{'dups':>4} {'offset':>7} {'recovered':>9} {'refused':>7}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for latency in latencies:
            faults = PoseFaults(
                latency=latency, heading_sd_deg=0.5, glitches=(Glitch(15, 3, 12, 0.1),), seed=3
            )
            info = write_scene_bag(
                Path(tmp) / f"late{latency}.bag",
                seed=3,
                n_frames=600,
                fmt="ros1",
                sensor="depth16",
                faults=faults,
            )
            plan, _, seen = load_truth(info.truth_path)
            for kind in SOURCES:
                spec = f"tum:{tum_path_for(info.path)}" if kind == "tum" else kind
                pipeline, _ = timed_run(info.path, configured(spec))
                reply = serving.reply(pipeline.map, MapQuery())
                score = evaluate_map(list(reply.walls), plan, seen)
                found = pipeline.mapping.judge.summary()
                print(
                    f"{kind:<16} {latency * 1e3:>4.0f}ms {found['latency_s'] * 1e3:>5.0f}ms "
                    f"{score.precision:>9.3f} {score.recall:>6.3f} {score.duplicates:>4} "
                    f"{score.median_offset_m * 100:>5.1f}cm {found['frames_recovered']:>9} "
                    f"{found['frames_refused']:>7}",
                    flush=True,
                )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="write the Jackal's pictures into this folder")
    parser.add_argument("--latencies", default="0.03,0.08,0.15", help="generated scenes' (s)")
    args = parser.parse_args()
    print("== the real Jackal run")
    jackal(args.out)
    print("\n== generated scenes, poses late, 0.5 deg noisy, 3 s 12 deg and 10 cm off")
    generated([float(v) for v in args.latencies.split(",")])


if __name__ == "__main__":
    main()
