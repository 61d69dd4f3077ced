"""What the map serves: confirmed walls, their segments joined at corners, replies, updates.

The estimation (``wall_map``) keeps every wall it has evidence for; this is the policy of what a
reply shows of them. A wall is served once confirmed (seen ``confirm_obs`` times from
``confirm_views`` viewpoints), unless it was seen through (free space where it should be), is a
shadow of better-seen walls (a line blended across a corner from far away), or is the lesser of
a fan (one surface seen as two lines a few degrees apart); its segments are the stretches seen
between doors, with ends moved onto the corners they make with their neighbours (an L, or a T
where only the wall that ends there is cut). Replies and updates are typed
(``common.map_records``). Pure, no Zenoh.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wallmap.common import wall_model
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply, MapUpdate, WallRecord
from wallmap.services.mapper.wall import Wall
from wallmap.services.mapper.wall_map import WallMap

Array = NDArray[np.float64]
SHADOW_SAMPLES = 21  # points along a wall tested for a shadow
SEEN_THROUGH = 0.5  # a wall seen through along this share of its length is none


def _end_near(ends: list[float], px: float, py: float, reach: float) -> int | None:
    """Which wall end lies within reach of point (px, py), the nearer if both, or None.

    ``ends`` is (x0, y0, x1, y1): 0 is the first segment's start, 1 the last one's end.
    """
    x0, y0, x1, y1 = ends
    d0, d1 = math.hypot(x0 - px, y0 - py), math.hypot(x1 - px, y1 - py)
    best, distance = (0, d0) if d0 <= d1 else (1, d1)
    return best if distance <= reach else None


def _passes(ends: list[float], px: float, py: float, margin: float) -> bool:
    """Whether point (px, py), on a wall's line, lies between its ends, ``margin`` inside."""
    x0, y0, x1, y1 = ends
    dx, dy = x1 - x0, y1 - y0
    length = math.hypot(dx, dy)
    along = ((px - x0) * dx + (py - y0) * dy) / max(length, 1e-12)
    return margin < along < length - margin


def _shadowed(wall_map: WallMap, wall: Wall) -> bool:
    """Whether far better supported walls run along most of this one (see MapperConfig).

    The wall is sampled along its extent; a sample is covered where a better supported
    wall within ``shadow_angle`` passes within ``shadow_offset`` of it, inside that
    wall's extent. Two such walls can cover a line blended across the corner they make.
    """
    cfg = wall_map.config
    pieces = wall.segments()
    (ax, ay), (bx, by) = pieces[0, 0].tolist(), pieces[-1, 1].tolist()
    samples: Array | None = None
    covered = np.zeros(SHADOW_SAMPLES, dtype=bool)
    cos_max, offset = math.cos(cfg.shadow_angle), cfg.shadow_offset
    for other in (wall_map.walls[i] for i in wall_map.index.near(wall.ends)):
        if other is wall or other.n_obs < cfg.shadow_ratio * wall.n_obs:
            continue
        fx, fy, _, _, nx, ny = other.frame
        if abs(wall.frame.nx * nx + wall.frame.ny * ny) < cos_max:
            continue
        # Both ends beyond the band on one side: no point between them is inside it.
        da, db = (ax - fx) * nx + (ay - fy) * ny, (bx - fx) * nx + (by - fy) * ny
        if min(da, db) > offset or max(da, db) < -offset:
            continue
        if samples is None:
            samples = np.linspace(pieces[0, 0], pieces[-1, 1], SHADOW_SAMPLES)
        across = np.abs((samples - other.foot) @ other.normal)
        along = other.along(samples)
        theirs = other.segments()
        low, high = other.along(theirs[0, 0]), other.along(theirs[-1, 1])
        covered |= (across <= offset) & (along >= low - offset) & (along <= high + offset)
    return float(covered.mean()) >= cfg.shadow_cover


def served(wall_map: WallMap, wall: Wall) -> bool:
    """Confirmed, not seen through, not a shadow of another wall: what a reply serves."""
    if not wall.confirmed(wall_map.config):
        return False
    if wall.extent.free_share() >= SEEN_THROUGH:
        return False
    pieces = wall.segments()
    length = float(np.linalg.norm(pieces[:, 1] - pieces[:, 0], axis=1).sum())
    if length < wall_map.config.min_length or _shadowed(wall_map, wall):
        return False
    return not _fanned(wall_map, wall, pieces)


def _fanned(wall_map: WallMap, wall: Wall, pieces: Array) -> bool:
    """Whether a better-seen confirmed wall runs alongside: one surface as two lines.

    On real clutter a surface and what stands against it (a cabinet front, appliances on a
    counter) come out as lines a few degrees and centimetres apart. Of two confirmed walls
    within ``fan_angle`` and ``fan_offset`` whose segments overlap by ``fan_overlap``, only
    the one seen more often (the older on a tie) is served. A scanner sees no clutter stand
    against walls, but it sees a bent wall (panels a few degrees apart, a bowed board) whole
    from afar and in pieces from near: the whole's line and a piece's overlap along most of
    the piece, and only the better seen is served. For a wall seen mostly by a scanner the
    overlap must also be ``fan_share`` of its length: the pieces of a bent wall, each seen
    where its points are, overlap only where they meet.
    """
    cfg = wall_map.config
    scanned = 2 * wall.depth_obs <= wall.n_obs
    cos_max = math.cos(cfg.fan_angle)
    ta = wall.along(pieces.reshape(-1, 2))
    for other in (wall_map.walls[i] for i in sorted(wall_map.index.near(wall.ends))):
        if other is wall or (other.n_obs, -other.id) < (wall.n_obs, -wall.id):
            continue
        if abs(float(wall.normal @ other.normal)) < cos_max or not other.confirmed(cfg):
            continue
        theirs = other.segments()
        tb = wall.along(theirs.reshape(-1, 2))
        low, high = max(ta.min(), tb.min()), min(ta.max(), tb.max())
        short = scanned and high - low < cfg.fan_share * (ta.max() - ta.min())
        if high - low <= cfg.fan_overlap or short:
            continue
        middle = wall.on_line(np.array([0.5 * (low + high)]))[0]
        if abs(float(other.normal @ (middle - other.foot))) <= cfg.fan_offset:
            return True
    return False


def _is_served(wall_map: WallMap, wall: Wall, cache: dict[int, bool]) -> bool:
    """:func:`served`, remembered in ``cache`` for one reply."""
    if wall.id not in cache:
        cache[wall.id] = served(wall_map, wall)
    return cache[wall.id]


def _selected(wall_map: WallMap, wall: Wall, query: MapQuery, cache: dict[int, bool]) -> bool:
    if wall.n_obs < query.min_obs or (
        not _is_served(wall_map, wall, cache) and not query.tentative
    ):
        return False
    if query.since is not None and wall.last_seen < query.since:
        return False
    return query.crosses(wall.segments())


def cornered_segments(
    wall_map: WallMap, ids: Iterable[int], cache: dict[int, bool]
) -> dict[int, Array]:
    """The segments of walls ``ids``, with their ends joined at corners.

    An end of a served wall that meets a served neighbour's end at a corner moves onto the
    corner (an L); so does one that meets a neighbour going on through the crossing (a T),
    which keeps its segments. ``cache`` remembers :func:`served` and comes back filled for
    ``ids``.
    """
    raw: dict[int, tuple[Array, list[float]]] = {}

    def segments(wall: Wall) -> tuple[Array, list[float]]:
        """The wall's segments and its two ends (x0, y0, x1, y1) as floats."""
        if wall.id not in raw:
            pieces = wall.segments()
            raw[wall.id] = pieces, [*pieces[0, 0].tolist(), *pieces[-1, 1].tolist()]
        return raw[wall.id]

    cfg = wall_map.config
    sin_min, reach = math.sin(cfg.corner_angle), cfg.corner_reach
    band, max_reach = cfg.corner_band, cfg.corner_max_reach
    out = {}
    for wall_id in ids:
        a = wall_map.walls[wall_id]
        pieces, a_ends = segments(a)
        mine = pieces.copy()
        out[wall_id] = mine
        if not _is_served(wall_map, a, cache):
            continue
        afx, afy, _, _, anx, any_ = a.frame
        a_offset = anx * afx + any_ * afy
        for b in (wall_map.walls[i] for i in sorted(wall_map.index.near(a.ends)) if i != a.id):
            bfx, bfy, _, _, bnx, bny = b.frame
            det = anx * bny - any_ * bnx  # sine of the angle between the lines
            if abs(det) < sin_min or not _is_served(wall_map, b, cache):
                continue
            b_offset = bnx * bfx + bny * bfy
            # Where the two lines cross (Cramer's rule on the 2x2 system of their normals).
            cx = (a_offset * bny - any_ * b_offset) / det
            cy = (anx * b_offset - bnx * a_offset) / det
            # The shallower the corner, the farther past it the inlier band reaches.
            far = min(max_reach, max(reach, band / abs(det)))
            end_a = _end_near(a_ends, cx, cy, far)
            if end_a is None:
                continue
            b_ends = segments(b)[1]
            # An L (both end at the crossing) or a T (b goes on through it): a's end goes
            # there. The wall that goes on through a T is not cut (its end is not near).
            if _end_near(b_ends, cx, cy, far) is not None or _passes(b_ends, cx, cy, far):
                mine[(0, -1)[end_a], end_a] = (cx, cy)
    return out


def reply(wall_map: WallMap, query: MapQuery | None = None) -> MapReply:
    """The walls ``query`` asks for, as served, with the map's counters."""
    query = query or MapQuery()
    cache: dict[int, bool] = {}
    chosen = [w.id for w in wall_map.walls.values() if _selected(wall_map, w, query, cache)]
    segments = cornered_segments(wall_map, chosen, cache)
    return MapReply(
        frames=wall_map.frames,
        observations=wall_map.observations,
        stamp=wall_map.stamp,
        walls=tuple(record(wall_map.walls[i], segments[i], tentative=not cache[i]) for i in chosen),
        merges=tuple(wall_map.merges),
        trajectory=tuple(wall_map.path()) if query.trajectory else None,
    )


def take_changes(wall_map: WallMap) -> MapUpdate:
    """Walls changed and ids removed since the last call: a map update.

    A wall's neighbours come along: a change can move the corner they share.
    """
    ids = set(wall_map.changed)
    for i in wall_map.changed:
        ids |= wall_map.index.near(wall_map.walls[i].ends)
    cache: dict[int, bool] = {}
    segments = cornered_segments(wall_map, sorted(ids), cache)
    walls = tuple(
        record(wall_map.walls[i], segments[i], tentative=not cache[i]) for i in sorted(ids)
    )
    removed = tuple(sorted(wall_map.removed))
    wall_map.changed.clear()
    wall_map.removed.clear()
    return MapUpdate(wall_map.frames, wall_map.stamp, walls, removed)


@dataclass
class HeldChanges:
    """The map's changes taken off it while nothing subscribes to its updates, not yet built.

    Building an update (what is served, the corners, a record of every wall changed and of its
    neighbours) costs a mapper about a tenth of a millisecond a frame, for nobody when nothing
    listens; Zenoh would drop the message. Held, the changes go out whole with the first update
    someone hears, so a subscriber the mapper had not yet heard of misses none of them.
    """

    changed: set[int] = field(default_factory=set)
    removed: set[int] = field(default_factory=set)

    def hold(self, wall_map: WallMap) -> None:
        """Take the map's changes since the last update into the held ones."""
        self.changed |= wall_map.changed
        self.removed |= wall_map.removed
        wall_map.changed.clear()
        wall_map.removed.clear()

    def give_back(self, wall_map: WallMap) -> None:
        """Put the held changes back for :func:`take_changes`: walls still there, ids gone."""
        walls = wall_map.walls
        wall_map.changed.update(i for i in self.changed if i in walls)
        wall_map.removed.update(i for i in self.removed if i not in walls)
        self.changed.clear()
        self.removed.clear()


def record(wall: Wall, segments: Array, *, tentative: bool) -> WallRecord:
    """The contract's wall record of ``wall``, in the map frame, with its served segments."""
    uv, jac = wall_model.to_map_frame(wall.s, wall.anchor)
    cov = jac @ wall.p @ jac.T
    pieces = tuple(((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))) for a, b in segments)
    return WallRecord(
        id=wall.id,
        u=float(uv[0]),
        v=float(uv[1]),
        cov=((float(cov[0, 0]), float(cov[0, 1])), (float(cov[1, 0]), float(cov[1, 1]))),
        p0=pieces[0][0],
        p1=pieces[-1][1],
        segments=pieces,
        n_obs=wall.n_obs,
        n_views=wall.views,
        tentative=tentative,
        first_seen=wall.first_seen,
        last_seen=wall.last_seen,
    )
