"""Random non-Manhattan floor plans: a strip of rooms joined by doorways, or a corridor.

The plans are ground truth for the wall mapper, so they are built to be hard in the ways
the paper's method must cope with: walls at arbitrary angles, kinked side walls, glass
that returns no depth, furniture below the detector's height band, and on request narrow
doors into side rooms or thin pillars. Every plan carries a ``route`` (waypoints through
the doorways or down the corridor) so that a trajectory can drive through it without
touching anything.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any, Literal

import numpy as np

from wallmap.common import se2

Point = tuple[float, float]

# A generated plan is valid only with these margins (metres); the trajectory promise of
# 0.6 m clearance rests on them.
_ROUTE_WALL_CLEARANCE = 0.7
_ROUTE_FURNITURE_CLEARANCE = 0.85
_MIN_WALL_GAP = 0.3
_MIN_KINK_DEG = 10.0
_MAX_ATTEMPTS = 200
DOORWAY = (1.5, 1.7)  # m: narrowest and widest doorway in a strip's dividers
_PILLAR_SIZE = 0.3
_DOOR_WIDTH = (0.9, 1.2)  # corridor doors: ordinary ones, narrower than the strip's doorways
_MIN_PIECE = 1.0  # shortest corridor wall piece, as the shortest wall of a strip plan

Layout = Literal["rooms", "corridor"]


@dataclass(frozen=True)
class Wall:
    """A vertical wall of zero thickness, seen from both sides, from the floor up to ``height``.

    ``windows`` are glass panes in it, ``(start, end, bottom, top)``: metres along the wall
    from ``p0``, and heights above the floor. The wall is one wall, window or not.
    """

    id: int
    p0: Point
    p1: Point
    glass: bool = False
    height: float = 2.6
    windows: tuple[tuple[float, float, float, float], ...] = ()

    @property
    def length(self) -> float:
        """Length of the wall segment in metres."""
        return math.dist(self.p0, self.p1)


@dataclass(frozen=True)
class Furniture:
    """A box standing on the floor (or on another box: an appliance on a counter).

    Attributes:
        center: Footprint centre (x, y) in the map frame.
        size: Footprint (w, d): w along the box's yaw direction, d across it.
        yaw: Orientation of the footprint in radians.
        height: Top of the box above the floor.
        base: Bottom of the box above the floor (0: it stands on the floor).
    """

    center: Point
    size: tuple[float, float]
    yaw: float
    height: float
    base: float = 0.0

    def corners(self) -> np.ndarray:
        """Footprint corners, (4, 2), counter-clockwise."""
        hw, hd = self.size[0] / 2, self.size[1] / 2
        local = np.array([[-hw, -hd], [hw, -hd], [hw, hd], [-hw, hd]])
        return se2.transform_points(local, (*self.center, self.yaw))


@dataclass(frozen=True)
class Room:
    """A room's floor outline, counter-clockwise: the truth rooms are scored against."""

    id: int
    polygon: tuple[Point, ...]


@dataclass(frozen=True)
class Door:
    """A doorway: its span from jamb to jamb, and the rooms (ids) it joins."""

    id: int
    p0: Point
    p1: Point
    rooms: tuple[int, ...]


@dataclass(frozen=True)
class FloorPlan:
    """Walls and furniture of one building level, plus a collision-free route through it.

    ``rooms`` and ``doors`` are the plan's truth where its generator knows them (a strip of
    rooms); empty otherwise.
    """

    walls: tuple[Wall, ...]
    furniture: tuple[Furniture, ...] = ()
    ceiling_height: float = 2.6
    route: tuple[Point, ...] = ()
    rooms: tuple[Room, ...] = ()
    doors: tuple[Door, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form for ground-truth files."""
        return {
            "ceiling_height": self.ceiling_height,
            "walls": [
                {
                    "id": w.id,
                    "p0": list(w.p0),
                    "p1": list(w.p1),
                    "glass": w.glass,
                    "height": w.height,
                    **({"windows": [list(p) for p in w.windows]} if w.windows else {}),
                }
                for w in self.walls
            ],
            "furniture": [
                {
                    "center": list(f.center),
                    "size": list(f.size),
                    "yaw": f.yaw,
                    "height": f.height,
                    **({"base": f.base} if f.base else {}),
                }
                for f in self.furniture
            ],
            "route": [list(p) for p in self.route],
            "rooms": [{"id": r.id, "polygon": [list(p) for p in r.polygon]} for r in self.rooms],
            "doors": [
                {"id": d.id, "p0": list(d.p0), "p1": list(d.p1), "rooms": list(d.rooms)}
                for d in self.doors
            ],
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> FloorPlan:
        """Inverse of :meth:`to_json`."""
        return cls(
            walls=tuple(
                Wall(
                    id=int(w["id"]),
                    p0=_point(w["p0"]),
                    p1=_point(w["p1"]),
                    glass=bool(w["glass"]),
                    height=float(w["height"]),
                    windows=tuple(
                        (float(a), float(b), float(c), float(d))
                        for a, b, c, d in w.get("windows", ())
                    ),
                )
                for w in data["walls"]
            ),
            furniture=tuple(
                Furniture(
                    center=_point(f["center"]),
                    size=_point(f["size"]),
                    yaw=float(f["yaw"]),
                    height=float(f["height"]),
                    base=float(f.get("base", 0.0)),
                )
                for f in data["furniture"]
            ),
            ceiling_height=float(data["ceiling_height"]),
            route=tuple(_point(p) for p in data.get("route", ())),
            rooms=tuple(
                Room(int(r["id"]), tuple(_point(p) for p in r["polygon"]))
                for r in data.get("rooms", ())
            ),
            doors=tuple(
                Door(int(d["id"]), _point(d["p0"]), _point(d["p1"]), tuple(map(int, d["rooms"])))
                for d in data.get("doors", ())
            ),
        )


def _point(values: Sequence[float] | np.ndarray) -> Point:
    return (float(values[0]), float(values[1]))


def point_segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (K, M) from K points to M segments a→b."""
    ab = b - a
    rel = points[:, None, :] - a[None, :, :]
    length2 = np.maximum(np.einsum("mi,mi->m", ab, ab), 1e-18)
    t = np.clip(np.einsum("kmi,mi->km", rel, ab) / length2, 0.0, 1.0)
    return np.linalg.norm(rel - t[..., None] * ab[None], axis=2)


def _cross2(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def segment_distances(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """Shortest distances (N, M) between N segments a0→a1 and M segments b0→b1 (0 if crossing)."""
    d = np.minimum.reduce(
        [
            point_segment_distance(a0, b0, b1),
            point_segment_distance(a1, b0, b1),
            point_segment_distance(b0, a0, a1).T,
            point_segment_distance(b1, a0, a1).T,
        ]
    )
    ea, eb = (a1 - a0)[:, None], (b1 - b0)[None]
    rel0, rel1 = b0[None] - a0[:, None], b1[None] - a0[:, None]
    crosses = (_cross2(ea, rel0) * _cross2(ea, rel1) < 0) & (
        _cross2(eb, -rel0) * _cross2(eb, a1[:, None] - b0[None]) < 0
    )
    d[crosses] = 0.0
    return d


def _inside_box(points: np.ndarray, box: Furniture) -> np.ndarray:
    lx, ly = se2.unrotate((points - np.asarray(box.center)).T, box.yaw)  # in the box's frame
    return (np.abs(lx) <= box.size[0] / 2) & (np.abs(ly) <= box.size[1] / 2)


def _box_edges(box: Furniture) -> tuple[np.ndarray, np.ndarray]:
    corners = box.corners()
    return corners, np.roll(corners, -1, axis=0)


def clearance(plan: FloorPlan, points: np.ndarray) -> np.ndarray:
    """Distance from each (x, y) point to the nearest wall or furniture footprint.

    Points inside a furniture footprint have clearance 0.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    starts = [np.array([w.p0 for w in plan.walls]).reshape(-1, 2)]
    ends = [np.array([w.p1 for w in plan.walls]).reshape(-1, 2)]
    for box in plan.furniture:
        a, b = _box_edges(box)
        starts.append(a)
        ends.append(b)
    a_all, b_all = np.concatenate(starts), np.concatenate(ends)
    if len(a_all) == 0:
        return np.full(len(points), np.inf)
    result = point_segment_distance(points, a_all, b_all).min(axis=1)
    for box in plan.furniture:
        result[_inside_box(points, box)] = 0.0
    return result


def free_rays(plan: FloorPlan, at: np.ndarray, n: int = 90, reach: float = 6.0) -> np.ndarray:
    """Where ``n`` rays from ``at``, all round, end on walls that return depth (not glass).

    Relative to ``at``; a ray meeting nothing within ``reach`` (m), or glass first, is left
    out, as a depth sensor reports no return through glass. The free floor a robot at ``at``
    sees, for tests of the room finder.
    """
    a = np.array([w.p0 for w in plan.walls])
    e = np.array([w.p1 for w in plan.walls]) - a
    glass = np.array([w.glass for w in plan.walls])
    ends = []
    for angle in np.linspace(-np.pi, np.pi, n, endpoint=False):
        d = np.array([np.cos(angle), np.sin(angle)])
        denom = d[0] * e[:, 1] - d[1] * e[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((a[:, 0] - at[0]) * e[:, 1] - (a[:, 1] - at[1]) * e[:, 0]) / denom
            u = ((a[:, 0] - at[0]) * d[1] - (a[:, 1] - at[1]) * d[0]) / denom
        hit = (s > 0) & (u >= 0) & (u <= 1) & (s <= reach)
        if hit.any():
            first = np.flatnonzero(hit)[np.argmin(s[hit])]
            if not glass[first]:
                ends.append(s[first] * d)
    return np.array(ends).reshape(-1, 2)


def smooth_route(route: Sequence[Point], iterations: int = 7) -> np.ndarray:
    """Dense smooth curve (K, 2) through a waypoint polyline, by Chaikin corner cutting.

    The limit is the quadratic B-spline of the waypoints: its tangent is continuous, it
    stays inside the corners of the polyline and it is straight wherever three consecutive
    waypoints are collinear, which is how routes cross doorways.
    """
    pts = np.asarray(route, dtype=float).reshape(-1, 2)
    if len(pts) < 2:
        raise ValueError("a route needs at least two waypoints")
    for _ in range(iterations):
        q = 0.75 * pts[:-1] + 0.25 * pts[1:]
        r = 0.25 * pts[:-1] + 0.75 * pts[1:]
        inner = np.empty((2 * len(q), 2))
        inner[0::2], inner[1::2] = q, r
        pts = np.vstack([pts[0], inner, pts[-1]])
    return pts


def _direction_deg(p: np.ndarray, q: np.ndarray) -> float:
    return math.degrees(math.atan2(q[1] - p[1], q[0] - p[0]))


def _kink_deg(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> float:
    diff = abs(_direction_deg(q, r) - _direction_deg(p, q)) % 360.0
    return min(diff, 360.0 - diff)


def _side_polyline(
    rng: np.random.Generator, anchors: list[np.ndarray], jitter_y: float
) -> list[list[np.ndarray]] | None:
    """Vertices of one side wall, room by room, with random kinks between the anchors."""
    rooms: list[list[np.ndarray]] = []
    previous: np.ndarray | None = None  # vertex before the current anchor
    for start, end in pairwise(anchors):
        span = float(end[0] - start[0])
        k = max(1, round(span / 3.0))
        base_y = (start[1] + end[1]) / 2
        for _ in range(50):
            inner = [
                np.array(
                    [
                        start[0] + span * j / k + rng.uniform(-0.3, 0.3),
                        base_y + rng.uniform(-jitter_y, jitter_y),
                    ]
                )
                for j in range(1, k)
            ]
            verts = [start, *inner, end]
            chain = verts if previous is None else [previous, *verts]
            kinks_ok = all(
                _kink_deg(chain[i], chain[i + 1], chain[i + 2]) >= _MIN_KINK_DEG
                for i in range(len(chain) - 2)
            )
            lengths_ok = all(1.0 <= float(np.linalg.norm(q - p)) <= 8.0 for p, q in pairwise(verts))
            if kinks_ok and lengths_ok:
                break
        else:
            return None
        rooms.append(verts)
        previous = verts[-2]
    return rooms


def _walls_well_formed(
    segments: Sequence[tuple[np.ndarray, np.ndarray]], *, tees: bool = False
) -> bool:
    """Every wall is 1-8 m long, and walls come close only where they are joined.

    Walls meeting at a corner share an exact vertex; with ``tees``, a wall may also end on
    another one (a T). Any other pair must stay ``_MIN_WALL_GAP`` apart, so that no two
    walls blur into one in a depth image.
    """
    if not all(1.0 <= float(np.linalg.norm(q - p)) <= 8.0 for p, q in segments):
        return False
    starts = np.array([p for p, _ in segments])
    ends = np.array([q for _, q in segments])
    gaps = segment_distances(starts, ends, starts, ends)
    joined = np.zeros_like(gaps, dtype=bool)
    for u in (starts, ends):
        for v in (starts, ends):
            joined |= np.all(u[:, None] == v[None], axis=2)
        if tees:
            on = point_segment_distance(u, starts, ends) < 1e-9
            joined |= on | on.T
    return not (gaps[~joined] < _MIN_WALL_GAP).any()


def _walled_plan(
    segments: Sequence[Any], route: Sequence[Any], rng: np.random.Generator
) -> tuple[FloorPlan, np.ndarray] | None:
    """Walls of one ceiling height along ``segments`` and the smoothed ``route``.

    None when the route passes too close to a wall. Draws the ceiling height from ``rng`` first:
    the plan generators rely on that draw order for reproducible plans.
    """
    ceiling = float(rng.uniform(2.5, 3.0))
    walls = tuple(
        Wall(id=i, p0=_point(p), p1=_point(q), height=ceiling) for i, (p, q) in enumerate(segments)
    )
    plan = FloorPlan(walls=walls, ceiling_height=ceiling, route=tuple(_point(p) for p in route))
    curve = smooth_route(plan.route)
    if clearance(plan, curve).min() < _ROUTE_WALL_CLEARANCE:
        return None
    return plan, curve


# A wall a box may stand against, and which way its room lies from it: (p, q, inward).
_BoxWall = tuple[np.ndarray, np.ndarray, np.ndarray]


def _furnish(
    rng: np.random.Generator,
    walls: tuple[Wall, ...],
    curve: np.ndarray,
    rooms: Sequence[list[_BoxWall]],
    per_room: int,
) -> list[Furniture]:
    """Up to ``per_room`` boxes against the walls of each room, clear of the route ``curve``.

    A box that does not fit is drawn again, 30 times at the most; then the room has one less.
    """
    furniture: list[Furniture] = []
    for candidates in rooms:
        for _ in range(per_room):
            for _ in range(30):
                p, q, inward = candidates[rng.integers(len(candidates))]
                box = _furniture_along(rng, p, q, inward)
                if _box_fits(FloorPlan(walls=walls, furniture=(*furniture, box)), box, curve):
                    furniture.append(box)
                    break
    return furniture


@dataclass(frozen=True, eq=False)
class _Dividers:
    """The cross walls of a strip of rooms, in strip coordinates, with the side walls' anchors.

    The two end caps (first and last) and, between them, the dividers, each with a doorway.

    Attributes:
        xs: Where each crosses the strip's axis (y = 0).
        centers: The centre of each one's doorway (of a cap: where a doorway would be).
        along: Each one's direction, from its right end to its left.
        left: Each one's end on the left side wall: the side wall's anchors.
        right: Each one's end on the right side wall.
        door_w: Each one's doorway width.
    """

    xs: np.ndarray
    centers: list[np.ndarray]
    along: list[np.ndarray]
    left: list[np.ndarray]
    right: list[np.ndarray]
    door_w: np.ndarray

    def doorway(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        """The jambs of divider ``b``'s doorway: its right one, then its left one."""
        half = self.door_w[b] / 2
        return self.centers[b] - half * self.along[b], self.centers[b] + half * self.along[b]


def _draw_dividers(
    rng: np.random.Generator, n_rooms: int, doorway: tuple[float, float]
) -> _Dividers:
    """Rooms 6.5-8.5 m long, their side walls anchored 2.2-2.8 m either side of the axis."""
    lengths = rng.uniform(6.5, 8.5, n_rooms)
    xs = np.concatenate([[0.0], np.cumsum(lengths)])
    left_y = rng.uniform(2.2, 2.8, n_rooms + 1)
    right_y = -rng.uniform(2.2, 2.8, n_rooms + 1)
    # End caps lean a little, dividers a lot: +-35 degrees from perpendicular to the strip.
    tilt_limits = np.full(n_rooms + 1, 35.0)
    tilt_limits[[0, -1]] = 15.0
    tilts = np.radians(rng.uniform(-1.0, 1.0, n_rooms + 1) * tilt_limits)
    door_c = rng.uniform(-0.3, 0.3, n_rooms + 1)
    door_c[[0, -1]] = 0.0
    door_w = rng.uniform(*doorway, n_rooms + 1)

    centers, along, left, right = [], [], [], []
    for b in range(n_rooms + 1):
        u = np.array([math.sin(tilts[b]), math.cos(tilts[b])])
        center = np.array([xs[b], door_c[b]])
        centers.append(center)
        along.append(u)
        left.append(center + (left_y[b] - door_c[b]) / math.cos(tilts[b]) * u)
        right.append(center - (door_c[b] - right_y[b]) / math.cos(tilts[b]) * u)
    return _Dividers(xs=xs, centers=centers, along=along, left=left, right=right, door_w=door_w)


def _strip_segments(
    dividers: _Dividers, left: list[list[np.ndarray]], right: list[list[np.ndarray]]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The strip's walls: the end caps, the dividers either side of their doorways, the sides."""
    segments = [(dividers.right[0], dividers.left[0]), (dividers.right[-1], dividers.left[-1])]
    for b in range(1, len(dividers.xs) - 1):
        right_jamb, left_jamb = dividers.doorway(b)
        segments.append((dividers.right[b], right_jamb))
        segments.append((left_jamb, dividers.left[b]))
    segments += [(p, q) for side in (left, right) for verts in side for p, q in pairwise(verts)]
    return segments


def _side_walls_by_room(
    left: list[list[np.ndarray]], right: list[list[np.ndarray]]
) -> list[list[_BoxWall]]:
    """Per room, the pieces of side wall a box may stand against: the left ones, then the right."""
    rooms: list[list[_BoxWall]] = [[] for _ in left]
    for inward, side in ((-1.0, left), (1.0, right)):
        for room, verts in enumerate(side):
            rooms[room] += [(p, q, np.array([0.0, inward])) for p, q in pairwise(verts)]
    return rooms


def _strip_route(rng: np.random.Generator, dividers: _Dividers) -> list[np.ndarray]:
    """Waypoints: the start, through every doorway perpendicular to its divider, the end."""
    xs, centers, along = dividers.xs, dividers.centers, dividers.along
    route = [np.array([xs[0] + 1.5, 0.0])]
    for b in range(1, len(xs) - 1):
        normal = np.array([along[b][1], -along[b][0]])
        before, after = centers[b] - normal, centers[b] + normal
        route.append((route[-1] + before) / 2 + np.array([0.0, rng.uniform(-0.4, 0.4)]))
        route.extend([before, centers[b], after])
    end = np.array([xs[-1] - 1.5, 0.0])
    route.append((route[-1] + end) / 2 + np.array([0.0, rng.uniform(-0.4, 0.4)]))
    route.append(end)
    return route


def _strip_rooms(left: list[list[np.ndarray]], right: list[list[np.ndarray]]) -> tuple[Room, ...]:
    """Each room's outline, as truth: its right side wall, then its left one backwards."""
    return tuple(
        Room(r, tuple(_point(p) for p in [*right[r], *left[r][::-1]])) for r in range(len(left))
    )


def _strip_doors(dividers: _Dividers) -> tuple[Door, ...]:
    """The dividers' doorways, as truth: doorway ``b`` joins rooms ``b - 1`` and ``b``."""
    doors = []
    for b in range(1, len(dividers.xs) - 1):
        right_jamb, left_jamb = dividers.doorway(b)
        doors.append(Door(b - 1, _point(right_jamb), _point(left_jamb), (b - 1, b)))
    return tuple(doors)


def _try_plan(
    rng: np.random.Generator,
    n_rooms: int,
    glass_fraction: float,
    furniture_per_room: int,
    pillars_per_room: int,
    doorway: tuple[float, float] = DOORWAY,
) -> FloorPlan | None:
    """One attempt at a plan in strip coordinates (x along the strip); None if invalid.

    Every random number is drawn in the order it always was: a seed gives the plan it gave.
    """
    dividers = _draw_dividers(rng, n_rooms, doorway)
    left = _side_polyline(rng, dividers.left, 0.8)
    right = _side_polyline(rng, dividers.right, 0.8)
    if left is None or right is None:
        return None
    segments = _strip_segments(dividers, left, right)
    if not _walls_well_formed(segments):
        return None
    route = _strip_route(rng, dividers)
    walled = _walled_plan(segments, route, rng)
    if walled is None:
        return None
    strip, curve = walled
    rooms = _side_walls_by_room(left, right)
    furniture = _furnish(rng, strip.walls, curve, rooms, furniture_per_room)
    walls = _with_glass(rng, strip.walls, glass_fraction)
    # Drawn last, so that plans without pillars come out as they always did.
    for room in range(n_rooms):
        x_range = (dividers.xs[room], dividers.xs[room + 1])
        for _ in range(pillars_per_room):
            walls += _place_pillar(rng, walls, furniture, curve, x_range)
    return FloorPlan(
        walls=walls,
        furniture=tuple(furniture),
        ceiling_height=strip.ceiling_height,
        route=strip.route,
        rooms=_strip_rooms(left, right),
        doors=_strip_doors(dividers),
    )


def _with_glass(
    rng: np.random.Generator, walls: tuple[Wall, ...], glass_fraction: float
) -> tuple[Wall, ...]:
    """The walls with a random ``glass_fraction`` of them turned to glass."""
    n_glass = round(glass_fraction * len(walls))
    glass_ids = set(rng.choice(len(walls), size=n_glass, replace=False).tolist())
    return tuple(
        Wall(id=w.id, p0=w.p0, p1=w.p1, glass=w.id in glass_ids, height=w.height) for w in walls
    )


def _place_pillar(
    rng: np.random.Generator,
    walls: tuple[Wall, ...],
    furniture: Sequence[Furniture],
    curve: np.ndarray,
    x_range: tuple[float, float],
) -> tuple[Wall, ...]:
    """Four walls of a free-standing pillar in the room spanning ``x_range``, or () if none fit.

    The pillar stands 1.2-2.2 m beside the route, as far from walls as walls are from
    each other and as far from the route as furniture is, so a robot can pass it.
    """
    in_room = np.flatnonzero((curve[:, 0] > x_range[0] + 1.0) & (curve[:, 0] < x_range[1] - 1.0))
    height = walls[0].height
    for _ in range(30):
        foot = curve[in_room[rng.integers(len(in_room))]]
        center = foot + np.array([0.0, rng.choice([-1.0, 1.0]) * rng.uniform(1.2, 2.2)])
        box = Furniture(
            _point(center), (_PILLAR_SIZE, _PILLAR_SIZE), float(rng.uniform(0, math.pi)), height
        )
        corners, ends = _box_edges(box)
        wall_a = np.array([w.p0 for w in walls])
        wall_b = np.array([w.p1 for w in walls])
        if segment_distances(corners, ends, wall_a, wall_b).min() < _MIN_WALL_GAP:
            continue
        # Seen from the route, not hidden behind a wall (or outside the building).
        if segment_distances(foot[None], center[None], wall_a, wall_b).min() <= 0.0:
            continue
        # Clear of the furniture, and of the route by as much as furniture is.
        if not _box_fits(FloorPlan(walls=walls, furniture=(*furniture, box)), box, curve):
            continue
        first = len(walls)
        return tuple(
            Wall(id=first + k, p0=_point(a), p1=_point(b), height=height)
            for k, (a, b) in enumerate(zip(corners, ends, strict=True))
        )
    return ()


def _line_intersection(p: np.ndarray, d: np.ndarray, q: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Where the lines p + t d and q + s e cross; they must not be parallel."""
    return p + float(_cross2(q - p, e) / _cross2(d, e)) * d


def _corridor_walls(
    sides: list[list[np.ndarray]], doors: dict[tuple[int, int], list[tuple[float, float]]]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """End caps, and the side walls cut at the doors."""
    segments = [(sides[1][0], sides[0][0]), (sides[0][-1], sides[1][-1])]
    for side, verts in enumerate(sides):
        for run, (start, end) in enumerate(pairwise(verts)):
            length = float(np.linalg.norm(end - start))
            unit = (end - start) / length
            gaps = doors[side, run]
            # Every vertex is made once, so that walls meeting there share it exactly.
            points = {0.0: start, length: end}
            points.update({t: start + t * unit for gap in gaps for t in gap})
            cuts = sorted(points)
            segments.extend(
                (points[t0], points[t1]) for t0, t1 in pairwise(cuts) if (t0, t1) not in gaps
            )
    return segments


@dataclass(frozen=True, eq=False)
class _Corridor:
    """A corridor's straight legs, in its first leg's frame (x along it).

    Attributes:
        centre: The centre line's vertices (n_legs + 1, 2): where the legs start and end.
        dirs: Each leg's direction (n_legs, 2).
        normals: Each leg's left (n_legs, 2).
        sides: The side walls' vertices, left (0) then right (1): the centre line offset by half
            the width, mitred at the kinks, ended on the leaning caps.
    """

    centre: np.ndarray
    dirs: np.ndarray
    normals: np.ndarray
    sides: list[list[np.ndarray]]


def _draw_corridor(rng: np.random.Generator, n_legs: int) -> _Corridor:
    """Legs 6.2-7.2 m long, turning 10-25 degrees at each kink, 1.8-2.5 m wide."""
    lengths = rng.uniform(6.2, 7.2, n_legs)
    turns = rng.choice([-1.0, 1.0], n_legs - 1) * np.radians(rng.uniform(10.0, 25.0, n_legs - 1))
    headings = np.concatenate([[0.0], np.cumsum(turns)])
    dirs = np.column_stack([np.cos(headings), np.sin(headings)])
    normals = np.column_stack([-dirs[:, 1], dirs[:, 0]])
    centre = np.vstack([[0.0, 0.0], np.cumsum(lengths[:, None] * dirs, axis=0)])
    half_width = rng.uniform(0.9, 1.25)
    caps = np.radians(rng.uniform(-15.0, 15.0, 2))
    cap_dirs = (se2.rotate(normals[0], caps[0]), se2.rotate(normals[-1], caps[1]))

    sides: list[list[np.ndarray]] = []
    for sign in (1.0, -1.0):
        offset = sign * half_width * normals
        verts = [_line_intersection(centre[0] + offset[0], dirs[0], centre[0], cap_dirs[0])]
        verts += [
            _line_intersection(
                centre[i] + offset[i - 1], dirs[i - 1], centre[i] + offset[i], dirs[i]
            )
            for i in range(1, n_legs)
        ]
        verts.append(_line_intersection(centre[-1] + offset[-1], dirs[-1], centre[-1], cap_dirs[1]))
        sides.append(verts)
    return _Corridor(centre=centre, dirs=dirs, normals=normals, sides=sides)


def _run_doors(
    rng: np.random.Generator, length: float
) -> tuple[list[tuple[float, float]], np.ndarray] | None:
    """Up to two doors in a run of side wall ``length`` long, with wall pieces between them.

    Returns:
        The doors' spans (metres along the run) and the pieces' lengths, each at least
        ``_MIN_PIECE``; None if the doors drawn do not fit.
    """
    k = int(rng.choice(3, p=[0.25, 0.5, 0.25]))
    widths = rng.uniform(*_DOOR_WIDTH, k)
    spare = length - widths.sum() - (k + 1) * _MIN_PIECE
    if spare < 0:
        return None
    pieces = _MIN_PIECE + spare * rng.dirichlet(np.ones(k + 1))
    s0 = np.cumsum(pieces[:-1]) + np.concatenate([[0.0], np.cumsum(widths[:-1])])
    return [(float(a), float(a + w)) for a, w in zip(s0, widths, strict=True)], pieces


def _room_behind(
    rng: np.random.Generator,
    *,
    start: np.ndarray,
    unit: np.ndarray,
    span: tuple[float, float],
    pieces: tuple[float, float],
    outward: np.ndarray,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The three walls of a small room behind the door ``span`` of the run from ``start``.

    They end in Ts on the side wall 0.5-1.5 m beyond the jambs, which keeps the side wall one
    wall, as it looks from the corridor; the Ts stay at least ``_MIN_WALL_GAP`` from the ends
    of the ``pieces`` of side wall either side of the door.
    """
    a = start + (span[0] - rng.uniform(0.5, min(1.5, pieces[0] - _MIN_WALL_GAP))) * unit
    b = start + (span[1] + rng.uniform(0.5, min(1.5, pieces[1] - _MIN_WALL_GAP))) * unit
    depth_a, depth_b = rng.uniform(2.0, 3.0, 2)
    lean_a, lean_b = np.radians(rng.uniform(-20.0, 20.0, 2))
    far_a = a + depth_a * se2.rotate(outward, lean_a)
    far_b = b + depth_b * se2.rotate(outward, lean_b)
    return [(a, far_a), (far_a, far_b), (far_b, b)]


@dataclass(frozen=True, eq=False)
class _SideDoors:
    """The doors of a corridor's side walls and the rooms that may open behind them.

    Attributes:
        spans: Per (side, run), its doors' spans in metres along the run.
        rooms: The walls of each room drawn behind a door (about two doors in three).
        behind: The door each room opens through: (side, run, door).
    """

    spans: dict[tuple[int, int], list[tuple[float, float]]]
    rooms: list[list[tuple[np.ndarray, np.ndarray]]]
    behind: list[tuple[int, int, int]]

    def on_both_sides(self, n_legs: int) -> bool:
        """At least three doors, and some on each side."""
        total = sum(map(len, self.spans.values()))
        return total >= 3 and all(
            any(self.spans[side, run] for run in range(n_legs)) for side in (0, 1)
        )


def _draw_side_doors(rng: np.random.Generator, corridor: _Corridor) -> _SideDoors | None:
    """Doors in every run of side wall, most with a room behind; None if some did not fit."""
    doors = _SideDoors(spans={}, rooms=[], behind=[])
    for side, verts in enumerate(corridor.sides):
        outward = corridor.normals * (1.0 if side == 0 else -1.0)
        for run, (start, end) in enumerate(pairwise(verts)):
            length = float(np.linalg.norm(end - start))
            drawn = _run_doors(rng, length)
            if drawn is None:
                return None
            doors.spans[side, run], pieces = drawn
            for j, span in enumerate(doors.spans[side, run]):
                if rng.random() < 0.3:
                    continue
                room = _room_behind(
                    rng,
                    start=start,
                    unit=(end - start) / length,
                    span=span,
                    pieces=(pieces[j], pieces[j + 1]),
                    outward=outward[run],
                )
                doors.rooms.append(room)
                doors.behind.append((side, run, j))
    return doors


def _open_rooms(
    segments: list[tuple[np.ndarray, np.ndarray]], doors: _SideDoors
) -> tuple[
    list[tuple[np.ndarray, np.ndarray]],
    list[list[tuple[np.ndarray, np.ndarray]]],
    dict[tuple[int, int, int], int],
]:
    """The rooms that fit among the walls, each in turn; one too near a wall stays a plain gap.

    Returns:
        The walls with those rooms', the rooms, and per door the truth id of the room behind it.
    """
    rooms: list[list[tuple[np.ndarray, np.ndarray]]] = []
    opened: dict[tuple[int, int, int], int] = {}
    for room, door in zip(doors.rooms, doors.behind, strict=True):
        if _walls_well_formed([*segments, *room], tees=True):
            segments = [*segments, *room]
            rooms.append(room)
            opened[door] = len(rooms)
    return segments, rooms, opened


def _corridor_route(corridor: _Corridor) -> list[np.ndarray]:
    """Waypoints down the corridor's middle, straight through each kink."""
    centre, dirs = corridor.centre, corridor.dirs
    route = [centre[0] + 1.5 * dirs[0]]
    for i in range(1, len(dirs)):
        route += [centre[i] - 0.8 * dirs[i - 1], centre[i], centre[i] + 0.8 * dirs[i]]
    route.append(centre[-1] - 1.5 * dirs[-1])
    return route


def _room_walls(room: list[tuple[np.ndarray, np.ndarray]]) -> list[_BoxWall]:
    """A side room's three walls, each with the way to the room's middle."""
    middle = np.mean([p for p, _ in room] + [room[-1][1]], axis=0)
    return [(p, q, middle - (p + q) / 2) for p, q in room]


def _try_corridor(
    rng: np.random.Generator, n_legs: int, glass_fraction: float, furniture_per_room: int
) -> FloorPlan | None:
    """One attempt at a corridor plan (x along its first leg); None if invalid.

    Every random number is drawn in the order it always was: a seed gives the plan it gave.
    """
    corridor = _draw_corridor(rng, n_legs)
    doors = _draw_side_doors(rng, corridor)
    if doors is None or not doors.on_both_sides(n_legs):
        return None
    segments = _corridor_walls(corridor.sides, doors.spans)
    if not _walls_well_formed(segments):
        return None
    segments, rooms, opened = _open_rooms(segments, doors)
    if not rooms:
        return None
    walled = _walled_plan(segments, _corridor_route(corridor), rng)
    if walled is None:
        return None
    plan, curve = walled
    box_walls = [_room_walls(room) for room in rooms]
    furniture = _furnish(rng, plan.walls, curve, box_walls, furniture_per_room)
    return FloorPlan(
        walls=_with_glass(rng, plan.walls, glass_fraction),
        furniture=tuple(furniture),
        ceiling_height=plan.ceiling_height,
        route=plan.route,
        rooms=_corridor_rooms(corridor.sides, rooms),
        doors=_corridor_doors(corridor.sides, doors.spans, opened),
    )


def _counter_clockwise(points: Sequence[np.ndarray]) -> tuple[Point, ...]:
    """The polygon's vertices, reversed if they ran clockwise."""
    xy = np.array(points, dtype=float)
    area = np.dot(xy[:, 0], np.roll(xy[:, 1], -1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], -1))
    return tuple(_point(p) for p in (xy if area > 0 else xy[::-1]))


def _corridor_rooms(
    sides: list[list[np.ndarray]], rooms: list[list[tuple[np.ndarray, np.ndarray]]]
) -> tuple[Room, ...]:
    """The corridor (room 0) and the rooms behind its doors (1, 2, ...), as truth."""
    corridor = Room(0, _counter_clockwise([*sides[0], *sides[1][::-1]]))
    behind = (
        Room(k + 1, _counter_clockwise([room[0][0], room[1][0], room[2][0], room[2][1]]))
        for k, room in enumerate(rooms)
    )
    return (corridor, *behind)


def _corridor_doors(
    sides: list[list[np.ndarray]],
    doors: dict[tuple[int, int], list[tuple[float, float]]],
    opened: dict[tuple[int, int, int], int],
) -> tuple[Door, ...]:
    """Every door in the corridor's side walls: into a room behind it, or into nothing."""
    out = []
    for (side, run), spans in sorted(doors.items()):
        start, end = sides[side][run], sides[side][run + 1]
        unit = (end - start) / np.linalg.norm(end - start)
        for j, (d0, d1) in enumerate(spans):
            room = opened.get((side, run, j))
            joined = (0,) if room is None else (0, room)
            out.append(Door(len(out), _point(start + d0 * unit), _point(start + d1 * unit), joined))
    return tuple(out)


def _furniture_along(
    rng: np.random.Generator, p: np.ndarray, q: np.ndarray, inward: np.ndarray
) -> Furniture:
    """A box standing against the wall p→q, on the side ``inward`` points to."""
    direction = (q - p) / np.linalg.norm(q - p)
    normal = np.array([-direction[1], direction[0]])
    if normal @ inward < 0:
        normal = -normal
    w, d = rng.uniform(0.6, 1.6), rng.uniform(0.4, 0.7)
    foot = p + rng.uniform(0.15, 0.85) * (q - p)
    center = foot + normal * (d / 2 + 0.05)
    return Furniture(
        center=_point(center),
        size=(float(w), float(d)),
        yaw=math.atan2(direction[1], direction[0]),
        height=float(rng.uniform(0.4, 1.1)),
    )


def _box_fits(plan: FloorPlan, box: Furniture, curve: np.ndarray) -> bool:
    """The box touches no wall, no other box, and keeps clear of the route."""
    corners, ends = _box_edges(box)
    wall_a = np.array([w.p0 for w in plan.walls])
    wall_b = np.array([w.p1 for w in plan.walls])
    if segment_distances(corners, ends, wall_a, wall_b).min() < 0.03:
        return False
    if _inside_box(np.concatenate([wall_a, wall_b]), box).any():
        return False
    for other in plan.furniture:
        if other is box:
            continue
        oa, ob = _box_edges(other)
        if _inside_box(oa, box).any() or _inside_box(corners, other).any():
            return False
        if segment_distances(corners, ends, oa, ob).min() < 0.1:
            return False
    single = FloorPlan(walls=(), furniture=(box,))
    return bool(clearance(single, curve).min() >= _ROUTE_FURNITURE_CLEARANCE)


def _transform_plan(plan: FloorPlan, angle: float, origin: np.ndarray) -> FloorPlan:
    """Rigidly move the plan: translate ``origin`` to (0, 0), then rotate by ``angle``."""

    def move(p: Point) -> Point:
        x, y = se2.rotate((p[0] - origin[0], p[1] - origin[1]), angle).tolist()
        return (x, y)

    return FloorPlan(
        walls=tuple(
            Wall(id=w.id, p0=move(w.p0), p1=move(w.p1), glass=w.glass, height=w.height)
            for w in plan.walls
        ),
        furniture=tuple(
            Furniture(
                center=move(f.center),
                size=f.size,
                # Exact for a yaw already in range (se2.wrap may move it by an ulp): the truth
                # files store these yaws, and they stay as drawn.
                yaw=math.remainder(f.yaw + angle, 2 * math.pi),
                height=f.height,
                base=f.base,
            )
            for f in plan.furniture
        ),
        ceiling_height=plan.ceiling_height,
        route=tuple(move(p) for p in plan.route),
        rooms=tuple(Room(r.id, tuple(move(p) for p in r.polygon)) for r in plan.rooms),
        doors=tuple(Door(d.id, move(d.p0), move(d.p1), d.rooms) for d in plan.doors),
    )


def generate_floorplan(
    seed: int,
    *,
    n_rooms: int = 3,
    glass_fraction: float = 0.15,
    furniture_per_room: int = 2,
    layout: Layout = "rooms",
    pillars_per_room: int = 0,
    doorway: tuple[float, float] = DOORWAY,
) -> FloorPlan:
    """A random non-Manhattan plan a robot can drive through.

    Layout ``rooms`` (the default) is a strip of rooms: the two long side walls are
    polylines with random kinks; the rooms are divided by walls leaning up to 35 degrees
    from perpendicular, each with a doorway ``doorway`` wide (1.5-1.7 m: wide enough to pass
    with 0.6 m clearance to the jambs; wider, an open-plan passage). Layout ``corridor`` is a
    corridor 1.8-2.5 m wide of straight legs joined by kinks of 10-25 degrees. Its side walls
    have up to two 0.9-1.2 m doors per leg (at least three in all, and some on each side); at
    least one door opens into a small room (2-3 m deep, side walls leaning up to 20 degrees),
    the others into nothing.
    The route runs down the corridor's middle. Either way the whole plan is rotated by a
    random angle and placed so that the route starts at the map origin, and every wall is
    1-8 m long except the faces of pillars. The same arguments always give the same plan.

    Args:
        seed: Random seed.
        n_rooms: Rooms along the strip (6.5-8.5 m each), or legs of the corridor
            (6.2-7.2 m each).
        glass_fraction: Fraction of walls that are glass (no depth return).
        furniture_per_room: Boxes placed against the side walls away from the route, or
            for a corridor against the walls of each room behind a door.
        layout: ``rooms`` or ``corridor``.
        pillars_per_room: Free-standing square pillars (0.3 m, full height) per room,
            beside the route; each adds four walls. Only for the ``rooms`` layout.
        doorway: The dividers' openings, narrowest and widest (m). Only for ``rooms``.

    Returns:
        The plan, with ``route`` set to waypoints through all rooms or down the corridor.

    Raises:
        ValueError: If ``n_rooms`` is less than 1, or pillars are asked of a corridor.
        RuntimeError: If no valid plan was found (not expected for sane arguments).
    """
    if n_rooms < 1:
        raise ValueError("n_rooms must be at least 1")
    if layout == "corridor" and pillars_per_room:
        raise ValueError("a corridor has no room for pillars")
    rng = np.random.default_rng(seed)
    for _ in range(_MAX_ATTEMPTS):
        if layout == "corridor":
            strip = _try_corridor(rng, n_rooms, glass_fraction, furniture_per_room)
        else:
            strip = _try_plan(
                rng, n_rooms, glass_fraction, furniture_per_room, pillars_per_room, doorway
            )
        if strip is not None:
            angle = float(rng.uniform(-math.pi, math.pi))
            return _transform_plan(strip, angle, np.asarray(strip.route[0]))
    raise RuntimeError(f"no valid floor plan found for seed {seed}")


COUNTER_HEIGHT = 0.9  # m: a kitchen counter's top


def with_counters(plan: FloorPlan, seed: int, counters: int = 3) -> FloorPlan:
    """The plan with kitchen counters along some walls and appliances standing on them.

    A counter is a box 0.9 m high and 0.6 m deep, 5 cm off a wall, on the side the route
    passes; two to four appliances (kettles, toasters, microwaves: 0.2 to 0.45 m tall, 0.25 to
    0.5 m wide) stand on it against the wall. Clutter that rises into a handheld camera's band
    but is no wall. Counters that would block the route are not placed.
    """
    rng = np.random.default_rng(seed)
    curve = smooth_route(plan.route)
    furniture = list(plan.furniture)
    walls = [w for w in plan.walls if not w.glass and w.length >= 1.6]
    for _ in range(counters if walls else 0):
        for _ in range(30):
            wall = walls[int(rng.integers(len(walls)))]
            p, q = np.array(wall.p0), np.array(wall.p1)
            direction = (q - p) / np.linalg.norm(q - p)
            normal = np.array([-direction[1], direction[0]])
            middle = (p + q) / 2
            if (curve[np.argmin(np.linalg.norm(curve - middle, axis=1))] - middle) @ normal < 0:
                normal = -normal  # the side the route passes
            width = min(2.4, 0.8 * wall.length)
            foot = p + rng.uniform(width / 2, wall.length - width / 2) * direction
            yaw = math.atan2(direction[1], direction[0])
            counter = Furniture(_point(foot + normal * 0.35), (width, 0.6), yaw, COUNTER_HEIGHT)
            if not _box_fits(
                FloorPlan(walls=plan.walls, furniture=(*furniture, counter)), counter, curve
            ):
                continue
            furniture.append(counter)
            slots = np.linspace(-width / 2, width / 2, int(rng.integers(2, 5)) + 2)[1:-1]
            for along in slots:
                size = (float(rng.uniform(0.25, 0.5)), float(rng.uniform(0.25, 0.45)))
                centre = foot + along * direction + normal * (0.07 + size[1] / 2)
                height = COUNTER_HEIGHT + float(rng.uniform(0.2, 0.45))
                furniture.append(Furniture(_point(centre), size, yaw, height, COUNTER_HEIGHT))
            break
    return FloorPlan(
        plan.walls, tuple(furniture), plan.ceiling_height, plan.route, plan.rooms, plan.doors
    )


WINDOW = (2.0, 0.8, 2.3)  # m: width, bottom and top of a window pane (across the whole band)


def with_windows(plan: FloorPlan, seed: int, windows: int = 3) -> FloorPlan:
    """The plan with a 2 m glass window, 0.8-2.3 m above the floor, in some long walls.

    The detector sees no return through glass, so such a wall is seen as two pieces with a
    2 m gap in its band: the map has to make one wall of them.
    """
    rng = np.random.default_rng(seed)
    width, bottom, top = WINDOW
    candidates = [w for w in plan.walls if not w.glass and w.length >= width + 2.0]
    chosen = set(rng.permutation([w.id for w in candidates])[:windows].tolist())
    walls = []
    for wall in plan.walls:
        pane = ()
        if wall.id in chosen:
            start = float(rng.uniform(1.0, wall.length - width - 1.0))
            pane = ((start, start + width, bottom, top),)
        walls.append(Wall(wall.id, wall.p0, wall.p1, wall.glass, wall.height, pane))
    return FloorPlan(
        tuple(walls), plan.furniture, plan.ceiling_height, plan.route, plan.rooms, plan.doors
    )


def junction_plan(seed: int) -> FloorPlan:
    """Two rooms side by side, the wall between them meeting the outer wall in a T at the origin.

    The outer wall runs 12 m straight through the map origin; the dividing wall stands on it
    at the origin with a 1.6 m doorway (two pieces, as a wall with a doorway is in these
    plans); the route crosses from one room to the other through it, looking at the outer wall
    from both sides of the T. The whole plan is turned by a random angle about the origin.
    """
    rng = np.random.default_rng(seed)
    depth = float(rng.uniform(4.5, 5.5))
    door = float(rng.uniform(1.4, 2.2))
    height = float(rng.uniform(2.5, 3.0))
    segments = [
        ((-6.0, 0.0), (6.0, 0.0)),  # the outer wall, through the origin
        ((0.0, 0.0), (0.0, door)),  # the divider: a T at the origin...
        ((0.0, door + 1.6), (0.0, depth)),  # ...with a doorway
        ((-6.0, depth), (6.0, depth)),
        ((-6.0, 0.0), (-6.0, depth)),
        ((6.0, 0.0), (6.0, depth)),
    ]
    middle = door + 0.8
    route = [
        (-4.5, depth - 1.2),
        (-3.5, 1.2),
        (-1.2, middle),
        (1.2, middle),
        (3.5, 1.2),
        (4.5, depth - 1.2),
    ]
    angle = float(rng.uniform(-math.pi, math.pi))

    def turn(p: Sequence[float]) -> Point:
        x, y = se2.rotate(p, angle).tolist()
        return (x, y)

    walls = tuple(Wall(i, turn(p), turn(q), height=height) for i, (p, q) in enumerate(segments))
    return FloorPlan(walls, (), height, tuple(turn(p) for p in route))


def glass_wall_plan(seed: int, glass: float = 3.6) -> FloorPlan:
    """One room of 10 x 6 m whose far long wall is glass over ``glass`` m of its middle.

    The glass runs floor to ceiling (across any height band), with solid wall either side: the
    wall is one wall, the room one room, and the glass no door. The route drives the room's
    length twice, facing the glass on the way. The plan is turned by a random angle about the
    origin, which the route starts beside.
    """
    rng = np.random.default_rng(seed)
    height = float(rng.uniform(2.5, 3.0))
    start = (10.0 - glass) / 2
    corners = [(0.0, 0.0), (10.0, 0.0), (10.0, 6.0), (0.0, 6.0)]
    angle = float(rng.uniform(-math.pi, math.pi))

    def turn(p: Sequence[float]) -> Point:
        x, y = se2.rotate((p[0] - 2.0, p[1] - 3.0), angle).tolist()
        return (x, y)

    walls = []
    for k, (p, q) in enumerate(zip(corners, corners[1:] + corners[:1], strict=True)):
        panes = ((start, start + glass, 0.0, height),) if k == 2 else ()
        walls.append(Wall(k, turn(p), turn(q), height=height, windows=panes))
    route = [(2.0, 3.0), (8.0, 3.5), (8.0, 2.0), (2.0, 2.0)]
    return FloorPlan(
        walls=tuple(walls),
        ceiling_height=height,
        route=tuple(turn(p) for p in route),
        rooms=(Room(0, tuple(turn(p) for p in corners)),),
    )
