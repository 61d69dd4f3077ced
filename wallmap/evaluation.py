"""Scoring a wall map against the ground-truth floor plan: the project's acceptance metric.

A mapped wall is a dict with at least ``u, v`` (the point of its infinite line closest to
the map origin) and ``p0, p1`` (the ends of its observed extent), all in the map frame;
an ``id`` key, if present, names it in the report, and ``segments`` (pairs of points), if
present, are the parts of the extent seen between doors. The rules:

* A mapped wall matches a true, non-glass wall when the angle between their lines is
  at most ``max_angle_deg``, their extents overlap (the projections of p0, p1 onto the
  true wall's line overlap the true segment by more than 0) and the mapped line passes
  within ``max_offset`` of the midpoint of that overlap.
* precision = mapped walls matching at least one true wall / mapped walls (1 if none).
* recall = true non-glass walls seen in at least ``min_frames`` frames and matched /
  such walls (1 if none).
* duplicates = true walls matched by two or more mapped walls.
* A true wall here is a physical wall: pieces of the plan on one line with at most 3 m between
  them (a wall with a doorway, which the plans give as two pieces) count as one wall, matched
  by any mapped wall matching one of its pieces (``physical_walls``). One mapped wall spanning
  the doorway matches it once; two mapped pieces either side are a duplicate.
* For each matched true wall its best match (smallest offset) gives an angle, an offset
  and an end-point error; their medians are reported (NaN if nothing matched).
* The end-point error of a match is the mean, over the mapped wall's two end points, of
  the distance to the nearer end point of the true wall. It measures the extent, which
  matching ignores: a wall mapped short, long or merged across a doorway shows here. A
  mapped wall with ``segments`` has the end points of the segment that overlaps the true
  wall most, so a door kept open inside a mapped wall is no error. The error also counts
  ends that were never in view (hidden behind a pillar, beyond the sensor's range or
  outside the frames recorded), so there it overstates the mapper's error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wallmap.common.map_records import WallRecord
from wallmap.scene.floorplan import FloorPlan, Wall

_EPS = 1e-9


@dataclass(frozen=True)
class MapScore:
    """How well a wall map matches the truth. See the module docstring for the rules.

    Attributes:
        precision: Share of mapped walls that match a true wall.
        recall: Share of sufficiently seen true walls that are matched.
        duplicates: True walls matched by two or more mapped walls.
        median_angle_deg: Median angle error of the best matches.
        median_offset_m: Median offset error of the best matches.
        median_endpoint_m: Median end-point error of the best matches.
        n_mapped: Mapped walls.
        n_mapped_matched: Mapped walls that match a true wall.
        n_true: True non-glass walls seen in at least ``min_frames`` frames.
        n_true_matched: Of those, the matched ones.
        unmatched_mapped: Ids (or list indices) of mapped walls matching nothing.
        unmatched_true: Ids of sufficiently seen true walls that no mapped wall matches.
    """

    precision: float
    recall: float
    duplicates: int
    median_angle_deg: float
    median_offset_m: float
    median_endpoint_m: float
    n_mapped: int
    n_mapped_matched: int
    n_true: int
    n_true_matched: int
    unmatched_mapped: list[Any]
    unmatched_true: list[int]

    def summary(self) -> str:
        """One readable line."""
        return (
            f"precision {self.precision:.3f} ({self.n_mapped_matched}/{self.n_mapped}), "
            f"recall {self.recall:.3f} ({self.n_true_matched}/{self.n_true}), "
            f"duplicates {self.duplicates}, "
            f"median angle error {self.median_angle_deg:.2f} deg, "
            f"median offset error {self.median_offset_m:.3f} m, "
            f"median end-point error {self.median_endpoint_m:.3f} m"
        )


def mapped_line(wall: Mapping[str, Any]) -> tuple[np.ndarray, float] | None:
    """Unit direction and signed offset of a mapped wall's line {q : n·q = offset}.

    The direction comes from p1 - p0, because (u, v) says nothing about it when the line
    passes through the origin; the offset comes from (u, v), which lies on the line. The
    normal n is the direction turned left. If p0 = p1 the direction falls back to the one
    perpendicular to (u, v); None if both are degenerate.
    """
    uv = np.array([wall["u"], wall["v"]], dtype=float)
    extent = np.asarray(wall["p1"], dtype=float) - np.asarray(wall["p0"], dtype=float)
    if np.linalg.norm(extent) > _EPS:
        direction = extent / np.linalg.norm(extent)
    elif np.linalg.norm(uv) > _EPS:
        direction = np.array([-uv[1], uv[0]]) / np.linalg.norm(uv)
    else:
        return None
    normal = np.array([-direction[1], direction[0]])
    return direction, float(normal @ uv)


def match_errors(wall: Mapping[str, Any], truth: Wall) -> tuple[float, float] | None:
    """Angle (deg) and offset (m) of a mapped wall against a true wall; None if disjoint.

    The offset is the distance from the mapped line to the midpoint of the overlap of the
    two extents along the true wall; without overlap there is nothing to compare.
    """
    line = mapped_line(wall)
    if line is None:
        return None
    direction, offset = line
    a, b = np.asarray(truth.p0, dtype=float), np.asarray(truth.p1, dtype=float)
    length = float(np.linalg.norm(b - a))
    along = (b - a) / length
    s0 = float((np.asarray(wall["p0"], dtype=float) - a) @ along)
    s1 = float((np.asarray(wall["p1"], dtype=float) - a) @ along)
    lo, hi = max(min(s0, s1), 0.0), min(max(s0, s1), length)
    if hi - lo <= 0.0:
        return None
    cross = float(direction[0] * along[1] - direction[1] * along[0])
    angle = math.degrees(math.atan2(abs(cross), abs(float(direction @ along))))
    middle = a + along * (lo + hi) / 2
    normal = np.array([-direction[1], direction[0]])
    return angle, abs(float(normal @ middle) - offset)


def endpoint_error(wall: Mapping[str, Any], truth: Wall) -> float:
    """Mean distance (m) from the mapped wall's end points to the nearer true end point.

    The end points are those of the wall's segment overlapping the true wall most (the
    nearest one if none overlaps), or ``p0, p1`` if it has no segments.
    """
    a, b = np.asarray(truth.p0, dtype=float), np.asarray(truth.p1, dtype=float)
    along = (b - a) / np.linalg.norm(b - a)
    pieces = np.asarray(wall.get("segments") or [[wall["p0"], wall["p1"]]], dtype=float)
    s = (pieces - a) @ along  # (pieces, 2) positions along the true wall
    overlap = np.minimum(s.max(axis=1), truth.length) - np.maximum(s.min(axis=1), 0.0)
    ends = pieces[int(np.argmax(overlap))]
    return float(
        np.mean(np.linalg.norm(ends[:, None] - np.array([a, b])[None], axis=2).min(axis=1))
    )


ONE_LINE_ANGLE = math.radians(0.1)  # true pieces this close to parallel...
ONE_LINE_OFFSET = 0.01  # ...and this close to one line...
ONE_LINE_GAP = 3.0  # ...and this close along it are one physical wall (a door or window between)


def physical_walls(plan: FloorPlan) -> list[list[Wall]]:
    """The plan's solid walls grouped into physical walls: pieces of one line across gaps.

    The generated plans give a wall with a doorway as two pieces, and the map models a door as
    a gap between the segments of one wall; scoring counts the two pieces as one wall, so that
    one mapped wall spanning the door matches it once and two mapped pieces are a duplicate.
    """
    solid = [w for w in plan.walls if not w.glass]
    groups: list[list[Wall]] = []
    for wall in solid:
        for group in groups:
            if any(_one_line(wall, other) for other in group):
                group.append(wall)
                break
        else:
            groups.append([wall])
    return groups


def _one_line(a: Wall, b: Wall) -> bool:
    """Two true pieces on one line with at most ``ONE_LINE_GAP`` between them."""
    pa, pb = np.array([a.p0, a.p1], dtype=float), np.array([b.p0, b.p1], dtype=float)
    along = (pa[1] - pa[0]) / np.linalg.norm(pa[1] - pa[0])
    other = (pb[1] - pb[0]) / np.linalg.norm(pb[1] - pb[0])
    if abs(float(along[0] * other[1] - along[1] * other[0])) > math.sin(ONE_LINE_ANGLE):
        return False
    normal = np.array([-along[1], along[0]])
    if np.abs((pb - pa[0]) @ normal).max() > ONE_LINE_OFFSET:
        return False
    ta, tb = (pa - pa[0]) @ along, (pb - pa[0]) @ along
    gap = max(tb.min() - ta.max(), ta.min() - tb.max())
    return gap <= ONE_LINE_GAP


def _matches(
    mapped: list[dict[str, Any]], groups: list[list[Wall]], max_angle_deg: float, max_offset: float
) -> tuple[dict[int, tuple[float, float, float]], dict[int, int], list[Any]]:
    """Each mapped wall against each physical wall (its pieces).

    Returns the best (smallest offset) match per physical wall as (angle, offset, end-point
    error); how many mapped walls match each (a mapped wall matching two of its pieces counts
    once); and the mapped walls matching none.
    """
    best: dict[int, tuple[float, float, float]] = {}
    match_count = dict.fromkeys(range(len(groups)), 0)
    unmatched_mapped: list[Any] = []
    for index, wall in enumerate(mapped):
        matched = False
        for group, pieces in enumerate(groups):
            hit = False
            for truth in pieces:
                errors = match_errors(wall, truth)
                if errors is None or errors[0] > max_angle_deg or errors[1] > max_offset:
                    continue
                hit = True
                if group not in best or errors[1] < best[group][1]:
                    best[group] = (*errors, endpoint_error(wall, truth))
            matched |= hit
            match_count[group] += int(hit)
        if not matched:
            unmatched_mapped.append(wall.get("id", index))
    return best, match_count, unmatched_mapped


def evaluate_map(
    mapped: Sequence[WallRecord | Mapping[str, Any]],
    plan: FloorPlan,
    seen_counts: Mapping[int, int],
    *,
    min_frames: int = 3,
    max_angle_deg: float = 5.0,
    max_offset: float = 0.15,
) -> MapScore:
    """Score a wall map against the plan it was built from (rules in the module docstring).

    Args:
        mapped: Mapped walls: records of a map reply, or dicts with ``u, v, p0, p1`` (and
            optionally ``id`` and ``segments``), from any mapper.
        plan: Ground truth.
        seen_counts: Per true wall id, the frames in which the detector could see it.
        min_frames: True walls seen in fewer frames are not required for recall.
        max_angle_deg: Largest angle between matching lines.
        max_offset: Largest distance from the mapped line to the overlap's midpoint.

    Returns:
        The score.
    """
    mapped = [w.to_map() if isinstance(w, WallRecord) else w for w in mapped]
    groups = physical_walls(plan)
    best, match_count, unmatched_mapped = _matches(mapped, groups, max_angle_deg, max_offset)
    required = [
        group
        for group, pieces in enumerate(groups)
        if max(seen_counts.get(w.id, 0) for w in pieces) >= min_frames
    ]
    unmatched_true = [groups[i][0].id for i in required if i not in best]
    n_mapped_matched = len(mapped) - len(unmatched_mapped)
    n_true_matched = len(required) - len(unmatched_true)
    angles = [e[0] for e in best.values()]
    offsets = [e[1] for e in best.values()]
    endpoints = [e[2] for e in best.values()]
    return MapScore(
        precision=n_mapped_matched / len(mapped) if mapped else 1.0,
        recall=n_true_matched / len(required) if required else 1.0,
        duplicates=sum(1 for k in match_count.values() if k >= 2),
        median_angle_deg=float(np.median(angles)) if angles else math.nan,
        median_offset_m=float(np.median(offsets)) if offsets else math.nan,
        median_endpoint_m=float(np.median(endpoints)) if endpoints else math.nan,
        n_mapped=len(mapped),
        n_mapped_matched=n_mapped_matched,
        n_true=len(required),
        n_true_matched=n_true_matched,
        unmatched_mapped=unmatched_mapped,
        unmatched_true=unmatched_true,
    )
