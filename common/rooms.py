"""Rooms and the doors between them, from the wall map and the floor the sensor saw free.

A room is a region of seen floor bounded by walls and doors; a corridor is a room. The method,
on a grid of ``FreeSpace``'s cells:

1. **Openings.** Every end of a wall's segment that stops short of the next wall (or of the
   next segment of its own wall) leaves an opening: the shortest span from that end, roughly
   along its wall (``door_angle``), to another wall's end or face, at most ``door_max`` long.
   Walls under ``standing_max`` across that meet no longer wall (a pillar) open nothing.
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

import copy
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wallmap.common import compiled
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
TRIM_GAP = 0.3  # m of a door unseen, bridged where wider gaps would leave no wall (door_span)
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
        standing_max: widest piece of wall (m) that no longer wall meets to be free-standing
            (a pillar, a cupboard's side): an obstacle, where no opening starts or ends.
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
    standing_max: float = 0.6


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
        (x0, y0), (x1, y1) = self.p0.tolist(), self.p1.tolist()
        return math.hypot(x1 - x0, y1 - y0)


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
class _Segments:
    """Every wall's segments, end to end: read from the walls once per segmentation."""

    a: Array  # (s, 2) each segment's first end
    b: Array  # (s, 2) ...and second
    owner: NDArray[np.int64]  # (s,) its wall, an index into the walls
    wall: NDArray[np.int64]  # (s,) its wall's id

    @classmethod
    def of(cls, walls: Sequence[WallSegments]) -> _Segments:
        """The segments of ``walls``, in their order."""
        pieces = [np.asarray(w.segments, dtype=float).reshape(-1, 2, 2) for w in walls]
        joined = np.concatenate([np.zeros((0, 2, 2)), *pieces])
        owner = np.repeat(np.arange(len(pieces)), [len(piece) for piece in pieces])
        ids = np.array([w.id for w in walls], dtype=np.int64)
        return cls(joined[:, 0], joined[:, 1], owner, ids[owner])


@dataclass(frozen=True)
class _Ends:
    """The segment ends no other wall meets (where openings may start), and all segments."""

    wall: NDArray[np.int64]  # (e,) the wall of each end
    piece: NDArray[np.int64]  # (e,) its segment, an index into a and b
    point: Array  # (e, 2)
    outward: Array  # (e, 2) unit: the way its segment would go on
    a: Array  # (s, 2) every segment's first end
    b: Array  # (s, 2) ...and second

    def left_open(self, used: set[tuple[float, ...]]) -> NDArray[np.int64]:
        """The ends that are no end of a span found (``used``, as ``_end_key``s)."""
        keys = _keys(self.point)
        return np.array([k for k, key in enumerate(keys) if key not in used], dtype=np.int64)


def _near(
    points: Array, a: Array, b: Array, radius: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (point k, segment s) with the point within ``radius`` of the segment's box.

    Every pair within ``radius`` of each other is among them, and in a large map few more:
    the exact tests run on these alone, not on every end against every segment.
    """
    lo, hi = np.minimum(a, b) - radius, np.maximum(a, b) + radius
    return compiled.room_kernels().near_pairs(compiled.plain(points, np.float64), lo, hi)


def _foot(points: Array, a: Array, b: Array) -> Array:
    """Each point's nearest point on its segment a[k]-b[k]: (n, 2)."""
    (sx, sy), (rx, ry) = (b - a).T, (points - a).T
    t = np.clip((rx * sx + ry * sy) / np.maximum(sx * sx + sy * sy, 1e-12), 0.0, 1.0)
    return a + t[:, None] * (b - a)


def _joins(segments: _Segments, joint: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (end k, segment s) where an end meets another segment: a corner, a T.

    End k is of the segments' first ends, then their second ends; within ``joint`` of s.
    """
    a, b = segments.a, segments.b
    if len(a) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    point, piece = np.concatenate([a, b]), np.tile(np.arange(len(a)), 2)
    k, s = _near(point, a, b, joint)
    k, s = k[s != piece[k]], s[s != piece[k]]
    gap = np.hypot(*(_foot(point[k], a[s], b[s]) - point[k]).T)
    return k[gap < joint], s[gap < joint]


def _free_ends(
    segments: _Segments,
    joint: float,
    joins: tuple[NDArray[np.int64], NDArray[np.int64]],
    standing: NDArray[np.bool_],
) -> _Ends:
    """The ends of every segment no other segment ``joins`` (a corner, a T).

    Free-standing pieces (``standing``) are left out, as ends and as segments: no opening
    starts or ends at a pillar, whose faces would otherwise cut a room with false doors.
    """
    a, b = segments.a, segments.b
    point = np.concatenate([a, b])
    outward = np.concatenate([a - b, b - a])
    piece = np.tile(np.arange(len(a)), 2)
    norm = np.hypot(outward[:, 0], outward[:, 1])
    joined = np.zeros(len(point), dtype=bool)
    joined[joins[0]] = True
    keep = (norm > 1e-9) & ~joined & ~standing[piece]
    open_at = keep.reshape(2, -1)  # (a end, b end) of each segment: not joined to a wall
    keep[keep] = ~_in_a_gap(
        point[keep], outward[keep] / norm[keep, None], piece[keep], a, b, joint, open_at
    )
    solid = np.cumsum(~standing) - 1  # a segment's index among those not free-standing
    return _Ends(
        wall=segments.wall[piece[keep]],
        piece=solid[piece[keep]],
        point=point[keep],
        outward=outward[keep] / norm[keep, None],
        a=a[~standing],
        b=b[~standing],
    )


def _free_standing(
    segments: _Segments, joins: tuple[NDArray[np.int64], NDArray[np.int64]], most: float
) -> NDArray[np.bool_]:
    """Per segment, whether its piece of wall stands free in a room: a pillar, a cupboard's side.

    Walls under ``most`` across, joined (``joins``) to no longer wall, together under ``most``
    across. (A depth camera sees metres of a building's wall at once: a piece this short on
    its own is an object in the room.) Only short walls can be part of one, so the pieces are
    put together from those alone.
    """
    a, b, owner = segments.a, segments.b, segments.owner
    n = int(owner.max()) + 1 if len(owner) else 0
    low, high = np.full((n, 2), np.inf), np.full((n, 2), -np.inf)
    for ends in (a, b):
        np.minimum.at(low, owner, ends)
        np.maximum.at(high, owner, ends)
    short = np.hypot(*(high - low).T) < most
    parent = {int(w): int(w) for w in np.flatnonzero(short)}

    def root(w: int) -> int:
        while parent[w] != w:
            parent[w] = parent[parent[w]]
            w = parent[w]
        return w

    attached = []  # short walls joined to a longer one
    pairs = owner[joins[0] % len(a)], owner[joins[1]]  # end k is an end of segment k mod n
    for v, w in zip(*(side.tolist() for side in pairs), strict=True):
        if short[v] and short[w]:
            parent[root(v)] = root(w)
        elif short[v] or short[w]:
            attached.append(v if short[v] else w)
    pieces: dict[int, list[int]] = {}
    for w in parent:
        pieces.setdefault(root(w), []).append(w)
    for w in attached:
        pieces.pop(root(w), None)
    standing = np.zeros(n, dtype=bool)
    for members in pieces.values():
        if np.hypot(*(high[members].max(axis=0) - low[members].min(axis=0))) < most:
            standing[members] = True
    return standing[owner]


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
    among: NDArray[np.int64] | None = None,
) -> list[Opening]:
    """Every free end's opening to the nearest wall roughly along its own wall (step 1).

    ``reach`` and ``angle``: how far and how far off its wall's direction to look (the
    configuration's door width and angle unless given). ``among``: the ends to look from
    (indices, ascending), all unless given.
    """
    reach = config.door_max if reach is None else reach
    cos_max = math.cos(math.radians(config.door_angle if angle is None else angle))
    among = np.arange(len(ends.point)) if among is None else among
    targets = _nearest_ahead(ends, among, reach, cos_max)
    ahead = np.flatnonzero(np.isfinite(targets[:, 0]))
    targets[ahead] = _to_a_corner(ends, ahead, targets[ahead], cos_max, config.joint)
    ahead = ahead[np.hypot(*(targets[ahead] - ends.point[ahead]).T) <= reach]
    crossing = _crossing(ends.point[ahead], targets[ahead], ends.a, ends.b, ends.piece[ahead])
    kept = ahead[~crossing]
    point, target = ends.point[kept], targets[kept]
    # A span's key: its two ends in (x, y) order, to the centimetre; one span per key.
    swap = (target[:, 0] < point[:, 0]) | (
        (target[:, 0] == point[:, 0]) & (target[:, 1] < point[:, 1])
    )
    first, second = np.where(swap[:, None], target, point), np.where(swap[:, None], point, target)
    keys = np.round(np.concatenate([first, second], axis=1), 2).tolist()
    once: dict[tuple[float, ...], int] = {}  # each key's first span
    for k, key in enumerate(keys):
        once.setdefault(tuple(key), k)
    walls = ends.wall[kept].tolist()
    return [Opening(walls[k], point[k], target[k]) for k in once.values()]


def _to_a_corner(
    ends: _Ends, starts: NDArray[np.int64], targets: Array, cos_max: float, slack: float
) -> Array:
    """Each span's far end moved to the end of the wall it meets, if that is nearly as near.

    A span closes the gap to the next wall; where that wall's end (a corner) lies ahead within
    the angle and at most ``slack`` farther than the nearest point of it, the span ends there
    (and is then held to its reach as it is). The nearest point is on its face when the wall
    the span starts from kinks where glass begins: a span so drawn cuts a sliver of seen
    floor off the room, and the sliver's edge looked like a door to nowhere (clutter seed 500).
    """
    k, s = _near(targets, ends.a, ends.b, 1e-6)
    if not len(k):
        return targets
    corner = np.concatenate([ends.a[s], ends.b[s]])  # each wall met: its two ends
    k, s = np.tile(k, 2), np.tile(s, 2)
    start, outward = ends.point[starts[k]], ends.outward[starts[k]]
    step = corner - start
    dist = np.hypot(*step.T)
    ok = (step * outward).sum(axis=1) >= cos_max * dist  # ahead, within the angle
    ok &= (dist <= np.hypot(*(targets[k] - start).T) + slack) & (dist > 1e-9)
    ok &= s != ends.piece[starts[k]]
    k, corner, dist = k[ok], corner[ok], dist[ok]
    order = np.lexsort((dist, k))  # per span the nearest corner (the first of equals)
    spans, first = np.unique(k[order], return_index=True)
    moved = targets.copy()
    moved[spans] = corner[order[first]]
    return moved


def passages(ends: _Ends, config: RoomsConfig, spans: Sequence[Opening] = ()) -> list[Opening]:
    """Wider openings in one line of wall: two free ends facing each other across the gap.

    From ``door_max`` to ``passage_max`` wide, each end's wall pointing at the other within
    ``passage_angle``: an opening too wide for a door that still divides two spaces, as an
    open-plan office's passages do. Ends that already open a span (``spans``) are left; an
    end another's span only reaches (a glass wall's neighbour opening onto it) may still be a
    passage's.
    """
    used = set(_keys([span.p0 for span in spans]))
    among = ends.left_open(used)
    point = ends.point[among]
    reach = config.passage_max
    i, j = compiled.room_kernels().near_pairs(point, point - reach, point + reach)
    i, j = i[i < j], j[i < j]
    (gx, gy) = (point[j] - point[i]).T  # from end i to end j
    dist = np.hypot(gx, gy)
    apart = (dist > config.door_max) & (dist <= reach)
    i, j, gx, gy, dist = among[i[apart]], among[j[apart]], gx[apart], gy[apart], dist[apart]
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


def _nearest_ahead(ends: _Ends, among: NDArray[np.int64], reach: float, cos_max: float) -> Array:
    """Per end of ``among``, the nearest point of another segment ahead of it; NaN where none.

    A segment's ends or the foot on it, within ``reach``, at most ``acos(cos_max)`` off the
    end's outward direction. A tie in distance goes to the first of all segments' first ends,
    then their second ends, then the feet (``room_kernels.nearest_ahead``).
    """
    return compiled.room_kernels().nearest_ahead(
        compiled.plain(among, np.int64),
        ends.point,
        ends.outward,
        ends.piece,
        compiled.plain(ends.a, np.float64),
        compiled.plain(ends.b, np.float64),
        reach,
        cos_max,
    )


def _end_key(point: Array) -> tuple[float, ...]:
    """A span's end as a key, to the millimetre: spans from one end are told apart by it."""
    return tuple(np.round(point, 3).tolist())


def _ends_of(spans: Sequence[Opening]) -> set[tuple[float, ...]]:
    """The ends of ``spans`` as keys (``_end_key``)."""
    return set(_keys([p for s in spans for p in (s.p0, s.p1)]))


def _keys(points: Sequence[Array] | Array) -> list[tuple[float, ...]]:
    """Points as keys (``_end_key``), rounded all at once."""
    return list(map(tuple, np.round(np.reshape(points, (-1, 2)), 3).tolist()))


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

    def __init__(self, free: FreeSpace, segments: _Segments) -> None:
        """Over the floor seen free and every wall's ends, ``PAD`` cells round them.

        Not over all of ``free``'s grid: it grows by wide margins, and every step of the
        segmentation costs by the cell.
        """
        self.cell = free.cell
        seen = free.free()
        rows, cols = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
        ends = np.concatenate([segments.a, segments.b])
        known = [np.floor(ends / self.cell).astype(np.int64)]
        if len(rows):
            known.append(free.origin + np.array([[rows[0], cols[0]], [rows[-1], cols[-1]]]))
        points = np.concatenate(known) if sum(map(len, known)) else np.zeros((1, 2), np.int64)
        low, high = points.min(axis=0), points.max(axis=0)
        self.origin = low - PAD
        self.shape = tuple((high - low + 1 + 2 * PAD).tolist())
        self.free = np.zeros(self.shape, dtype=bool)
        if len(rows):
            at = free.origin + np.array([rows[0], cols[0]]) - self.origin
            part = seen[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
            self.free[at[0] : at[0] + part.shape[0], at[1] : at[1] + part.shape[1]] = part

    def local(
        self, points: Array
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
        """Local cell indices of map points, and whether they fall on the grid."""
        idx = np.floor(np.asarray(points) / self.cell).astype(np.int64) - self.origin
        ok = (idx >= 0).all(axis=-1) & (idx < np.array(self.shape)).all(axis=-1)
        return idx[..., 0].clip(0, self.shape[0] - 1), idx[..., 1].clip(0, self.shape[1] - 1), ok

    def draw(self, mask: NDArray[np.bool_], p: Array, q: Array, radius: float) -> None:
        """Mark the cells whose centres lie within ``radius`` of a segment p[k]-q[k] (k, 2)."""
        p = compiled.plain(np.reshape(p, (-1, 2)), np.float64)
        q = compiled.plain(np.reshape(q, (-1, 2)), np.float64)
        lo = np.floor((np.minimum(p, q) - radius) / self.cell).astype(np.int64) - self.origin
        hi = np.floor((np.maximum(p, q) + radius) / self.cell).astype(np.int64) - self.origin
        lo, hi = np.maximum(lo, 0), np.minimum(hi, np.array(self.shape) - 1)
        compiled.room_kernels().draw_segments(mask, lo, hi, p, q, self.origin, self.cell, radius)


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
    segments = _Segments.of(walls)
    grid = _Grid(free, segments)
    if not grid.free.any():
        return Layout([], [])
    radius = max(config.barrier, 0.75 * grid.cell)  # no 4-connected path slips through a line
    drawn = np.zeros(grid.shape, dtype=bool)
    joins = _joins(segments, config.joint)
    standing = _free_standing(segments, joins, config.standing_max)
    ends = _free_ends(segments, config.joint, joins, standing)
    grid.draw(drawn, segments.a, segments.b, radius)
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
    compiled.room_kernels().grow(labels, barrier, math.ceil(radius / grid.cell))
    shapes = _shapes(grid, _cells_of(grid, labels, len(rooms)), rooms, config, outlines)
    _bounding_walls(grid, labels, walls, segments, shapes, radius)
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
    among = ends.left_open(used)
    for nearest in openings(ends, config, config.divider_max, config.passage_angle, among):
        k = int(np.argmin(np.hypot(*(ends.point - nearest.p0).T)))  # the end it starts from
        span = _along_its_line(ends, k, nearest, config.joint)
        if _end_key(span.p0) in used or not config.door_max < span.width <= config.divider_max:
            continue
        if length[ends.piece[k]] < config.divider_min:
            continue  # a pillar's face, a cupboard's side: no divider
        door = door_span(grid, span, config.door_min)
        width = float(np.hypot(*(door[1] - door[0])))
        beside = span.width <= config.passage_max or bool(np.all(door[0] == span.p0))
        if width < span.width - config.door_min / 2 and width <= config.passage_max and beside:
            found.append(dataclasses.replace(span, door=door))
            used |= _ends_of([span])
    return found


def _along_its_line(ends: _Ends, k: int, span: Opening, reach: float) -> Opening:
    """A divider's span from end ``k``, along the line of its own wall to the wall it meets.

    The nearest point ahead (``openings``) may lie off that line: where the wall met was
    mapped short of the corner (glass below it), the span runs up to 15 degrees off towards
    its mapped end, into the next room, whose floor then looks like the door. Along the
    line, the span ends where it meets that wall's line, on the wall or at most ``reach``
    past its mapped end; else it stays as found.
    """
    _, s = _near(span.p1[None], ends.a, ends.b, 1e-6)
    if not len(s):
        return span
    a, b = ends.a[s[0]], ends.b[s[0]]
    d, e = ends.outward[k], b - a
    denom = d[0] * e[1] - d[1] * e[0]
    length = math.hypot(*e)
    if abs(denom) < math.sin(math.radians(GAP_ANGLE)) * length:
        return span  # nearly along it: no corner to meet
    w = a - span.p0
    t = (w[0] * e[1] - w[1] * e[0]) / denom  # along the end's line
    u = (w[0] * d[1] - w[1] * d[0]) / denom  # along the wall met, in lengths of it
    if t <= 0 or not -reach / length <= u <= 1 + reach / length:
        return span
    return dataclasses.replace(span, p1=span.p0 + t * d)


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
    for span in openings(ends, config, config.blind_max, config.blind_angle, ends.left_open(used)):
        if span.width <= config.door_max:
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
    kernels = compiled.room_kernels()
    regions, n = label(~barrier)
    leaky = touches_border(regions, n)
    min_cells = config.min_area / grid.cell**2
    cells, seen = kernels.label_counts(regions, n, grid.free)
    # Enclosed, and mostly seen: spans closed across unexplored space (it looks like glass:
    # nothing seen through) can enclose more unknown than floor; such a region is open.
    leaky |= seen < config.closed_seen * cells
    enclosed = np.flatnonzero((seen >= min_cells) & ~leaky)
    room_of = np.full(n + 1, -1, dtype=np.int32)  # region -> room; the last entry for -1
    room_of[enclosed] = np.arange(len(enclosed))
    closed = [True] * len(enclosed)
    pieces, m = label(grid.free & np.append(leaky, False)[regions])  # open regions' seen floor
    kept = np.flatnonzero(
        kernels.label_counts(pieces, m, grid.free)[0] >= config.min_open_area / grid.cell**2
    )
    piece_room = np.full(m + 1, -1, dtype=np.int32)
    piece_room[kept] = len(closed) + np.arange(len(kept))
    labels = room_of[regions]
    open_floor = pieces >= 0
    labels[open_floor] = piece_room[pieces[open_floor]]
    return labels, closed + [False] * len(kept)


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


def _cells_of(grid: _Grid, labels: NDArray[np.int32], n: int) -> list[NDArray[np.int64]]:
    """Each room's cells (global (i, j)), from one pass over the grid."""
    cells, ends = compiled.room_kernels().cells_by_label(labels, n, grid.origin)
    return np.split(cells, ends[:-1]) if n else []


def _cells_key(cells: NDArray[np.int64]) -> tuple[int, ...]:
    """A room's cells (global, as ``_cells_of`` orders them) told apart from most others.

    At a glance: their count, first and last. Equal keys still need the cells compared;
    hashing them all would cost more than the rest of a large map's update.
    """
    return (len(cells), *cells[:1].ravel().tolist(), *cells[-1:].ravel().tolist())


Outlines = dict[tuple[bool, tuple[int, ...]], RoomShape]  # (closed, ``_cells_key``) -> shape


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
        key = (shut, _cells_key(mine))
        shape = known.get(key)
        if shape is None or not np.array_equal(shape.cells, mine):
            shape = _shape(grid, mine, shut, config)
        kept[key] = shape
        shapes.append(copy.copy(shape))
        shapes[-1].walls = []
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
    polygon = simplify(corners * grid.cell, config.simplify)
    return RoomShape(
        polygon=polygon,
        area=abs(polygon_area(polygon)),
        centroid=polygon_centroid(polygon),
        closed=closed,
        cells=cells,
    )


def _bounding_walls(
    grid: _Grid,
    labels: NDArray[np.int32],
    walls: Sequence[WallSegments],
    segments: _Segments,
    shapes: list[RoomShape],
    radius: float,
) -> None:
    """Each room's walls: those with a share of their length facing its cells.

    Each segment is sampled every 20 cm (from a tenth to nine tenths of it) and looked at from
    both sides, just past the barrier; a wall bounds a room whose cells are in front of a fifth
    of its samples (two at least).
    """
    reach = radius + 1.5 * grid.cell
    if not shapes or not len(segments.a):
        return
    a, b, owner = segments.a, segments.b, segments.owner
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
    by a jamb is often hidden from every view the robot had).

    Rays cross a door's floor sparsely, at a slant, and leave patches unseen within it: gaps
    narrower than a door (``door_min``) between crossed stretches are bridged, if an unseen
    end as long as a door still remains to be the missing wall; else only gaps up to
    ``TRIM_GAP``. (Floor along glass is crossed too, by rays through it from the next room:
    a door whose unseen patch is bridged there would take in the glass.)
    """
    steps = max(3, math.ceil(2 * span.width / grid.cell))
    t = np.linspace(0.0, 1.0, steps)
    i, j, ok = grid.local(span.p0 + t[:, None] * (span.p1 - span.p0))
    at = np.flatnonzero(ok & grid.free[i, j])
    for gap in (door_min, TRIM_GAP) if len(at) else ():
        bridge = math.ceil(gap / (span.width / (steps - 1)))
        runs = np.split(at, np.flatnonzero(np.diff(at) > bridge) + 1)
        run = max(runs, key=lambda r: r[-1] - r[0])
        before, after = t[run[0]], 1.0 - t[run[-1]]  # unseen at each end, shares of the span
        if max(before, after) * span.width >= door_min:
            lo, hi = (t[run[0]], 1.0) if before > after else (0.0, t[run[-1]])
            return span.p0 + lo * (span.p1 - span.p0), span.p0 + hi * (span.p1 - span.p0)
    return span.p0, span.p1


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
