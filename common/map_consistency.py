"""What a map of a real recording can be checked against when there is no ground truth. Pure.

A real bag has no plan to score against, but the map and the poses still have to agree with the
data: scan points placed with the published poses (``se2.transform_points``) should lie on
mapped walls; no wall should be mapped twice; a straight corridor should come out as two long
parallel walls. These are the checks of ``docs/real-data.md`` and of the real-bag tests.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common.map_records import WallRecord, as_records

Array = NDArray[np.float64]


@dataclass(frozen=True)
class MappedWall:
    """A wall of a map reply: its id and served segments (k x 2 x 2, map frame)."""

    id: int
    segments: Array

    @classmethod
    def from_reply(cls, record: WallRecord | Mapping[str, Any]) -> MappedWall:
        """From one wall of a map reply (typed, or the contract's JSON)."""
        (wall,) = as_records([record])
        return cls(wall.id, np.asarray(wall.segments, dtype=float).reshape(-1, 2, 2))

    @property
    def length(self) -> float:
        """Total length of the segments (m)."""
        return float(np.linalg.norm(self.segments[:, 1] - self.segments[:, 0], axis=1).sum())

    @property
    def direction(self) -> Array:
        """Unit vector from the first segment's start to the last one's end."""
        d = self.segments[-1, 1] - self.segments[0, 0]
        return d / np.linalg.norm(d)


def distance_to_walls(points: Array, walls: Sequence[MappedWall]) -> Array:
    """Distance (m) of each map point (N x 2) to the nearest mapped segment (inf if none)."""
    if not walls or not len(points):
        return np.full(len(points), np.inf)
    segs = np.concatenate([w.segments for w in walls])  # S x 2 x 2
    a, d = segs[:, 0], segs[:, 1] - segs[:, 0]
    length2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-12)
    best = np.full(len(points), np.inf)
    for start in range(0, len(points), 4096):  # bounded memory on long recordings
        p = points[start : start + 4096, None, :]  # N x 1 x 2
        t = np.clip(np.einsum("nsk,sk->ns", p - a, d) / length2, 0.0, 1.0)
        nearest = a + t[..., None] * d
        best[start : start + 4096] = np.linalg.norm(p - nearest, axis=2).min(axis=1)
    return best


def _overlap(a: MappedWall, b: MappedWall) -> float:
    """Length of b's extent overlapping a's, along a's direction (m)."""
    axis = a.direction
    ta = a.segments.reshape(-1, 2) @ axis
    tb = b.segments.reshape(-1, 2) @ axis
    return min(ta.max(), tb.max()) - max(ta.min(), tb.min())


def duplicates(
    walls: Sequence[MappedWall],
    max_angle_deg: float = 3.0,
    max_offset: float = 0.10,
    min_overlap: float = 0.0,
) -> list[tuple[int, int]]:
    """Pairs of walls within ``max_angle_deg`` and ``max_offset`` whose extents overlap.

    The offset is measured from the middle of the overlap on one wall to the other's line; the
    overlap must exceed ``min_overlap`` (m).
    """
    pairs = []
    for a, b in itertools.combinations(walls, 2):
        cos = abs(float(a.direction @ b.direction))
        if math.degrees(math.acos(min(cos, 1.0))) > max_angle_deg or _overlap(a, b) <= min_overlap:
            continue
        axis = a.direction
        ta = a.segments.reshape(-1, 2) @ axis
        tb = b.segments.reshape(-1, 2) @ axis
        middle_t = 0.5 * (max(ta.min(), tb.min()) + min(ta.max(), tb.max()))
        start = a.segments[0, 0]
        middle = start + (middle_t - float(start @ axis)) * axis
        normal_b = np.array([-b.direction[1], b.direction[0]])
        if abs(float((middle - b.segments[0, 0]) @ normal_b)) <= max_offset:
            pairs.append((a.id, b.id))
    return pairs


def fans(walls: Sequence[MappedWall]) -> list[tuple[int, int]]:
    """Near-parallel lines for one surface: within 8 degrees and 30 cm, overlapping > 0.3 m.

    What a detector that blends clutter into walls leaves behind on real RGB-D data.
    """
    return duplicates(walls, max_angle_deg=8.0, max_offset=0.30, min_overlap=0.3)


def angle_between(a: MappedWall, b: MappedWall) -> float:
    """Angle between two walls' directions, degrees, in [0, 90]."""
    return math.degrees(math.acos(min(abs(float(a.direction @ b.direction)), 1.0)))
