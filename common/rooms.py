"""Rooms and the doors between them, from the wall map and the floor the sensor saw free.

A room is a region of seen floor bounded by walls and doors; a corridor is a room. The method,
on a grid of ``FreeSpace``'s cells:

1. **Openings.** Every end of a wall's segment that stops short of the next wall (or of the
   next segment of its own wall) leaves an opening: the shortest span from that end, roughly
   along its wall (``door_angle``), to another wall's end or face, at most ``door_max`` long.
   Spans under ``door_min`` are gaps in the masonry (a corner not quite seen): closed as wall.
   Longer ones are door candidates, and closed too while the floor is divided. Two ends
   facing each other across a wider gap in one line of wall (up to ``passage_max``) make a
   passage, a door candidate too. A longer span from an end left open that nothing was ever
   seen through (``blind_max``; under ``blind_seen`` of it seen free) is closed as wall: glass.
2. **Regions.** Walls and openings drawn as barriers (``barrier`` thick), the rest of the grid
   split into 4-connected regions. A region that does not reach the grid's edge is enclosed:
   it is a room, ``closed``, and its floor is all of it (corners the sensor never saw
   included). A region reaching the edge leaks to unexplored space: its seen floor, in
   connected pieces, makes rooms that are not closed. Rooms under ``min_area`` are dropped,
   open ones under ``min_open_area`` (a glimpse through a door into the space beyond).
3. **Doors.** A door candidate is a door when the robot or its rays crossed it (its cells
   are seen free) and it joins two different rooms, or a room and unexplored space. One
   never seen through (glass, a dark niche) stays wall; one with the same room both sides is
   not a door.

Each room is then its cells grown back into the barrier they face (a barrier's half thickness),
outlined, simplified (``simplify``). Pure numpy: no Zenoh, so the mapper, the offline runner
and the benchmarks share it. Ids are not given here (``services.mapper.room_map``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wallmap.common.free_space import FreeSpace
from wallmap.common.grid_labels import (
    convex_hull,
    inside_polygon,
    label,
    outline,
    polygon_area,
    polygon_centroid,
    simplify,
    spread,
    touches_border,
)

Array = NDArray[np.float64]
PAD = 8  # cells of grid kept around everything known
TRIM_GAP = 0.3  # m unseen along a passage bridged when its door is found (``door_span``)
GAP_REACH = 2.5  # m past a wall's end along its line where an end across it is in its gap
GAP_ANGLE = 45.0  # deg: an end's wall this far from another's line runs across it


@dataclass(frozen=True)
class RoomsConfig:
    """How rooms are told apart.

    Attributes:
        door_min: narrowest door (m); narrower openings are gaps in the wall.
        door_max: widest door (m).
        door_angle: how far (deg) an opening's direction may turn from its wall's.
        joint: an end this near (m) another wall is joined to it (a corner, a T): no opening.
        barrier: half thickness (m) of walls and openings while the floor is divided.
        min_area: smallest room (m^2).
        min_open_area: smallest room not closed (m^2): less is a glimpse through a door.
        fill_reach: how far (m) an open room is filled out from its seen floor.
        closed_seen: share of an enclosed region seen free for it to be a closed room.
        simplify: how far (m) an outline may stray from its cells.
        passage_max: widest opening (m) between two ends of one line of wall that is a door.
        passage_angle: how far (deg) each end's wall may point off the other end.
        blind_max: longest span (m) closed as an unseen wall (glass) where nothing crossed it.
        blind_angle: how far (deg) such a span may turn from its wall's direction.
        blind_seen: share of a span's cells seen free beyond which it is a passage, not glass.
        divider_min: shortest piece of wall (m) whose end may start a divider's span.
        divider_max: longest divider's span (m): a passage and the unmapped wall beside it.
    """

    door_min: float = 0.6
    door_max: float = 2.5
    door_angle: float = 35.0
    joint: float = 0.2
    barrier: float = 0.1
    min_area: float = 1.0
    min_open_area: float = 2.5
    fill_reach: float = 1.5
    closed_seen: float = 0.5
    simplify: float = 0.12
    passage_max: float = 4.0
    passage_angle: float = 15.0
    blind_max: float = 8.0
    blind_angle: float = 60.0
    blind_seen: float = 0.1
    divider_min: float = 1.0
    divider_max: float = 5.0


@dataclass(frozen=True)
class WallSegments:
    """One wall of the map: its id and its segments (k, 2, 2), in the map frame."""

    id: int
    segments: Array


@dataclass(frozen=True)
class Opening:
    """A span from one wall's end to another wall (or piece of its own), in the map frame.

    ``door``: a divider's span is door and missing wall in one (``_divider_spans``); its door
    is the part seen crossed (``door_span``). Any other span (None) is all door.
    """

    wall: int
    p0: Array
    p1: Array
    door: tuple[Array, Array] | None = None

    @property
    def width(self) -> float:
        """Its length (m)."""
        return float(np.hypot(*(self.p1 - self.p0)))


@dataclass
class RoomShape:
    """A room found, before it has an id: its outline and what bounds it.

    ``cells``: its grid cells as global (i, j) indices of ``FreeSpace``'s cell size.
    """

    polygon: Array
    area: float
    centroid: Array
    closed: bool
    cells: NDArray[np.int64]
    walls: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class DoorShape:
    """A door found, before it has an id: its span, its wall, and the rooms (indices) it joins."""

    p0: Array
    p1: Array
    wall: int
    rooms: tuple[int, ...]


@dataclass(frozen=True)
class Layout:
    """The rooms and doors of one segmentation."""

    rooms: list[RoomShape]
    doors: list[DoorShape]


@dataclass(frozen=True)
class _Ends:
    """The segment ends no other wall meets (where openings may start), and all segments."""

    wall: NDArray[np.int64]  # (e,) the wall of each end
    piece: NDArray[np.int64]  # (e,) its segment, an index into a and b
    point: Array  # (e, 2)
    outward: Array  # (e, 2) unit: the way its segment would go on
    a: Array  # (s, 2) every segment's first end
    b: Array  # (s, 2) ...and second
    reach: float  # farthest (m) any search looks from an end (``targets``)

    @functools.cached_property
    def targets(self) -> _Targets:
        """What each end may open onto, once for every search (``_nearest_ahead``).

        Every other segment within ``reach``: its two ends and the end's foot on it.
        """
        k, s = _near(self.point, self.a, self.b, self.reach)  # by end, then segment
        other = s != self.piece[k]
        k, s = k[other], s[other]
        # An end's rows together: its segments' first ends, their second ends, its feet.
        count = np.bincount(k, minlength=len(self.point))
        row = 2 * (np.cumsum(count) - count)[k] + np.arange(len(k))
        points = np.empty((3 * len(k), 2))
        points[row] = self.a[s]
        points[row + count[k]] = self.b[s]
        points[row + 2 * count[k]] = _foot(self.point[k], self.a[s], self.b[s])
        end = np.repeat(np.arange(len(self.point)), 3 * count)
        dx, dy = (points - self.point[end]).T
        dist = np.hypot(dx, dy)
        ox, oy = self.outward[end].T
        with np.errstate(divide="ignore", invalid="ignore"):
            cosine = (dx * ox + dy * oy) / dist
        dist[dist <= 1e-6] = np.inf
        return _Targets(end, points, dist, cosine)


@dataclass(frozen=True)
class _Targets:
    """Points an end may open onto, one row each (``_Ends.targets``).

    Rows are grouped by end; within an end, in the order of all segments' first ends, then
    second ends, then feet, which settles ties in distance whatever was left out as too far.
    """

    end: NDArray[np.int64]
    points: Array
    dist: Array
    cosine: Array

    @functools.cached_property
    def groups(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Each end's first row, and each row's group (an index into the first)."""
        new = np.diff(self.end, prepend=-1) != 0
        return np.flatnonzero(new), np.cumsum(new) - 1


def _near(
    points: Array, a: Array, b: Array, radius: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (point k, segment s) with the point within ``radius`` of the segment's box.

    Every pair within ``radius`` of each other is among them, and in a large map few more:
    the exact tests run on these alone, not on every end against every segment.
    """
    lo, hi = np.minimum(a, b) - radius, np.maximum(a, b) + radius
    x, y = points[:, :1], points[:, 1:]
    k, s = np.nonzero((x >= lo[:, 0]) & (x <= hi[:, 0]) & (y >= lo[:, 1]) & (y <= hi[:, 1]))
    return k.astype(np.int64), s.astype(np.int64)


def _foot(points: Array, a: Array, b: Array) -> Array:
    """Each point's nearest point on its segment a[k]-b[k]: (n, 2)."""
    (sx, sy), (rx, ry) = (b - a).T, (points - a).T
    t = np.clip((rx * sx + ry * sy) / np.maximum(sx * sx + sy * sy, 1e-12), 0.0, 1.0)
    return a + t[:, None] * (b - a)


def _free_ends(walls: Sequence[WallSegments], joint: float, reach: float) -> _Ends:
    """The ends of every segment not within ``joint`` of another segment (a corner, a T)."""
    segments = [np.asarray(w.segments, dtype=float).reshape(-1, 2, 2) for w in walls]
    owners = np.concatenate([[w.id] * len(s) for w, s in zip(walls, segments, strict=True)] + [[]])
    pieces = np.concatenate(segments) if segments else np.zeros((0, 2, 2))
    a, b = pieces[:, 0], pieces[:, 1]
    point = np.concatenate([a, b])
    outward = np.concatenate([a - b, b - a])
    piece = np.tile(np.arange(len(a)), 2)
    norm = np.hypot(outward[:, 0], outward[:, 1])
    if len(a) < 2:
        keep = np.zeros(len(point), dtype=bool)
    else:
        k, s = _near(point, a, b, joint)
        k, s = k[s != piece[k]], s[s != piece[k]]
        gap = np.hypot(*(_foot(point[k], a[s], b[s]) - point[k]).T)
        joined = np.zeros(len(point), dtype=bool)
        joined[k[gap < joint]] = True
        keep = (norm > 1e-9) & ~joined
    open_at = keep.reshape(2, -1)  # (a end, b end) of each segment: not joined to a wall
    keep[keep] = ~_in_a_gap(
        point[keep], outward[keep] / norm[keep, None], piece[keep], a, b, joint, open_at
    )
    return _Ends(
        wall=owners.astype(np.int64)[piece[keep]],
        piece=piece[keep],
        point=point[keep],
        outward=outward[keep] / norm[keep, None],
        a=a,
        b=b,
        reach=reach,
    )


def _in_a_gap(
    point: Array,
    outward: Array,
    piece: NDArray[np.int64],
    a: Array,
    b: Array,
    joint: float,
    open_at: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """Ends that stop in the line of another wall, in a gap of it: a door beside a corner.

    A side room's wall meets a corridor's wall where the corridor's wall has the side room's
    door: its end is free, and the way it points crosses the corridor, where a span would cut
    the corridor in two. The door is the gap in the corridor's wall, which that wall's own end
    spans; this end opens nothing. Within twice ``joint`` of the line (a mapped end stops a
    little short), at most ``GAP_REACH`` past the wall's end, that end open (``open_at``: a
    gap's jamb, not a corner), and across it (an end in line with a wall is a door in one line
    of wall, and opens it).
    """
    k, s = _near(point, a, b, GAP_REACH + 2 * joint)
    k, s = k[s != piece[k]], s[s != piece[k]]
    seg = (b - a)[s]
    length = np.maximum(np.hypot(seg[:, 0], seg[:, 1]), 1e-12)
    unit = seg / length[:, None]
    rel = point[k] - a[s]
    along = (rel * unit).sum(axis=1)
    off_line = np.abs(rel[:, 0] * unit[:, 1] - rel[:, 1] * unit[:, 0])
    beyond = np.maximum(-along, along - length)  # past the wall's nearer end (m)
    across = np.abs((outward[k] * unit).sum(axis=1)) < math.cos(math.radians(GAP_ANGLE))
    jamb = np.where(along < 0, open_at[0][s], open_at[1][s])  # that end of the wall open
    in_gap = (off_line < 2 * joint) & (beyond > 0) & (beyond <= GAP_REACH) & across & jamb
    out = np.zeros(len(point), dtype=bool)
    out[k[in_gap]] = True
    return out


def openings(
    ends: _Ends,
    config: RoomsConfig,
    reach: float | None = None,
    angle: float | None = None,
) -> list[Opening]:
    """Every free end's opening to the nearest wall roughly along its own wall (step 1).

    ``reach`` and ``angle``: how far and how far off its wall's direction to look (the
    configuration's door width and angle unless given).
    """
    reach = config.door_max if reach is None else reach
    cos_max = math.cos(math.radians(config.door_angle if angle is None else angle))
    targets = _nearest_ahead(ends, reach, cos_max)
    ahead = np.flatnonzero(np.isfinite(targets[:, 0]))
    crossing = _crossing(ends.point[ahead], targets[ahead], ends.a, ends.b, ends.piece[ahead])
    kept = ahead[~crossing]
    point, target = ends.point[kept], targets[kept]
    # A span's key: its two ends in (x, y) order, to the centimetre; one span per key.
    swap = (target[:, 0] < point[:, 0]) | (
        (target[:, 0] == point[:, 0]) & (target[:, 1] < point[:, 1])
    )
    first, second = np.where(swap[:, None], target, point), np.where(swap[:, None], point, target)
    keys = np.round(np.concatenate([first, second], axis=1), 2).tolist()
    found: dict[tuple[float, ...], Opening] = {}
    for k, key in enumerate(keys):
        found.setdefault(tuple(key), Opening(int(ends.wall[kept[k]]), point[k], target[k]))
    return list(found.values())


def passages(ends: _Ends, config: RoomsConfig, spans: Sequence[Opening] = ()) -> list[Opening]:
    """Wider openings in one line of wall: two free ends facing each other across the gap.

    From ``door_max`` to ``passage_max`` wide, each end's wall pointing at the other within
    ``passage_angle``: an opening too wide for a door that still divides two spaces, as an
    open-plan office's passages do. Ends that already have a span (``spans``) are left.
    """
    return _facing_ends(ends, config, _ends_of(spans))


def _facing_ends(ends: _Ends, config: RoomsConfig, used: set[tuple[float, ...]]) -> list[Opening]:
    """Passages between two free ends of one line of wall, facing each other (``passages``)."""
    gap = ends.point[None, :] - ends.point[:, None]  # (i, j): from end i to end j
    dist = np.hypot(gap[..., 0], gap[..., 1])
    i, j = np.nonzero(np.triu((dist > config.door_max) & (dist <= config.passage_max), 1))
    (gx, gy), dist = gap[i, j].T, dist[i, j]
    (ox, oy), (px, py) = ends.outward[i].T, ends.outward[j].T
    cos_min = math.cos(math.radians(config.passage_angle))
    facing = ((gx * ox + gy * oy) / dist >= cos_min) & (-(gx * px + gy * py) / dist >= cos_min)
    i, j = i[facing], j[facing]
    crossing = _crossing(ends.point[i], ends.point[j], ends.a, ends.b, ends.piece[i])
    found = []
    for k, m in zip(i[~crossing].tolist(), j[~crossing].tolist(), strict=True):
        p, q = ends.point[k], ends.point[m]
        if not {_end_key(p), _end_key(q)} & used:
            found.append(Opening(int(ends.wall[k]), p.copy(), q.copy()))
            used |= {_end_key(p), _end_key(q)}
    return found


def _nearest_ahead(ends: _Ends, reach: float, cos_max: float) -> Array:
    """Per end, the nearest point of another segment ahead of it; NaN where none.

    A segment's ends or the foot on it, within ``reach``, at most ``acos(cos_max)`` off the
    end's outward direction.
    """
    found = ends.targets
    out = np.full((len(ends.point), 2), np.nan)
    if not len(found.end):
        return out
    dist = np.where((found.dist <= reach) & (found.cosine >= cos_max), found.dist, np.inf)
    first, group = found.groups
    nearest = np.minimum.reduceat(dist, first)
    hit = np.flatnonzero((dist == nearest[group]) & np.isfinite(dist))
    _, once = np.unique(group[hit], return_index=True)  # the first of a tie
    out[found.end[hit[once]]] = found.points[hit[once]]
    return out


def _end_key(point: Array) -> tuple[float, ...]:
    """A span's end as a key, to the millimetre: spans from one end are told apart by it."""
    return tuple(np.round(point, 3).tolist())


def _ends_of(spans: Sequence[Opening]) -> set[tuple[float, ...]]:
    """The ends of ``spans`` as keys (``_end_key``), rounded all at once."""
    ends = np.array([p for s in spans for p in (s.p0, s.p1)]).reshape(-1, 2)
    return set(map(tuple, np.round(ends, 3).tolist()))


def _crossing(p: Array, q: Array, a: Array, b: Array, own: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Per span p[k]-q[k]: does it pass through a segment other than ``own[k]`` (ends aside)?"""
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    low, high = np.minimum(a, b), np.maximum(a, b)
    k, s = np.nonzero(  # boxes that meet: no crossing elsewhere
        (lo[:, None, 0] <= high[None, :, 0])
        & (hi[:, None, 0] >= low[None, :, 0])
        & (lo[:, None, 1] <= high[None, :, 1])
        & (hi[:, None, 1] >= low[None, :, 1])
    )
    k, s = k[s != own[k]], s[s != own[k]]
    d, e, w = (q - p)[k], (b - a)[s], a[s] - p[k]
    denom = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / denom
        u = (w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / denom
    inner = (t > 0.02) & (t < 0.98) & (u > 0.02) & (u < 0.98)
    # Parallel (a span along the line of a wall's other piece) is no crossing: there the
    # fractions are noise over a vanishing denominator.
    inner &= np.abs(denom) > 1e-6 * np.hypot(d[:, 0], d[:, 1]) * np.hypot(e[:, 0], e[:, 1])
    out = np.zeros(len(p), dtype=bool)
    out[k[inner]] = True
    return out


class _Grid:
    """The cells over everything known: global index (i, j) -> local [i - i0, j - j0]."""

    def __init__(self, free: FreeSpace, walls: Sequence[WallSegments]) -> None:
        self.cell = free.cell
        ends = [np.asarray(w.segments, dtype=float).reshape(-1, 2) for w in walls]
        low = np.array(free.origin, dtype=np.int64)
        high = low + np.array(free.counts.shape, dtype=np.int64) - 1
        if ends and sum(len(e) for e in ends):
            points = np.floor(np.concatenate(ends) / self.cell).astype(np.int64)
            low = np.minimum(low, points.min(axis=0)) if free.counts.size else points.min(axis=0)
            high = np.maximum(high, points.max(axis=0)) if free.counts.size else points.max(axis=0)
        self.origin = low - PAD
        self.shape = tuple((high - low + 1 + 2 * PAD).tolist())
        self.free = np.zeros(self.shape, dtype=bool)
        if free.counts.size:
            at = free.origin - self.origin
            seen = free.free()
            self.free[at[0] : at[0] + seen.shape[0], at[1] : at[1] + seen.shape[1]] = seen

    def centres(self, i: NDArray[np.int64], j: NDArray[np.int64]) -> Array:
        """Map-frame centres of local cells."""
        return (np.stack([i, j], axis=-1) + self.origin + 0.5) * self.cell

    def local(
        self, points: Array
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
        """Local cell indices of map points, and whether they fall on the grid."""
        idx = np.floor(np.asarray(points) / self.cell).astype(np.int64) - self.origin
        ok = (idx >= 0).all(axis=-1) & (idx < np.array(self.shape)).all(axis=-1)
        return idx[..., 0].clip(0, self.shape[0] - 1), idx[..., 1].clip(0, self.shape[1] - 1), ok

    def draw(self, mask: NDArray[np.bool_], p: Array, q: Array, radius: float) -> None:
        """Mark the cells whose centres lie within ``radius`` of a segment p[k]-q[k] (k, 2).

        All segments at once: each one's box of cells, listed end to end, tested together.
        """
        p, q = np.asarray(p, dtype=float).reshape(-1, 2), np.asarray(q, dtype=float).reshape(-1, 2)
        lo = np.floor((np.minimum(p, q) - radius) / self.cell).astype(np.int64) - self.origin
        hi = np.floor((np.maximum(p, q) + radius) / self.cell).astype(np.int64) - self.origin
        lo, hi = np.maximum(lo, 0), np.minimum(hi, np.array(self.shape) - 1)
        size = np.maximum(hi - lo + 1, 0)  # (k, 2): cells along i and j
        count = size[:, 0] * size[:, 1]
        seg, rank = spread(count)
        ii = lo[seg, 0] + rank // np.maximum(size[seg, 1], 1)
        jj = lo[seg, 1] + rank % np.maximum(size[seg, 1], 1)
        c = self.centres(ii, jj)
        d = q - p
        t = np.einsum("nk,nk->n", c - p[seg], d[seg]) / np.maximum((d**2).sum(axis=1), 1e-12)[seg]
        foot = p[seg] + np.clip(t, 0.0, 1.0)[:, None] * d[seg]
        near = np.hypot(*(c - foot).T) <= radius
        mask[ii[near], jj[near]] = True


def find_rooms(
    walls: Sequence[WallSegments],
    free: FreeSpace,
    config: RoomsConfig | None = None,
    outlines: Outlines | None = None,
) -> Layout:
    """Rooms and doors of the map's walls and the seen floor (steps 1-3 of the module's doc).

    ``outlines``: the last segmentation's rooms by their cells, to reuse the outline of a room
    whose cells did not change (most, between two updates of a large map); updated in place.
    """
    config = config or RoomsConfig()
    grid = _Grid(free, walls)
    if not grid.free.any():
        return Layout([], [])
    radius = max(config.barrier, 0.75 * grid.cell)  # no 4-connected path slips through a line
    drawn = np.zeros(grid.shape, dtype=bool)
    ends = _free_ends(
        walls,
        config.joint,
        max(config.door_max, config.passage_max, config.divider_max, config.blind_max),
    )
    grid.draw(drawn, ends.a, ends.b, radius)
    spans = [o for o in openings(ends, config) if o.width > 0]
    spans += passages(ends, config, spans)
    dividers = _divider_spans(grid, ends, spans, config)
    barrier = _barrier(grid, drawn, ends, spans, dividers, config, radius)
    labels, rooms = _regions(grid, barrier, config)
    kept = [d for d in dividers if _divides(grid, labels, d, radius, ends, config)]
    if len(kept) < len(dividers):  # one that divides no two rooms is no divider: without it
        barrier = _barrier(grid, drawn, ends, spans, kept, config, radius)
        labels, rooms = _regions(grid, barrier, config)
    spans += kept
    for k, closed in enumerate(rooms):
        if not closed:
            _fill_open(grid, labels, barrier, k, config.fill_reach)
    _grow(labels, barrier, math.ceil(radius / grid.cell))
    shapes = _shapes(grid, _cells_of(labels, len(rooms)), rooms, config, outlines)
    _bounding_walls(grid, labels, walls, shapes, radius)
    doors = _doors(grid, labels, [s for s in spans if s.width >= config.door_min], radius)
    return Layout(shapes, doors)


def _barrier(
    grid: _Grid,
    walls: NDArray[np.bool_],
    ends: _Ends,
    spans: list[Opening],
    dividers: list[Opening],
    config: RoomsConfig,
    radius: float,
) -> NDArray[np.bool_]:
    """The walls drawn (``walls``) with the spans, the dividers and the blind spans closed.

    An end a divider starts from is the divider's; once the divider is dropped (it divides
    nothing), the end is open again, and what nothing was seen through from it is glass.
    """
    barrier = walls.copy()
    blind = _blind_spans(grid, ends, spans + dividers, config)
    _draw_spans(grid, barrier, [*spans, *dividers, *blind], radius)
    return barrier


def _draw_spans(
    grid: _Grid, barrier: NDArray[np.bool_], spans: list[Opening], radius: float
) -> None:
    """Spans closed: drawn into ``barrier``."""
    grid.draw(barrier, np.array([o.p0 for o in spans]), np.array([o.p1 for o in spans]), radius)


def _divides(
    grid: _Grid,
    labels: NDArray[np.int32],
    span: Opening,
    radius: float,
    ends: _Ends,
    config: RoomsConfig,
) -> bool:
    """Whether the door part of a divider's span leads from a room to another space.

    Another room on its other side; or, where the span goes on along a line of wall (its far
    end's wall within ``GAP_ANGLE`` of it: a side room's door and glass beside it) and its
    door is a door's width, floor seen beyond it that makes no room. That is a glimpse
    through the door, too little to serve, which leaks to unexplored space round the walls
    the map lacks; without the divider it joins the room. A span whose far end meets a wall
    across it cuts off a corner of the room, and what is seen beyond it there is the room's
    own floor before glass; a sliver crossed between two pieces of a wall mapped a little
    apart (poses that drift) is no door.
    """
    p0, p1 = span.door or (span.p0, span.p1)
    sides, along, normal = _sides(grid, labels, p0[None], p1[None], radius)
    first, second = sides[0]
    if max(first, second) < 0 or first == second:
        return False
    if min(first, second) >= 0:
        return True
    if not config.door_min <= float(np.hypot(*(p1 - p0))) <= config.door_max:
        return False
    seen = _seen_beyond(grid, sides, along, normal, radius)
    return _goes_on_along(ends, span) and bool(seen[0])


def _goes_on_along(ends: _Ends, span: Opening) -> bool:
    """Whether the span goes on along a line of wall: a wall at its far end within ``GAP_ANGLE``."""
    _, s = _near(span.p1[None], ends.a, ends.b, 0.05)
    direction = (span.p1 - span.p0) / max(span.width, 1e-12)
    seg = ends.b[s] - ends.a[s]
    length = np.maximum(np.hypot(seg[:, 0], seg[:, 1]), 1e-12)
    near = np.hypot(*(_foot(span.p1[None], ends.a[s], ends.b[s]) - span.p1).T) < 0.05
    along = np.abs(seg @ direction) / length >= math.cos(math.radians(GAP_ANGLE))
    return bool((near & along).any())


def _divider_spans(
    grid: _Grid, ends: _Ends, spans: list[Opening], config: RoomsConfig
) -> list[Opening]:
    """Dividers whose piece beyond the door was never mapped: door and unseen wall in one span.

    From an end left open, along its wall (``passage_angle``) to another wall, ``door_max`` to
    ``divider_max`` long, from a piece of wall ``divider_min`` long or more: a door candidate
    when the robot or its rays crossed part of it and an end of it, ``door_min`` or more, was
    never seen (``door_span`` finds the door, at most ``passage_max`` wide). A span longer
    than ``passage_max`` (an open-plan passage and glass beside it) must have its door by
    the end it starts from: one crossed at its far end only, from a piece of wall across
    the room, cuts a corner off a room whose walls there are glass. A span seen free all
    along is open floor, not a divider, and stays open. Whether it divides two rooms is
    known only once the floor is divided (``find_rooms`` keeps those that do).
    """
    used = _ends_of(spans)
    length = np.hypot(*(ends.b - ends.a).T)
    found = []
    for span in openings(ends, config, config.divider_max, config.passage_angle):
        if _end_key(span.p0) in used or span.width <= config.door_max:
            continue
        k = int(np.argmin(np.hypot(*(ends.point - span.p0).T)))  # the end it starts from
        if length[ends.piece[k]] < config.divider_min:
            continue  # a pillar's face, a cupboard's side: no divider
        door = door_span(grid, span, config.door_min)
        width = float(np.hypot(*(door[1] - door[0])))
        beside = span.width <= config.passage_max or bool(np.all(door[0] == span.p0))
        if width < span.width - config.door_min / 2 and width <= config.passage_max and beside:
            found.append(dataclasses.replace(span, door=door))
            used |= _ends_of([span])
    return found


def _blind_spans(
    grid: _Grid, ends: _Ends, spans: list[Opening], config: RoomsConfig
) -> list[Opening]:
    """Longer spans from ends left open that nothing was ever seen through: glass, closed.

    A wall the sensor cannot see (glass across the band) leaves its neighbours' ends open; the
    rays stop at it and the robot does not cross it, so the floor along the span is unseen.
    A passage the robot drove or looked through is seen free and stays open.
    """
    used = _ends_of(spans)
    found = []
    for span in openings(ends, config, config.blind_max, config.blind_angle):
        if _end_key(span.p0) in used or span.width <= config.door_max:
            continue
        t = np.linspace(0.0, 1.0, max(3, int(span.width / grid.cell)))[:, None]
        i, j, ok = grid.local(span.p0 + t * (span.p1 - span.p0))
        if grid.free[i[ok], j[ok]].mean() <= config.blind_seen if ok.any() else True:
            found.append(span)
    return found


def _regions(
    grid: _Grid, barrier: NDArray[np.bool_], config: RoomsConfig
) -> tuple[NDArray[np.int32], list[bool]]:
    """Room labels per cell (-1: none) and whether each room is closed (step 2)."""
    regions, n = label(~barrier)
    leaky = touches_border(regions, n)
    min_cells = config.min_area / grid.cell**2
    seen = _counts(np.where(grid.free, regions, -1), n)
    # Enclosed, and mostly seen: spans closed across unexplored space (it looks like glass:
    # nothing seen through) can enclose more unknown than floor; such a region is open.
    leaky |= seen < config.closed_seen * _counts(regions, n)
    enclosed = np.flatnonzero((seen >= min_cells) & ~leaky)
    room_of = np.full(n + 1, -1, dtype=np.int32)  # region -> room; the last entry for -1
    room_of[enclosed] = np.arange(len(enclosed))
    closed = [True] * len(enclosed)
    pieces, m = label(grid.free & np.append(leaky, False)[regions])  # open regions' seen floor
    kept = np.flatnonzero(_counts(pieces, m) >= config.min_open_area / grid.cell**2)
    piece_room = np.full(m + 1, -1, dtype=np.int32)
    piece_room[kept] = len(closed) + np.arange(len(kept))
    labels = np.where(pieces >= 0, piece_room[pieces], room_of[regions])
    return labels, closed + [False] * len(kept)


def _counts(labels: NDArray[np.int32], n: int) -> NDArray[np.int64]:
    """Cells per label 0..n-1 (-1: none)."""
    return np.bincount(labels.ravel() + 1, minlength=n + 1)[1:]


def _fill_open(
    grid: _Grid, labels: NDArray[np.int32], barrier: NDArray[np.bool_], k: int, reach: float
) -> None:
    """An open room's unseen floor within the hull of its seen floor and the walls it faces.

    Glass returns nothing, so the floor before it is never seen: the room's walls and seen
    floor still span it. Only cells of no room and no barrier are taken, only those the
    room's own cells reach within the hull without crossing a barrier, and only within
    ``reach`` (m) of them: the hull of a kinked corridor spans much that is not corridor.
    """
    mine = labels == k
    near = barrier & _dilate(mine, 2)
    ii, jj = np.nonzero(_edge(mine) | near)
    if len(ii) < 3:
        return
    hull = convex_hull(np.stack([ii, jj], axis=1).astype(float))
    lo, hi = hull.min(axis=0).astype(int), hull.max(axis=0).astype(int)
    bi, bj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    inside = inside_polygon(np.stack([bi.ravel(), bj.ravel()], axis=1) + 0.0, hull).reshape(
        bi.shape
    )
    box_labels = labels[bi, bj]
    open_floor = inside & ((box_labels < 0) | (box_labels == k)) & ~barrier[bi, bj]
    # Only what the room reaches within its hull without crossing a wall, and within ``reach``
    # along the floor: not the space behind one of its walls that the hull happens to span,
    # nor floor round the end of a wall the map does not have yet.
    reached = _dilate(box_labels == k, round(reach / grid.cell), within=open_floor)
    take = reached & (box_labels < 0)
    labels[bi[take], bj[take]] = k


def _dilate(
    mask: NDArray[np.bool_], steps: int, within: NDArray[np.bool_] | None = None
) -> NDArray[np.bool_]:
    """``mask`` grown ``steps`` cells (4-neighbours), through ``within`` cells only if given."""
    out = mask.copy()
    for _ in range(steps):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown[:, 1:] |= out[:, :-1]
        grown[:, :-1] |= out[:, 1:]
        if within is not None:
            grown &= within | mask
        out = grown
    return out


def _edge(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Cells of ``mask`` with a neighbour outside it."""
    return mask & _dilate(~mask, 1)


def _grow(labels: NDArray[np.int32], barrier: NDArray[np.bool_], steps: int) -> None:
    """Each room's cells grown ``steps`` cells into the barrier it faces (walls' half width)."""
    for _ in range(steps):
        for shift, axis in ((1, 0), (-1, 0), (1, 1), (-1, 1)):
            moved = np.roll(labels, shift, axis=axis)
            take = barrier & (labels < 0) & (moved >= 0)
            labels[take] = moved[take]


def _cells_of(labels: NDArray[np.int32], n: int) -> list[NDArray[np.int64]]:
    """Each room's cells (local (i, j)), from one pass over the grid."""
    flat = labels.ravel()
    at = np.flatnonzero(flat >= 0)
    order = np.argsort(flat[at], kind="stable")
    bounds = np.cumsum(np.bincount(flat[at], minlength=n))
    cells = np.stack(np.divmod(at[order], labels.shape[1]), axis=1)
    return np.split(cells, bounds[:-1]) if n else []


Outlines = dict[tuple[bool, bytes], RoomShape]  # (closed, global cells' bytes) -> shape


def _shapes(
    grid: _Grid,
    cells: list[NDArray[np.int64]],
    closed: list[bool],
    config: RoomsConfig,
    outlines: Outlines | None,
) -> list[RoomShape]:
    """Each room's shape, the last segmentation's where its cells are the same (``outlines``)."""
    known = {} if outlines is None else outlines
    shapes, kept = [], {}
    for mine, shut in zip(cells, closed, strict=True):
        key = (shut, (mine + grid.origin).tobytes())
        shape = known.get(key) or _shape(grid, mine, shut, config)
        kept[key] = shape
        shapes.append(dataclasses.replace(shape, walls=[]))
    if outlines is not None:
        outlines.clear()
        outlines.update(kept)
    return shapes


def _shape(grid: _Grid, cells: NDArray[np.int64], closed: bool, config: RoomsConfig) -> RoomShape:
    """A room's outline (map frame, counter-clockwise), area and centroid from its cells.

    Outlined on the room's own box of the grid, not the whole: a building has many rooms.
    """
    low = cells.min(axis=0)
    box = np.zeros(tuple(cells.max(axis=0) - low + 1), dtype=bool)
    box[cells[:, 0] - low[0], cells[:, 1] - low[1]] = True
    corners = outline(box) + low
    polygon = simplify((corners + grid.origin) * grid.cell, config.simplify)
    return RoomShape(
        polygon=polygon,
        area=abs(polygon_area(polygon)),
        centroid=polygon_centroid(polygon),
        closed=closed,
        cells=cells + grid.origin,
    )


def _bounding_walls(
    grid: _Grid,
    labels: NDArray[np.int32],
    walls: Sequence[WallSegments],
    shapes: list[RoomShape],
    radius: float,
) -> None:
    """Each room's walls: those with a share of their length facing its cells.

    Each segment is sampled every 20 cm (from a tenth to nine tenths of it) and looked at from
    both sides, just past the barrier; a wall bounds a room whose cells are in front of a fifth
    of its samples (two at least).
    """
    reach = radius + 1.5 * grid.cell
    pieces = [np.asarray(w.segments, dtype=float).reshape(-1, 2, 2) for w in walls]
    if not shapes or not sum(len(piece) for piece in pieces):
        return
    owner = np.concatenate([np.full(len(piece), k) for k, piece in enumerate(pieces)])
    a, b = np.concatenate(pieces)[:, 0], np.concatenate(pieces)[:, 1]
    length = np.hypot(*(b - a).T)
    real = length >= 1e-9
    a, b, length, owner = a[real], b[real], length[real], owner[real]
    n = np.maximum(2, (length / 0.2).astype(np.int64))
    seg, rank = spread(n)
    t = 0.1 + 0.8 * rank / (n[seg] - 1)
    along = a[seg] + t[:, None] * (b - a)[seg]
    normal = np.stack([a[:, 1] - b[:, 1], b[:, 0] - a[:, 0]], axis=1) / length[:, None]
    rooms = len(shapes)
    hits = np.zeros(len(walls) * rooms, dtype=np.int64)
    for side in (1.0, -1.0):
        i, j, ok = grid.local(along + side * reach * normal[seg])
        room = labels[i, j]
        ok &= room >= 0
        hits += np.bincount(owner[seg][ok] * rooms + room[ok], minlength=len(hits))
    total = np.bincount(owner, weights=n, minlength=len(walls))
    for k, room in np.argwhere(
        hits.reshape(len(walls), rooms) >= np.maximum(2, 0.2 * total)[:, None]
    ).tolist():
        shapes[room].walls.append(walls[k].id)


def _doors(
    grid: _Grid, labels: NDArray[np.int32], spans: list[Opening], radius: float
) -> list[DoorShape]:
    """The spans that are doors (step 3): seen through, and other rooms (or none) each side."""
    if not spans:
        return []
    p0, p1 = np.array([s.p0 for s in spans]), np.array([s.p1 for s in spans])
    sides, along, normal = _sides(grid, labels, p0, p1, radius)
    crossed = _free_near(grid, along)  # else never crossed: glass or a niche, wall for the rooms
    # Towards no room, and nothing seen beyond it either: not an opening.
    beyond = _seen_beyond(grid, sides, along, normal, radius)
    lone = sides.min(axis=1) < 0
    door = crossed & (sides[:, 0] != sides[:, 1]) & (sides.max(axis=1) >= 0) & (~lone | beyond)
    return [
        DoorShape(
            *(span.door or (span.p0, span.p1)), span.wall, tuple(sorted(r for r in two if r >= 0))
        )
        for span, two in zip(
            [spans[k] for k in np.flatnonzero(door)], sides[door].tolist(), strict=True
        )
    ]


def door_span(grid: _Grid, span: Opening, door_min: float) -> tuple[Array, Array]:
    """The door in a wide span: the stretch the robot or its rays crossed, to its jambs.

    A divider whose piece beyond its door was never mapped (glass, or too little seen) leaves a
    span of door and unmapped wall. Nothing is seen through the wall, so its stretch at one end
    of the span is unseen: the longer unseen end, if ``door_min`` or more, is cut off. The
    other end's unseen stretch is door beside its jamb that no ray happened to cross (floor
    by a jamb is often hidden from every view the robot had). Gaps of up to ``TRIM_GAP``
    along the span are bridged.
    """
    steps = max(3, math.ceil(2 * span.width / grid.cell))
    t = np.linspace(0.0, 1.0, steps)
    i, j, ok = grid.local(span.p0 + t[:, None] * (span.p1 - span.p0))
    at = np.flatnonzero(ok & grid.free[i, j])
    if not len(at):
        return span.p0, span.p1
    bridge = math.ceil(TRIM_GAP / (span.width / (steps - 1)))
    runs = np.split(at, np.flatnonzero(np.diff(at) > bridge) + 1)
    run = max(runs, key=lambda r: r[-1] - r[0])
    before, after = t[run[0]], 1.0 - t[run[-1]]  # unseen at each end, shares of the span
    if max(before, after) * span.width < door_min:
        return span.p0, span.p1
    lo, hi = (t[run[0]], 1.0) if before > after else (0.0, t[run[-1]])
    return span.p0 + lo * (span.p1 - span.p0), span.p0 + hi * (span.p1 - span.p0)


def _sides(
    grid: _Grid, labels: NDArray[np.int32], p0: Array, p1: Array, radius: float
) -> tuple[NDArray[np.int64], Array, Array]:
    """The room each side of spans p0[k]-p1[k] (n, 2), -1 for none.

    Each side's is the most common label (the smallest of a tie) at five points along the
    span, just past the barrier. Also the five points (n, 5, 2) and each span's unit normal
    (n, 2), the first side's way.
    """
    along = p0[:, None] + np.linspace(0.2, 0.8, 5)[None, :, None] * (p1 - p0)[:, None]
    d = p1 - p0
    normal = np.stack([-d[:, 1], d[:, 0]], axis=1)
    normal /= np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    sides = []
    for side in (normal, -normal):
        i, j, ok = grid.local(along + (radius + 2.5 * grid.cell) * side[:, None])
        found = np.where(ok, labels[i, j], -1)  # (n, 5)
        valid = found >= 0
        count = ((found[:, :, None] == found[:, None, :]) & valid[:, None, :]).sum(axis=2) * valid
        best = np.argmax(count * (found.max() + 2) - found, axis=1)  # most, then smallest
        sides.append(np.where(valid.any(axis=1), found[np.arange(len(found)), best], -1))
    return np.stack(sides, axis=1), along, normal


def _seen_beyond(
    grid: _Grid, sides: NDArray[np.int64], along: Array, normal: Array, radius: float
) -> NDArray[np.bool_]:
    """Per span, floor seen free just past it on its side with no room (``_sides``' output).

    As far out as ``_sides`` looks: past the barrier, on the second side's way if the first
    has a room, else on the first's.
    """
    towards_none = np.where((sides[:, 0] < 0)[:, None], normal, -normal)
    return _free_near(grid, along + (radius + 2.5 * grid.cell) * towards_none[:, None])


def _free_near(grid: _Grid, points: Array) -> NDArray[np.bool_]:
    """Per span, seen free floor within a cell of any of its points (n, m, 2).

    Within a cell, not on: the opening's own cells are barrier-drawn.
    """
    steps = np.array([(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1)]) * grid.cell
    i, j, ok = grid.local(points[:, :, None] + steps)
    return (grid.free[i, j] & ok).any(axis=(1, 2))
