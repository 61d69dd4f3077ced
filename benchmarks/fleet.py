"""A fleet of two robots in one building: B's frame found by the walls, the fused map scored.

Part 1, per scene kind (``benchmarks/accuracy.py``'s) and seed: robot A a depth camera (ROS 2
mcap, the kind's camera; its map frame the world's), robot B a 2-D lidar driving the route the
other way, its poses in a frame at its own start (``wallmap scene --reverse --own-frame``); each
bag mapped offline (``wallmap.offline``, the services' code), the two maps handed to the merge
service's ``Fleet``. Printed: where B's frame
was found against where the scene put it, the fused map against the truth (precision, recall,
duplicates, as ``benchmarks/accuracy.py`` scores a map), and each map alone.

Part 2, the cost: two maps of about 200 walls (ten generated buildings side by side, B's 90 %
of the walls in a frame of its own, ends 1 cm off): aligning them from nothing, and an update
(A's map again with five walls seen once more: read, placed, fused, ids given), medians of 5.

    .venv/bin/python benchmarks/fleet.py [--kinds non-manhattan,corridor] [--seeds 600,601,602]
        [--frames 1000]
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from wallmap.common.map_alignment import Walls, align
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply, WallRecord
from wallmap.evaluation import evaluate_map
from wallmap.offline import run_bag
from wallmap.scene import load_truth, write_scene_bag
from wallmap.scene.bags import load_map_in_world
from wallmap.scene.floorplan import generate_floorplan
from wallmap.scene.kinds import SCENE_KINDS
from wallmap.services.mapper import serving
from wallmap.services.merge.fleet import Fleet


def one_building(kind: str, seed: int, frames: int, folder: Path) -> str:
    """A table row: both robots' bags of one building of a scene kind mapped, merged, scored."""
    bag_a, bag_b = folder / f"{kind}-a{seed}", folder / f"{kind}-b{seed}.bag"
    recipe = SCENE_KINDS[kind]
    scene = {"seed": seed, "n_frames": frames, "plan": recipe.plan(seed)}
    write_scene_bag(bag_a, **scene, fmt="ros2-mcap", sensor="depth16", camera=recipe.camera)
    write_scene_bag(bag_b, **scene, fmt="ros1", sensor="laserscan", reverse=True, own_frame=True)
    plan, _, seen_a = load_truth(Path(f"{bag_a}.truth.json"))
    _, _, seen_b = load_truth(Path(f"{bag_b}.truth.json"))
    replies = {
        robot: serving.reply(run_bag(bag).map, MapQuery(trajectory=True))
        for robot, bag in (("A", bag_a), ("B", bag_b))
    }
    fleet = Fleet(["A", "B"])
    for robot, reply in replies.items():
        fleet.take(robot, reply)
    fleet.update()
    found = fleet.robots["B"].alignment
    truth = np.array(load_map_in_world(Path(f"{bag_b}.truth.json")))
    seen = {k: seen_a.get(k, 0) + seen_b.get(k, 0) for k in set(seen_a) | set(seen_b)}
    fused = evaluate_map(fleet.reply(MapQuery()).walls, plan, seen)
    alone = evaluate_map(replies["A"].walls, plan, seen_a)
    if found is None:
        where = "not aligned | | "
    else:
        error = found.pose - truth
        turn = abs(math.degrees(math.remainder(error[2], 2 * math.pi)))
        where = f"{np.hypot(*error[:2]) * 100:.2f} | {turn:.3f} | {found.runner_up:.2f}"
    return (
        f"| {kind} | {seed} | {len(replies['A'].walls)} / {len(replies['B'].walls)} | {where} | "
        f"{fused.precision:.3f} | {fused.recall:.3f} | {fused.duplicates} | "
        f"{alone.recall:.3f} |"
    )


def _records(segments: np.ndarray) -> tuple[WallRecord, ...]:
    return tuple(WallRecord.from_segment(k, p, q, n_obs=10) for k, (p, q) in enumerate(segments))


def cost(rounds: int = 5) -> tuple[int, int, float, float]:
    """Walls of A and B, and the median seconds of an alignment and of a fusion."""
    world = np.concatenate(
        [
            np.array([[w.p0, w.p1] for w in generate_floorplan(s).walls])
            + np.array([35.0 * s, 0.0])
            for s in range(10)
        ]
    )
    rng = np.random.default_rng(0)
    frame = np.array([12.0, -7.0, 2.2])
    c, s = math.cos(frame[2]), math.sin(frame[2])
    keep = rng.random(len(world)) < 0.9
    mine = (world[keep] - frame[:2]) @ np.array([[c, -s], [s, c]])
    mine += rng.normal(0.0, 0.01, mine.shape)
    aligning, fusing = [], []
    for _ in range(rounds):
        started = time.perf_counter()
        align(Walls.of(world), Walls.of(mine))
        aligning.append(time.perf_counter() - started)
    fleet = Fleet(["A", "B"])
    walls = _records(world)
    fleet.take("A", MapReply(frames=1, walls=walls))
    fleet.take("B", MapReply(frames=1, walls=_records(mine)))
    fleet.update()  # aligns
    for k in range(rounds):  # A's map again, five walls seen once more: an update
        seen = {*range(5 * k, 5 * k + 5)}
        walls = tuple(replace(w, n_obs=w.n_obs + 1) if w.id in seen else w for w in walls)
        fleet.take("A", MapReply(frames=2 + k, walls=walls))
        started = time.perf_counter()
        fleet.update()
        fusing.append(time.perf_counter() - started)
    return len(world), len(mine), statistics.median(aligning), statistics.median(fusing)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="600,601,602")
    parser.add_argument("--kinds", default="non-manhattan", help="scene kinds, comma-separated")
    parser.add_argument("--frames", type=int, default=1000)
    args = parser.parse_args()
    print(
        "| scene | seed | walls A / B | B's frame off (cm) | turned (deg) | runner-up | "
        "precision | recall | duplicates | recall of A alone |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds.split(","):
            for seed in (int(s) for s in args.seeds.split(",")):
                print(one_building(kind, seed, args.frames, Path(tmp)), flush=True)
    walls_a, walls_b, aligning, fusing = cost()
    print(
        f"\ncost: {walls_a} walls and {walls_b} walls aligned in {aligning:.3f} s (target 1 s), "
        f"fused again in {fusing * 1e3:.1f} ms (target 20 ms), medians of 5"
    )


if __name__ == "__main__":
    main()
