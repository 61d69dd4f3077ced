"""Random non-Manhattan floor plans: a strip of rooms joined by doorways.

The plans are ground truth for the wall mapper, so they are built to be hard in the ways
the paper's method must cope with: walls at arbitrary angles, kinked side walls, glass
that returns no depth and furniture below the detector's height band. Every plan carries
a ``route`` (waypoints through the doorways) so that a trajectory can drive through it
without touching anything.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np

Point = tuple[float, float]

# A generated plan is valid only with these margins (metres); the trajectory promise of
# 0.6 m clearance rests on them.
_ROUTE_WALL_CLEARANCE = 0.7
_ROUTE_FURNITURE_CLEARANCE = 0.85
_MIN_WALL_GAP = 0.3
_MIN_KINK_DEG = 10.0
_MAX_ATTEMPTS = 200


@dataclass(frozen=True)
class Wall:
    """A vertical wall of zero thickness, seen from both sides, from the floor up to ``height``."""

    id: int
    p0: Point
    p1: Point
    glass: bool = False
    height: float = 2.6

    @property
    def length(self) -> float:
        """Length of the wall segment in metres."""
        return math.dist(self.p0, self.p1)


@dataclass(frozen=True)
class Furniture:
    """A box standing on the floor, lower than the detector's height band.

    Attributes:
        center: Footprint centre (x, y) in the map frame.
        size: Footprint (w, d): w along the box's yaw direction, d across it.
        yaw: Orientation of the footprint in radians.
        height: Top of the box above the floor.
    """

    center: Point
    size: tuple[float, float]
    yaw: float
    height: float

    def corners(self) -> np.ndarray:
        """Footprint corners, (4, 2), counter-clockwise."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        hw, hd = self.size[0] / 2, self.size[1] / 2
        local = np.array([[-hw, -hd], [hw, -hd], [hw, hd], [-hw, hd]])
        return local @ np.array([[c, s], [-s, c]]) + np.asarray(self.center)


@dataclass(frozen=True)
class FloorPlan:
    """Walls and furniture of one building level, plus a collision-free route through it."""

    walls: tuple[Wall, ...]
    furniture: tuple[Furniture, ...] = ()
    ceiling_height: float = 2.6
    route: tuple[Point, ...] = ()

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
                }
                for w in self.walls
            ],
            "furniture": [
                {
                    "center": list(f.center),
                    "size": list(f.size),
                    "yaw": f.yaw,
                    "height": f.height,
                }
                for f in self.furniture
            ],
            "route": [list(p) for p in self.route],
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
                )
                for w in data["walls"]
            ),
            furniture=tuple(
                Furniture(
                    center=_point(f["center"]),
                    size=_point(f["size"]),
                    yaw=float(f["yaw"]),
                    height=float(f["height"]),
                )
                for f in data["furniture"]
            ),
            ceiling_height=float(data["ceiling_height"]),
            route=tuple(_point(p) for p in data.get("route", ())),
        )


def _point(values: Sequence[float]) -> Point:
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
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    rel = points - np.asarray(box.center)
    lx = rel[:, 0] * c + rel[:, 1] * s
    ly = -rel[:, 0] * s + rel[:, 1] * c
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


def _try_plan(
    rng: np.random.Generator, n_rooms: int, glass_fraction: float, furniture_per_room: int
) -> FloorPlan | None:
    """One attempt at a plan in strip coordinates (x along the strip); None if invalid."""
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
    door_w = rng.uniform(1.5, 1.7, n_rooms + 1)

    centers, along, left_anchor, right_anchor = [], [], [], []
    for b in range(n_rooms + 1):
        u = np.array([math.sin(tilts[b]), math.cos(tilts[b])])
        center = np.array([xs[b], door_c[b]])
        centers.append(center)
        along.append(u)
        left_anchor.append(center + (left_y[b] - door_c[b]) / math.cos(tilts[b]) * u)
        right_anchor.append(center - (door_c[b] - right_y[b]) / math.cos(tilts[b]) * u)

    left = _side_polyline(rng, left_anchor, 0.8)
    right = _side_polyline(rng, right_anchor, 0.8)
    if left is None or right is None:
        return None

    # Segments in strip coordinates, with the room each side segment belongs to.
    segments: list[tuple[np.ndarray, np.ndarray]] = []
    # (room, a, b, sign of y pointing from the wall towards the strip axis)
    side_segments: list[tuple[int, np.ndarray, np.ndarray, float]] = []
    segments.append((right_anchor[0], left_anchor[0]))
    segments.append((right_anchor[-1], left_anchor[-1]))
    for b in range(1, n_rooms):
        half = door_w[b] / 2
        segments.append((right_anchor[b], centers[b] - half * along[b]))
        segments.append((centers[b] + half * along[b], left_anchor[b]))
    for inward, side in ((-1.0, left), (1.0, right)):
        for room, verts in enumerate(side):
            for p, q in pairwise(verts):
                segments.append((p, q))
                side_segments.append((room, p, q, inward))

    if not all(1.0 <= float(np.linalg.norm(q - p)) <= 8.0 for p, q in segments):
        return None
    starts = np.array([p for p, _ in segments])
    ends = np.array([q for _, q in segments])
    gaps = segment_distances(starts, ends, starts, ends)
    # Walls meeting at a corner share an exact vertex; any other pair must stay apart.
    shares_end = np.zeros_like(gaps, dtype=bool)
    for u in (starts, ends):
        for v in (starts, ends):
            shares_end |= np.all(u[:, None] == v[None], axis=2)
    if (gaps[~shares_end] < _MIN_WALL_GAP).any():
        return None

    # Route: start, through every doorway perpendicular to its divider, end.
    route = [np.array([xs[0] + 1.5, 0.0])]
    for b in range(1, n_rooms):
        normal = np.array([along[b][1], -along[b][0]])
        before, after = centers[b] - normal, centers[b] + normal
        route.append((route[-1] + before) / 2 + np.array([0.0, rng.uniform(-0.4, 0.4)]))
        route.extend([before, centers[b], after])
    end = np.array([xs[-1] - 1.5, 0.0])
    route.append((route[-1] + end) / 2 + np.array([0.0, rng.uniform(-0.4, 0.4)]))
    route.append(end)

    ceiling = float(rng.uniform(2.5, 3.0))
    walls = tuple(
        Wall(id=i, p0=_point(p), p1=_point(q), height=ceiling) for i, (p, q) in enumerate(segments)
    )
    strip = FloorPlan(walls=walls, ceiling_height=ceiling, route=tuple(_point(p) for p in route))
    curve = smooth_route(strip.route)
    if clearance(strip, curve).min() < _ROUTE_WALL_CLEARANCE:
        return None

    furniture: list[Furniture] = []
    for room in range(n_rooms):
        candidates = [s for s in side_segments if s[0] == room]
        for _ in range(furniture_per_room):
            for _ in range(30):
                _, p, q, inward = candidates[rng.integers(len(candidates))]
                box = _furniture_along(rng, p, q, inward)
                trial = FloorPlan(walls=walls, furniture=(*furniture, box))
                if _box_fits(trial, box, curve):
                    furniture.append(box)
                    break

    n_glass = round(glass_fraction * len(walls))
    glass_ids = set(rng.choice(len(walls), size=n_glass, replace=False).tolist())
    walls = tuple(
        Wall(id=w.id, p0=w.p0, p1=w.p1, glass=w.id in glass_ids, height=w.height) for w in walls
    )
    return FloorPlan(
        walls=walls,
        furniture=tuple(furniture),
        ceiling_height=ceiling,
        route=strip.route,
    )


def _furniture_along(
    rng: np.random.Generator, p: np.ndarray, q: np.ndarray, inward_y: float
) -> Furniture:
    """A box standing against the wall p→q, on the side facing the strip's axis."""
    direction = (q - p) / np.linalg.norm(q - p)
    normal = np.array([-direction[1], direction[0]])
    if normal[1] * inward_y < 0:
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
    c, s = math.cos(angle), math.sin(angle)

    def move(p: Point) -> Point:
        x, y = p[0] - origin[0], p[1] - origin[1]
        return (c * x - s * y, s * x + c * y)

    return FloorPlan(
        walls=tuple(
            Wall(id=w.id, p0=move(w.p0), p1=move(w.p1), glass=w.glass, height=w.height)
            for w in plan.walls
        ),
        furniture=tuple(
            Furniture(
                center=move(f.center),
                size=f.size,
                yaw=math.remainder(f.yaw + angle, 2 * math.pi),
                height=f.height,
            )
            for f in plan.furniture
        ),
        ceiling_height=plan.ceiling_height,
        route=tuple(move(p) for p in plan.route),
    )


def generate_floorplan(
    seed: int, *, n_rooms: int = 3, glass_fraction: float = 0.15, furniture_per_room: int = 2
) -> FloorPlan:
    """A random non-Manhattan plan: a strip of rooms a robot can drive through.

    The two long side walls are polylines with random kinks; the rooms are divided by
    walls leaning up to 35 degrees from perpendicular, each with a 1.5-1.7 m doorway (wide
    enough to pass with 0.6 m clearance to the jambs); the whole plan is rotated by a
    random angle and placed so that the route starts at the map origin. Every wall is
    1-8 m long. The same seed always gives the same plan.

    Args:
        seed: Random seed.
        n_rooms: Number of rooms along the strip (6.5-8.5 m each).
        glass_fraction: Fraction of walls that are glass (no depth return).
        furniture_per_room: Boxes placed against the side walls, away from the route.

    Returns:
        The plan, with ``route`` set to waypoints through all rooms.

    Raises:
        ValueError: If ``n_rooms`` is less than 1.
        RuntimeError: If no valid plan was found (not expected for sane arguments).
    """
    if n_rooms < 1:
        raise ValueError("n_rooms must be at least 1")
    rng = np.random.default_rng(seed)
    for _ in range(_MAX_ATTEMPTS):
        strip = _try_plan(rng, n_rooms, glass_fraction, furniture_per_room)
        if strip is not None:
            angle = float(rng.uniform(-math.pi, math.pi))
            return _transform_plan(strip, angle, np.asarray(strip.route[0]))
    raise RuntimeError(f"no valid floor plan found for seed {seed}")
