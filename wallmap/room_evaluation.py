"""Rooms and doors scored against a scene's truth, for `wallmap up --truth` and benchmarks.

Rooms are matched one to one with the truth's by the IoU of their outlines (both rasterised on a
5 cm grid), best pairs first, a pair counting from an IoU of 0.3; a truth room left unmatched is
missed, a served room left unmatched is false, two served rooms over one truth room (the second
overlapping it by 0.3 or more of its own area) a split. What is asked of a map is the rooms the
robot entered (its path passes inside them) and the doors between two of them: a room seen only
through its door may be served, or not, and a door into nothing seen is not asked for. Doors are
matched by centre, within 0.5 m; a matched door joins the right rooms when its rooms are the
matches of the truth's.

Given the floor the mapper saw (its ``FreeSpace``), each entered room's ``seen`` share says how
much of its floor lies within ``SEEN_REACH`` of floor seen free. Rooms are made of seen floor
(an open room's filled out a little towards the walls it faces), so a room seen in part is
served in part: a low IoU with a low share is the drive's, not the segmentation's.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from wallmap.common.free_space import FreeSpace
from wallmap.common.grid_labels import inside_polygon
from wallmap.scene.floorplan import Door, FloorPlan

STEP = 0.05  # m: the grid outlines are compared on
MATCH_IOU = 0.3
DOOR_REACH = 0.5  # m
# m: floor this near floor seen free counts as seen (free rays stop 0.2 m short of their wall)
SEEN_REACH = 0.3


def _grid(polygons: Iterable[np.ndarray]) -> np.ndarray:
    both = np.concatenate(list(polygons))
    xs = np.arange(both[:, 0].min(), both[:, 0].max() + STEP, STEP)
    ys = np.arange(both[:, 1].min(), both[:, 1].max() + STEP, STEP)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two polygons (n, 2), on a 5 cm grid."""
    grid = _grid([a, b])
    in_a, in_b = inside_polygon(grid, a), inside_polygon(grid, b)
    return float((in_a & in_b).sum() / max(int((in_a | in_b).sum()), 1))


def _share_of(a: np.ndarray, b: np.ndarray) -> float:
    """How much of polygon ``a`` lies in ``b``."""
    grid = _grid([a, b])
    in_a = inside_polygon(grid, a)
    return float((in_a & inside_polygon(grid, b)).sum() / max(int(in_a.sum()), 1))


def seen_shares(polygons: dict[int, np.ndarray], free: FreeSpace) -> dict[int, float]:
    """How much of each room's floor (polygon (n, 2)) lies near floor seen free.

    On the 5 cm grid, within ``SEEN_REACH`` (a square of cells) of a free cell: the free grid's
    box sums are counted once, for every room.
    """
    reach = int(np.ceil(SEEN_REACH / free.cell - 1e-9))
    pad = reach + 1
    summed = np.pad(free.free(), pad).astype(np.int32).cumsum(axis=0).cumsum(axis=1)
    return {
        k: _near_seen(polygon, free.origin, free.cell, summed, reach)
        for k, polygon in polygons.items()
    }


def _near_seen(
    polygon: np.ndarray, origin: np.ndarray, cell: float, summed: np.ndarray, reach: int
) -> float:
    """The share of ``polygon``'s grid points with a free cell in the square around theirs."""
    points = _grid([polygon])
    points = points[inside_polygon(points, polygon)]
    if not len(points):
        return 0.0
    i, j = (np.floor(points / cell).astype(np.int64) - origin + reach + 1).T
    inside = (i > reach) & (j > reach) & (i < summed.shape[0] - reach - 1)
    inside &= j < summed.shape[1] - reach - 1
    i, j = i[inside], j[inside]
    lo_i, hi_i, lo_j, hi_j = i - reach - 1, i + reach, j - reach - 1, j + reach
    box = summed[hi_i, hi_j] - summed[lo_i, hi_j] - summed[hi_i, lo_j] + summed[lo_i, lo_j]
    return float((box > 0).sum() / len(points))


def entered(plan: FloorPlan, path: ArrayLike | None) -> frozenset[int]:
    """The truth rooms a path of the robot's positions (n, 2) passes inside (None: all)."""
    if path is None:
        return frozenset(r.id for r in plan.rooms)
    points = np.asarray(path, dtype=float).reshape(-1, 2)
    return frozenset(
        r.id for r in plan.rooms if inside_polygon(points, np.asarray(r.polygon, float)).any()
    )


@dataclass(frozen=True)
class RoomScore:
    """Served rooms and doors against the truth's (see the module's doc)."""

    rooms: int
    truth_rooms: int
    entered: frozenset[int]  # truth room ids the robot entered
    matched: dict[int, int]  # served room id -> truth room id
    ious: dict[int, float]  # truth room id -> the IoU of its match
    split: int
    doors: int
    truth_doors: int  # between entered rooms
    doors_found: int
    doors_joined: int  # of those found, joining the right rooms
    centre_err: float  # m, the largest of the doors found
    width_err: float  # m, likewise
    seen: dict[int, float]  # entered truth room id -> its seen share (empty: no floor given)

    @property
    def false(self) -> int:
        """Served rooms matching no truth room and not part of a split."""
        return self.rooms - len(self.matched) - self.split

    @property
    def entered_ious(self) -> list[float]:
        """The IoU of each entered room (0 for one not found)."""
        return [self.ious.get(t, 0.0) for t in sorted(self.entered)]

    def summary(self) -> str:
        """One line for people."""
        values = self.entered_ious
        found = sum(v > 0 for v in values)
        ious = (
            f"IoU min {min(values):.2f}, median {statistics.median(values):.2f}" if values else "-"
        )
        if self.seen:
            shares = list(self.seen.values())
            ious += f"; floor seen min {min(shares):.2f}, median {statistics.median(shares):.2f}"
        return (
            f"rooms entered {found} of {len(values)} found ({ious}), {self.false} false, "
            f"{self.split} split, {self.rooms} served; doors between them {self.doors_found} "
            f"of {self.truth_doors} found, {self.doors_joined} joining the right rooms (centre "
            f"within {self.centre_err:.2f} m, width within {self.width_err:.2f} m)"
        )


def evaluate_rooms(
    body: dict[str, Any],
    plan: FloorPlan,
    path: ArrayLike | None = None,
    free: FreeSpace | None = None,
) -> RoomScore:
    """The mapper's rooms reply (the contract's payload) against the plan's truth.

    ``path``: the robot's positions (n, 2), which say the rooms it entered (None: all).
    ``free``: the floor the mapper saw, for each entered room's seen share.
    """
    served = {r["id"]: np.asarray(r["polygon"], dtype=float) for r in body["rooms"]}
    truth = {t.id: np.asarray(t.polygon, dtype=float) for t in plan.rooms}
    pairs = sorted(
        ((iou(mine, theirs), i, t) for i, mine in served.items() for t, theirs in truth.items()),
        reverse=True,
    )
    matched: dict[int, int] = {}
    ious: dict[int, float] = {}
    for value, i, t in pairs:
        if value >= MATCH_IOU and i not in matched and t not in ious:
            matched[i], ious[t] = t, value
    split = sum(
        1
        for i, mine in served.items()
        if i not in matched and any(_share_of(mine, truth[t]) >= MATCH_IOU for t in ious)
    )
    inside = entered(plan, path)
    doors = [d for d in plan.doors if len(d.rooms) == 2 and set(d.rooms) <= inside]
    found, joined, centre, width = _doors(body["doors"], doors, matched)
    return RoomScore(
        rooms=len(served),
        truth_rooms=len(truth),
        entered=inside,
        matched=matched,
        ious=ious,
        split=split,
        doors=len(body["doors"]),
        truth_doors=len(doors),
        doors_found=found,
        doors_joined=joined,
        centre_err=centre,
        width_err=width,
        seen={} if free is None else seen_shares({t: truth[t] for t in sorted(inside)}, free),
    )


def _doors(
    served: list[dict[str, Any]], truth: list[Door], matched: dict[int, int]
) -> tuple[int, int, float, float]:
    """Truth doors found, found joining the right rooms, the largest centre and width errors."""
    found, joined, centre, width = 0, 0, [0.0], [0.0]
    for door in truth:
        middle = (np.asarray(door.p0) + np.asarray(door.p1)) / 2
        near = [d for d in served if np.hypot(*(np.asarray(d["center"]) - middle)) <= DOOR_REACH]
        if not near:
            continue
        d = min(near, key=lambda d: np.hypot(*(np.asarray(d["center"]) - middle)))
        found += 1
        centre.append(float(np.hypot(*(np.asarray(d["center"]) - middle))))
        width.append(abs(d["width"] - float(np.hypot(*np.subtract(door.p1, door.p0)))))
        joined += sorted(matched.get(r, -1) for r in d["rooms"]) == sorted(door.rooms)
    return found, joined, max(centre), max(width)
