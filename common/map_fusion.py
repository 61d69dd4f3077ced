"""Several robots' wall maps as one: each placed in the fleet's frame, the same wall fused once.

Each robot maps in its own frame; ``common.map_alignment`` finds where that frame lies in the
fleet's (the first robot's). Here each robot's walls are moved there (``place``: the line by the
measurement model seen from the fleet's origin, its covariance through both Jacobians, the
frame's uncertainty included), then walls of different robots that are one physical wall are
fused (``fuse_walls``): on one line (``parallel``, ``offset`` where they meet) and overlapping
or with a gap of at most ``join_gap`` along it. Two walls of one robot are fused only as pieces
of one line, apart along it, that another robot saw as one wall; never two that overlap (two
faces of a thin wall). A fused wall's line combines its members in information form
(``ekf.fuse``), its segments are theirs projected onto it and joined.

Fleet ids stay while the maps grow (``FleetIds``): a fused wall takes the id most of its
sources had; ids are never reused, and one merged away is reported as a merge.

Pure numpy, no Zenoh: the merge service is a shell around this.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from wallmap.common import ekf, se2, wall_model
from wallmap.common.map_records import WallRecord

Array = NDArray[np.float64]
Source = tuple[str, int]  # (robot prefix, the wall's id in that robot's map)
# A line this near (m) the fleet's origin has no closest point to fuse by (the first robot stood
# there, so none is); its best-seen member's line is kept.
NEAR_ORIGIN = 0.05
PIECES_OVERLAP = 0.05  # m two walls of one robot may overlap along their line and still be pieces


@dataclass(frozen=True)
class FuseConfig:
    """When walls of two robots are one.

    Attributes:
        parallel: largest angle (deg) between them. A wall one robot saw only while turning
            fast lies a few degrees off (the Jackal arena's left wall: 4.7 deg in every run).
        offset: farthest (m) one's line may lie from the other's, at the middle of the stretch
            they share (or of the gap between them).
        join_gap: longest gap (m) along the line between their extents.
    """

    parallel: float = 8.0
    offset: float = 0.12
    join_gap: float = 1.0


def place(wall: WallRecord, pose: Array, pose_cov: Array) -> WallRecord:
    """A robot's wall in the fleet's frame, its map frame placed there by ``pose`` (``pose_cov``).

    The line's closest point to the fleet's origin is the model's prediction seen from that
    origin (the pose ``inverse(pose)`` in the robot's frame); its covariance takes the wall's
    through ``d s'/d s`` and the frame's through ``d s'/d pose``.
    """
    s = np.array([wall.u, wall.v])
    origin = np.zeros(2)
    seen_from = se2.inverse(pose)
    moved = wall_model.predict(s, origin, seen_from)
    j_wall = wall_model.jacobian_state(s, origin, seen_from)
    j_pose = wall_model.jacobian_pose(s, origin, seen_from) @ se2.inverse_jacobian(pose)
    cov = j_wall @ np.asarray(wall.cov) @ j_wall.T + j_pose @ pose_cov @ j_pose.T
    cov = 0.5 * (cov + cov.T)

    def at(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
        return [(float(x), float(y)) for x, y in se2.transform_points(np.array(points), pose)]

    p0, p1 = at([wall.p0, wall.p1])
    return replace(
        wall,
        u=float(moved[0]),
        v=float(moved[1]),
        cov=((float(cov[0, 0]), float(cov[0, 1])), (float(cov[1, 0]), float(cov[1, 1]))),
        p0=p0,
        p1=p1,
        segments=tuple((a, b) for a, b in (at(seg) for seg in wall.segments)),
    )


def fuse_walls(
    walls: Sequence[tuple[str, WallRecord]], config: FuseConfig | None = None
) -> list[tuple[WallRecord, tuple[Source, ...]]]:
    """The robots' placed walls, each physical wall once, and the sources of each.

    The fused walls keep their first source's id: the fleet's are given by ``FleetIds``.
    """
    groups = group_walls(walls, config or FuseConfig())
    return [fused_wall([walls[k] for k in group]) for group in groups]


def group_walls(walls: Sequence[tuple[str, WallRecord]], config: FuseConfig) -> list[list[int]]:
    """Indices of the walls that are one, best pairs first.

    Two walls of one robot are one only as pieces of one line apart along it, joined by another
    robot's wall: never two that overlap (two faces of a thin wall, a wall and its shadow).
    """
    n = len(walls)
    if not n:
        return []
    a = np.array([w.p0 for _, w in walls])
    b = np.array([w.p1 for _, w in walls])
    d = b - a
    length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    unit = d / length[:, None]
    normal = np.stack([-unit[:, 1], unit[:, 0]], axis=1)
    rho = np.einsum("nk,nk->n", normal, a)
    cos = np.abs(unit @ unit.T)
    a_across = a @ normal.T  # [j, i]: how far j's first end lies across i's normal
    off = np.maximum(np.abs(a_across - rho), np.abs(b @ normal.T - rho))  # [j, i]: j from i
    along_a, along_b = (
        a @ unit.T - np.einsum("nk,nk->n", a, unit),
        b @ unit.T - np.einsum("nk,nk->n", a, unit),
    )
    low, high = np.minimum(along_a, along_b), np.maximum(along_a, along_b)  # j along i's line
    gap = np.maximum(low - length[None, :], -high)  # > 0: apart along the line
    # The lines' distance at the middle of the stretch they share (or of the gap between them),
    # not at the ends: an end of a long wall placed a degree or two off (a robot's odometry
    # drifted while it saw that wall) lies well off the other's line while the wall is the same.
    middle = 0.5 * (np.maximum(low, 0.0) + np.minimum(high, length[None, :]))  # [j, i]
    # [j, i]: j's line from the point ``middle`` along i's line, a_i + middle unit_i.
    mid_off = np.abs(a_across.T - rho[:, None] + middle * (unit @ normal.T).T)
    robot = np.array([r for r, _ in walls])
    ok = (cos >= math.cos(math.radians(config.parallel))) & (gap <= config.join_gap)
    ok &= (mid_off <= config.offset) & (robot[:, None] != robot[None, :])
    i, j = np.nonzero(np.triu(ok & ok.T, 1))
    order = np.argsort(np.maximum(mid_off[j, i], mid_off[i, j]), kind="stable")
    owner = list(range(n))
    members = {k: [k] for k in range(n)}
    # Two walls of one robot in one group only as pieces of one line, apart along it (a wall the
    # other robot saw whole, across the gap its mapper left open); never overlapping walls.
    apart = (np.minimum(high, length[None, :]) - np.maximum(low, 0.0) < PIECES_OVERLAP) & (
        off <= 2 * config.offset
    )
    for p, q in zip(i[order].tolist(), j[order].tolist(), strict=True):
        gp, gq = _root(owner, p), _root(owner, q)
        if gp == gq or not all(
            apart[x, y] and apart[y, x]
            for x in members[gp]
            for y in members[gq]
            if robot[x] == robot[y]
        ):
            continue
        owner[gq] = gp
        members[gp] += members.pop(gq)
    return [sorted(group) for group in members.values()]


def _root(owner: list[int], k: int) -> int:
    while owner[k] != k:
        k = owner[k]
    return k


def fused_wall(members: list[tuple[str, WallRecord]]) -> tuple[WallRecord, tuple[Source, ...]]:
    """One wall of the placed walls of several robots (or one), and its sources."""
    members = sorted(members, key=lambda m: -m[1].n_obs)
    sources = tuple((robot, w.id) for robot, w in members)
    first = members[0][1]
    if len(members) == 1:
        return first, sources
    origin = np.zeros(2)
    s, p = np.array([first.u, first.v]), np.asarray(first.cov, dtype=float)
    if min(math.hypot(w.u, w.v) for _, w in members) > NEAR_ORIGIN:
        for _, w in members[1:]:
            s, p = ekf.fuse(s, p, origin, np.array([w.u, w.v]), np.asarray(w.cov), origin)
    if math.hypot(*s) > NEAR_ORIGIN:
        foot, unit = s, np.array([-s[1], s[0]]) / math.hypot(*s)
    else:
        foot, unit = np.array(first.p0), np.subtract(first.p1, first.p0) / max(first.length, 1e-9)
    segments = _joined(foot, unit, [seg for _, w in members for seg in w.segments])
    seen = [w.first_seen for _, w in members if w.first_seen is not None]
    last = [w.last_seen for _, w in members if w.last_seen is not None]
    wall = replace(
        first,
        u=float(s[0]),
        v=float(s[1]),
        cov=((float(p[0, 0]), float(p[0, 1])), (float(p[1, 0]), float(p[1, 1]))),
        p0=segments[0][0],
        p1=segments[-1][1],
        segments=tuple(segments),
        n_obs=sum(w.n_obs for _, w in members),
        n_views=sum(w.n_views for _, w in members),
        tentative=all(w.tentative for _, w in members),
        first_seen=min(seen, default=None),
        last_seen=max(last, default=None),
    )
    return wall, sources


Point = tuple[float, float]


def _joined(
    foot: Array, unit: Array, segments: list[tuple[Point, Point]]
) -> list[tuple[Point, Point]]:
    """Segments projected onto the line through ``foot`` along ``unit``, joined if they overlap."""
    ends = np.sort((np.array(segments, dtype=float) - foot) @ unit, axis=1)
    ends = ends[np.argsort(ends[:, 0])]
    joined = [list(ends[0])]
    for lo, hi in ends[1:].tolist():
        if lo <= joined[-1][1] + 1e-3:
            joined[-1][1] = max(joined[-1][1], hi)
        else:
            joined.append([lo, hi])
    ends_at = [(foot + lo * unit, foot + hi * unit) for lo, hi in joined]
    return [((float(p[0]), float(p[1])), (float(q[0]), float(q[1]))) for p, q in ends_at]


@dataclass
class FleetIds:
    """Fleet ids by source, kept from one fusion to the next (see the module's doc)."""

    next_id: int = 0
    of_source: dict[Source, int] = field(default_factory=dict)

    def assign(
        self, groups: Sequence[tuple[Source, ...]]
    ) -> tuple[list[int], list[tuple[int, int]]]:
        """An id per group of sources, and (merged id, surviving id) for ids merged away."""
        claims = []
        for k, sources in enumerate(groups):
            known = [self.of_source[s] for s in sources if s in self.of_source]
            for fleet_id in set(known):
                claims.append((-known.count(fleet_id), fleet_id, k))
        ids: dict[int, int] = {}  # group -> its id: the one most of its sources had
        for _, fleet_id, k in sorted(claims):
            if k not in ids and fleet_id not in ids.values():
                ids[k] = fleet_id
        taken = set(ids.values())
        merges = []
        for k, sources in enumerate(groups):
            if k not in ids:
                ids[k], self.next_id = self.next_id, self.next_id + 1
            for s in sources:
                old = self.of_source.get(s)
                if old is not None and old != ids[k] and old not in taken:
                    merges.append((old, ids[k]))
        self.of_source = {s: ids[k] for k, sources in enumerate(groups) for s in sources}
        return [ids[k] for k in range(len(groups))], sorted(set(merges))
