"""Rooms and doors: found against the truth of generated buildings, and what an update costs.

Part 1: strips of three rooms joined by doorways, and kinked corridors with small rooms behind
some of their doors (``generate_floorplan``, glass in some walls, furniture below the band),
written as 320x240 depth bags, mapped offline with tf poses (``wallmap.offline``, the
services' code) and segmented as the mapper serves them. Rooms are
matched one to one with the truth by IoU of their outlines (rasterised at 5 cm); the IoU columns
are of the rooms the robot entered (the corridor's robot stays in the corridor), the door columns
of the doors between two of them (``wallmap.room_evaluation``). Part 2: one update (draw
what is new, segment, give ids) of a building of 10 x 10 rooms of 4 x 4 m off corridors, from
its true walls and the floor seen along a route through every room, median of 5: with nothing
new and the outlines of the update before kept (rooms whose cells did not change are not
outlined again); a frame later, as the live mapper's update is (the walls the frame saw moved
a centimetre, its rays drawn); and a first update (every room outlined). The issue's target is
100 rooms within 20 ms.

    .venv/bin/python benchmarks/rooms.py [--seeds 4] [--frames 900]
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wallmap.common.map_records import WallRecord
from wallmap.offline import rooms, run_bag
from wallmap.room_evaluation import evaluate_rooms
from wallmap.scene import Camera, load_truth, write_scene_bag
from wallmap.scene.floorplan import FloorPlan, Wall, free_rays, generate_floorplan
from wallmap.services.mapper.room_map import RoomMap

Array = NDArray[np.float64]


def score(seed: int, frames: int, folder: Path, layout: str) -> dict[str, float]:
    """One building mapped and segmented, against its truth."""
    bag = folder / f"{layout}{seed}.bag"
    write_scene_bag(
        bag,
        seed=seed,
        n_frames=frames,
        fmt="ros1",
        sensor="depth16",
        camera=Camera(width=320, height=240),
        plan=generate_floorplan(seed, layout=layout),
    )
    plan, trajectory, _ = load_truth(Path(f"{bag}.truth.json"))
    found = evaluate_rooms(rooms(run_bag(bag)).to_map(), plan, trajectory.positions)
    ious = found.entered_ious
    return {
        "rooms": found.rooms,
        "truth": found.truth_rooms,
        "matched": len(found.matched),
        "false": found.false,
        "split": found.split,
        "entered": sum(v > 0 for v in ious),
        "entered_truth": len(ious),
        "iou_min": min(ious, default=0.0),
        "iou_median": statistics.median(ious or [0.0]),
        "doors": found.doors,
        "door_truth": found.truth_doors,
        "doors_found": found.doors_found,
        "joined": found.doors_joined,
        "centre": found.centre_err,
        "width": found.width_err,
    }


def grid_building(n: int = 10, size: float = 4.0, door: float = 0.9) -> FloorPlan:
    """n x n rooms of ``size`` m, each with a door in its south and west wall (the outer ones
    closed), and a route through every room."""
    walls: list[Wall] = []
    wall_id = 0
    for k in range(n + 1):
        for m in range(n):
            for horizontal in (True, False):
                a = (m * size, k * size) if horizontal else (k * size, m * size)
                b = ((m + 1) * size, k * size) if horizontal else (k * size, (m + 1) * size)
                if 0 < k < n:  # an inner wall: a door in its middle
                    mid = np.add(a, b) / 2
                    along = np.subtract(b, a) / size
                    walls.append(Wall(wall_id, a, tuple(mid - along * door / 2)))
                    walls.append(Wall(wall_id + 1, tuple(mid + along * door / 2), b))
                    wall_id += 2
                else:
                    walls.append(Wall(wall_id, a, b))
                    wall_id += 1
    route = [
        ((m + 0.5) * size, (k + 0.5) * size)
        for k in range(n)
        for m in (range(n) if k % 2 == 0 else reversed(range(n)))
    ]
    return FloorPlan(walls=tuple(walls), route=tuple(route))


def update_cost(n: int = 10, rounds: int = 5) -> tuple[int, int, float, float, float]:
    """Rooms and doors of the grid building, and the median seconds of one update: with the
    outlines of the update before kept (nothing changed), a frame later (see ``_moved``), and
    a first one (every outline drawn).
    """
    plan = grid_building(n)
    records = tuple(_record(w.id, w.p0, w.p1) for w in plan.walls)
    room_map = RoomMap()
    route = np.array(plan.route)
    for a, b in itertools.pairwise(route):
        for t in np.linspace(0.0, 1.0, 12, endpoint=False):
            at = a + t * (b - a)
            room_map.add_frame(np.array([*at, 0.0]), np.zeros(2), free_rays(plan, at))
    reply = room_map.update(records, 0.0)
    again, later, first = [], [], []
    for k in range(rounds):
        started = time.perf_counter()
        room_map.update(records, 0.0)
        again.append(time.perf_counter() - started)
        at = route[(k * 37) % len(route)] + 0.3  # somewhere new in a room on the route
        room_map.add_frame(np.array([*at, 0.0]), np.zeros(2), free_rays(plan, at))
        moved = _moved(records, at, k)
        started = time.perf_counter()
        room_map.update(moved, 0.0)
        later.append(time.perf_counter() - started)
        room_map.update(records, 0.0)
        fresh = RoomMap(free=room_map.free)
        started = time.perf_counter()
        fresh.update(records, 0.0)
        first.append(time.perf_counter() - started)
    return (
        len(reply.rooms),
        len(reply.doors),
        *(statistics.median(times) for times in (again, later, first)),
    )


def _record(wall: int, p0: tuple[float, float], p1: tuple[float, float]) -> WallRecord:
    return WallRecord(wall, 0.0, 0.0, ((1e-4, 0.0), (0.0, 1e-4)), p0, p1, ((p0, p1),), 10)


def _moved(records: tuple[WallRecord, ...], at: Array, k: int) -> tuple[WallRecord, ...]:
    """The walls as a frame at ``at`` leaves them: what a live map's update starts from.

    Those within 3 m (the room's, the ones the camera saw) moved 1 cm along their normal,
    either way, as an observation moves a wall's estimate; the mapper segments again only
    when the map changed.
    """
    moved = []
    for r in records:
        p0, p1 = np.array(r.p0), np.array(r.p1)
        d = p1 - p0
        foot = p0 + np.clip((at - p0) @ d / (d @ d), 0.0, 1.0) * d
        shift = 0.01 * (-1) ** (k + r.id) * np.array([-d[1], d[0]]) / np.hypot(*d)
        near = np.hypot(*(at - foot)) < 3.0
        moved.append(_record(r.id, tuple(p0 + shift), tuple(p1 + shift)) if near else r)
    return tuple(moved)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--frames", type=int, default=900)
    args = parser.parse_args()
    print(
        "| building | seed | rooms / truth | matched | false | split | entered found | IoU min | "
        "IoU median | doors served | between entered: truth | found | rooms joined right | "
        "centre err max m | width err max m |"
    )
    print("|---|---:|---|---:|---:|---:|---|---:|---:|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for layout, seed in [(k, n) for k in ("rooms", "corridor") for n in range(args.seeds)]:
            s = score(seed, args.frames, Path(tmp), layout)
            print(
                f"| {layout} | {seed} | {s['rooms']} / {s['truth']} | {s['matched']} | "
                f"{s['false']} | {s['split']} | "
                f"{s['entered']} / {s['entered_truth']} | {s['iou_min']:.3f} | "
                f"{s['iou_median']:.3f} | {s['doors']} | {s['door_truth']} | {s['doors_found']} | "
                f"{s['joined']} | {s['centre']:.3f} | {s['width']:.3f} |",
                flush=True,
            )
    found_rooms, found_doors, again, later, first = update_cost()
    print(
        f"\nupdate of a 10 x 10 grid building: {found_rooms} rooms, {found_doors} doors, "
        f"median {again * 1e3:.1f} ms, a frame later (its walls moved, its rays drawn) "
        f"{later * 1e3:.1f} ms, a first one (every outline drawn) {first * 1e3:.1f} ms "
        "(target: 100 rooms within 20 ms)"
    )


if __name__ == "__main__":
    main()
