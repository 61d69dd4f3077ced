"""Depth images and laser scans of a floor plan by vectorised ray casting.

A Kinect-like depth camera sees walls, furniture, floor and ceiling; a 2-D laser scanner
casts horizontal rays at its mount height and sees only what stands that tall.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import lru_cache
from typing import Any, Self

import numpy as np

from wallmap.scene.floorplan import FloorPlan, Point, Wall, point_segment_distance

# Optical frame (z forward, x right, y down) expressed in camera_link (x forward, z up).
R_LINK_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

_KINECT_HFOV_DEG = 57.0
_KINECT_VFOV_DEG = 43.0
_CHUNK_RAYS = 8192  # bounds the (rays x segments) temporaries to a few MB


class _MountedSensor:
    """JSON round trip for the sensors' dataclasses (their mount is a tuple)."""

    mount_xyz: tuple[float, float, float]

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form for ground-truth files."""
        data = asdict(self)  # type: ignore[call-overload]
        data["mount_xyz"] = list(self.mount_xyz)
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Self:
        """Inverse of :meth:`to_json`."""
        return cls(**{**data, "mount_xyz": tuple(data["mount_xyz"])})


@dataclass(frozen=True)
class Camera(_MountedSensor):
    """A pinhole depth camera on the robot.

    Intrinsics left as NaN are derived from the Kinect's 57 x 43 degree field of view at
    the given image size, so ``Camera(width=640, height=480)`` is Kinect-like too.

    Attributes:
        width: Image width in pixels.
        height: Image height in pixels.
        fx: Focal length in pixels along x (NaN: from the horizontal field of view).
        fy: Focal length in pixels along y (NaN: from the vertical field of view).
        cx: Principal point x (NaN: image centre).
        cy: Principal point y (NaN: image centre).
        min_range: Nearer depths give no return.
        max_range: Farther depths give no return.
        noise_k: Depth noise sigma = noise_k * z**2 (Khoshelham & Elberink 2012).
        mount_xyz: Position of camera_link in base_link.
        tilt_deg: Rotation of camera_link about base_link's y axis; positive looks up.
    """

    width: int = 160
    height: int = 120
    fx: float = math.nan
    fy: float = math.nan
    cx: float = math.nan
    cy: float = math.nan
    min_range: float = 0.5
    max_range: float = 5.0
    noise_k: float = 1.425e-3
    mount_xyz: tuple[float, float, float] = (0.1, 0.0, 1.0)
    tilt_deg: float = 0.0

    def __post_init__(self) -> None:
        derived = {
            "fx": (self.width / 2) / math.tan(math.radians(_KINECT_HFOV_DEG / 2)),
            "fy": (self.height / 2) / math.tan(math.radians(_KINECT_VFOV_DEG / 2)),
            "cx": (self.width - 1) / 2,
            "cy": (self.height - 1) / 2,
        }
        for name, value in derived.items():
            if math.isnan(getattr(self, name)):
                object.__setattr__(self, name, value)

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the usual name of the intrinsic matrix
        """Intrinsic matrix (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def R_base_link(self) -> np.ndarray:  # noqa: N802 - rotation naming R_parent_child
        """Rotation of camera_link in base_link: the tilt about y."""
        a = math.radians(-self.tilt_deg)
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    @property
    def T_base_camera(self) -> np.ndarray:
        """Pose (4, 4) of the optical frame in base_link: maps optical points to base_link."""
        transform = np.eye(4)
        transform[:3, :3] = self.R_base_link @ R_LINK_OPTICAL
        transform[:3, 3] = self.mount_xyz
        return transform


@dataclass(frozen=True)
class Scanner(_MountedSensor):
    """A planar laser scanner on the robot: 270 degrees in 0.5 degree steps, up to 8 m.

    Attributes:
        angle_min: Angle of the first beam, counter-clockwise from the laser's x axis.
        angle_max: Angle of the last beam.
        n_beams: Number of beams, evenly spaced from ``angle_min`` to ``angle_max``.
        range_min: Nearer ranges give no return.
        range_max: Farther ranges give no return.
        noise_sigma: Range noise sigma in metres, the same at every distance.
        mount_xyz: Position of the laser frame in base_link; the default height clears
            the furniture (at most 1.1 m), so the scan sees the walls behind it.
    """

    angle_min: float = -3 * math.pi / 4
    angle_max: float = 3 * math.pi / 4
    n_beams: int = 541
    range_min: float = 0.1
    range_max: float = 8.0
    noise_sigma: float = 0.01
    mount_xyz: tuple[float, float, float] = (0.15, 0.0, 1.2)

    @property
    def angle_increment(self) -> float:
        """Angle between neighbouring beams (0.5 degrees by default)."""
        return (self.angle_max - self.angle_min) / (self.n_beams - 1)

    @property
    def angles(self) -> np.ndarray:
        """Beam angles (n_beams,) in the laser frame, as a LaserScan reader computes them."""
        return self.angle_min + self.angle_increment * np.arange(self.n_beams)

    @property
    def T_base_laser(self) -> np.ndarray:
        """Pose (4, 4) of the laser frame in base_link: level and facing forward."""
        transform = np.eye(4)
        transform[:3, 3] = self.mount_xyz
        return transform


@lru_cache(maxsize=8)
def _pixel_rays(camera: Camera) -> np.ndarray:
    """Ray per pixel (h*w, 3) in the optical frame, scaled so that z = 1 (t is depth)."""
    u, v = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    rays = np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)], axis=-1
    ).reshape(-1, 3)
    rays.flags.writeable = False
    return rays


@dataclass(frozen=True)
class _Geometry:
    """A plan as arrays: vertical segments (walls and box sides) and box tops."""

    seg_a: np.ndarray  # (M, 2) segment starts
    seg_e: np.ndarray  # (M, 2) segment vectors
    seg_top: np.ndarray  # (M,) height of the quad's top above the floor
    seg_bottom: np.ndarray  # (M,) and of its bottom
    seg_label: np.ndarray  # (M,) wall id, -1 for furniture
    seg_glass: np.ndarray  # (M,) glass walls return nothing
    box_center: np.ndarray  # (F, 2)
    box_axes: np.ndarray  # (F, 2): cos, sin of yaw
    box_half: np.ndarray  # (F, 2): half size
    box_top: np.ndarray  # (F,)


@lru_cache(maxsize=8)
def _geometry(plan: FloorPlan) -> _Geometry:
    starts, ends, tops, bottoms, labels, glass = [], [], [], [], [], []
    for wall in plan.walls:
        for p, q, bottom, top, pane in _wall_quads(wall):
            starts.append(p)
            ends.append(q)
            bottoms.append(bottom)
            tops.append(top)
            labels.append(wall.id)
            glass.append(wall.glass or pane)
    for box in plan.furniture:
        corners = box.corners()
        starts.extend(corners.tolist())
        ends.extend(np.roll(corners, -1, axis=0).tolist())
        tops.extend([box.height] * 4)
        bottoms.extend([box.base] * 4)
        labels.extend([-1] * 4)
        glass.extend([False] * 4)
    a = np.array(starts, dtype=float).reshape(-1, 2)
    return _Geometry(
        seg_a=a,
        seg_e=np.array(ends, dtype=float).reshape(-1, 2) - a,
        seg_top=np.array(tops, dtype=float),
        seg_bottom=np.array(bottoms, dtype=float),
        seg_label=np.array(labels, dtype=np.int32),
        seg_glass=np.array(glass, dtype=bool),
        box_center=np.array([b.center for b in plan.furniture], dtype=float).reshape(-1, 2),
        box_axes=np.array(
            [(math.cos(b.yaw), math.sin(b.yaw)) for b in plan.furniture], dtype=float
        ).reshape(-1, 2),
        box_half=np.array([b.size for b in plan.furniture], dtype=float).reshape(-1, 2) / 2,
        box_top=np.array([b.height for b in plan.furniture], dtype=float),
    )


def _wall_quads(wall: Wall) -> list[tuple[Point, Point, float, float, bool]]:
    """A wall as vertical quads (start, end, bottom, top, glass): solid around its windows."""
    if not wall.windows:
        return [(wall.p0, wall.p1, 0.0, wall.height, False)]
    p0, p1 = np.asarray(wall.p0, float), np.asarray(wall.p1, float)
    along = (p1 - p0) / wall.length

    def at(t: float) -> Point:
        x, y = p0 + along * t
        return (float(x), float(y))

    quads, done = [], 0.0
    for start, end, bottom, top in sorted(wall.windows):
        quads.append((at(done), at(start), 0.0, wall.height, False))
        quads.append((at(start), at(end), 0.0, bottom, False))
        quads.append((at(start), at(end), bottom, top, True))
        quads.append((at(start), at(end), top, wall.height, False))
        done = end
    quads.append((at(done), wall.p1, 0.0, wall.height, False))
    return [q for q in quads if math.dist(q[0], q[1]) > 1e-9 and q[3] > q[2]]


def _nearest_vertical(
    origin: np.ndarray,
    rays: np.ndarray,
    a: np.ndarray,
    e: np.ndarray,
    top: np.ndarray,
    bottom: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of each ray on vertical quads (segment x [bottom, top]): (t, segment)."""
    rx, ry, rz = rays[:, 0:1], rays[:, 1:2], rays[:, 2:3]
    wx, wy = a[:, 0] - origin[0], a[:, 1] - origin[1]
    ex, ey = e[:, 0], e[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / (rx * ey - ry * ex)
        t = (wx * ey - wy * ex) * inv
        s = (wx * ry - wy * rx) * inv
        z = origin[2] + t * rz
        hit = (t > 1e-9) & (s >= 0.0) & (s <= 1.0) & (z >= bottom) & (z <= top)
    t = np.where(hit, t, np.inf)
    index = np.argmin(t, axis=1)
    return t[np.arange(len(t)), index], index


def _nearest_box_top(origin: np.ndarray, rays: np.ndarray, geo: _Geometry) -> np.ndarray:
    """Depth of each ray's hit on the top faces of the furniture boxes (inf if none)."""
    if len(geo.box_top) == 0:
        return np.full(len(rays), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (geo.box_top[None] - origin[2]) / rays[:, 2:3]
        px = origin[0] + t * rays[:, 0:1] - geo.box_center[:, 0]
        py = origin[1] + t * rays[:, 1:2] - geo.box_center[:, 1]
        c, s = geo.box_axes[:, 0], geo.box_axes[:, 1]
        inside = (np.abs(px * c + py * s) <= geo.box_half[:, 0]) & (
            np.abs(-px * s + py * c) <= geo.box_half[:, 1]
        )
        t = np.where(inside & (t > 1e-9), t, np.inf)
    return t.min(axis=1)


def _cast_vertical(
    geo: _Geometry, origin: np.ndarray, rays: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hit of each ray on the walls and box sides: (t, wall id or -1, glass).

    Segments farther than ``reach`` (the longest in-range ray) cannot matter and are skipped;
    rays are cast in chunks so that the (rays x segments) temporaries stay small.
    """
    near = point_segment_distance(origin[None, :2], geo.seg_a, geo.seg_a + geo.seg_e)[0]
    keep = np.flatnonzero(near <= reach)
    n = len(rays)
    t_hit = np.full(n, np.inf)
    label = np.full(n, -1, dtype=np.int32)
    glass = np.zeros(n, dtype=bool)
    if len(keep):
        a, e, top = geo.seg_a[keep], geo.seg_e[keep], geo.seg_top[keep]
        bottom = geo.seg_bottom[keep]
        for start in range(0, n, _CHUNK_RAYS):
            chunk = slice(start, start + _CHUNK_RAYS)
            t, index = _nearest_vertical(origin, rays[chunk], a, e, top, bottom)
            t_hit[chunk] = t
            label[chunk] = geo.seg_label[keep][index]
            glass[chunk] = geo.seg_glass[keep][index]
    return t_hit, label, glass


def _cast_everything(
    plan: FloorPlan, origin: np.ndarray, rays: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hit of each ray on walls, furniture, floor or ceiling: (t, wall id or -1, glass).

    A camera sees all of them, unlike a scanner's level beams, which meet only what stands.
    """
    geo = _geometry(plan)
    depth, label, glass = _cast_vertical(geo, origin, rays, reach)
    rz = rays[:, 2]
    with np.errstate(divide="ignore"):
        planes = np.where(rz < 0, -origin[2] / rz, (plan.ceiling_height - origin[2]) / rz)
    planes[rz == 0] = np.inf
    other = np.minimum(planes, _nearest_box_top(origin, rays, geo))
    closer = other < depth
    depth[closer] = other[closer]
    label[closer] = -1
    glass[closer] = False
    return depth, label, glass


def render_depth(
    plan: FloorPlan,
    x: float,
    y: float,
    yaw: float,
    camera: Camera,
    rng: np.random.Generator | None = None,
    mount: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Depth image seen with base_link at (x, y, yaw).

    Rays are cast against the walls (two-sided quads from the floor to their height),
    the furniture boxes (sides and top), the floor and the ceiling. A ray whose first hit
    is glass gets no return, as do depths outside [min_range, max_range].

    Args:
        plan: The scene.
        x: Position of base_link in the map frame.
        y: Position of base_link in the map frame.
        yaw: Heading of base_link in the map frame.
        camera: Sensor and mount.
        rng: Source of depth noise (sigma = noise_k * z**2); None for an exact image.
        mount: T_base_optical for this frame (a handheld camera's), else the camera's own.

    Returns:
        depth: float32 (h, w), metres along the optical z axis, NaN where no return.
        hit_wall: int32 (h, w), id of the wall each ray hit first within range (glass
        included, though it gives no return), -1 for floor, ceiling, furniture, out of
        range or nothing.
    """
    rays_cam = _pixel_rays(camera)
    mount = camera.T_base_camera if mount is None else mount
    c, s = math.cos(yaw), math.sin(yaw)
    r_world_base = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    origin = np.array([x, y, 0.0]) + r_world_base @ mount[:3, 3]
    rays = rays_cam @ (r_world_base @ mount[:3, :3]).T

    reach = camera.max_range * float(np.linalg.norm(rays_cam, axis=1).max())
    depth, label, glass = _cast_everything(plan, origin, rays, reach)

    in_range = (depth >= camera.min_range) & (depth <= camera.max_range)
    label[~in_range] = -1
    valid = in_range & ~glass
    if rng is not None and camera.noise_k > 0:
        noise = rng.normal(size=len(rays)) * camera.noise_k
        depth = depth + noise * np.where(valid, depth, 0.0) ** 2
    shape = (camera.height, camera.width)
    return (
        np.where(valid, depth, np.nan).astype(np.float32).reshape(shape),
        label.reshape(shape),
    )


def depth_to_points(depth: np.ndarray, camera: Camera) -> np.ndarray:
    """Back-project a depth image to points (h, w, 3) float32 in the optical frame."""
    rays = _pixel_rays(camera).reshape(camera.height, camera.width, 3)
    return (rays * depth[..., None]).astype(np.float32)


def walls_seen(
    hit_wall: np.ndarray,
    depth: np.ndarray,
    camera: Camera,
    *,
    z_band: tuple[float, float] = (1.3, 2.1),
    min_columns: int = 15,
    mount: np.ndarray | None = None,
) -> set[int]:
    """Ids of the walls the detector can see in this frame.

    The detector looks at a height band above the furniture, so a wall counts as seen
    when at least ``min_columns`` image columns have a return from it at a height (in
    base_link, z up) inside ``z_band``. The height does not depend on the robot's pose.
    """
    points = depth_to_points(depth, camera).astype(float)
    mount = camera.T_base_camera if mount is None else mount
    z = points @ mount[2, :3] + mount[2, 3]
    with np.errstate(invalid="ignore"):
        mask = (hit_wall >= 0) & (z >= z_band[0]) & (z <= z_band[1])
    _, cols = np.nonzero(mask)
    pairs = np.unique(hit_wall[mask].astype(np.int64) * camera.width + cols)
    ids, counts = np.unique(pairs // camera.width, return_counts=True)
    return {int(i) for i, k in zip(ids, counts, strict=True) if k >= min_columns}


def render_scan(
    plan: FloorPlan,
    x: float,
    y: float,
    yaw: float,
    scanner: Scanner,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Laser scan taken with base_link at (x, y, yaw).

    The beams are horizontal at the mount height, so they hit walls and only the furniture
    that reaches that high; floor and ceiling are never seen. A beam whose first hit is glass
    gets no return, as do measured ranges outside [range_min, range_max].

    Args:
        plan: The scene.
        x: Position of base_link in the map frame.
        y: Position of base_link in the map frame.
        yaw: Heading of base_link in the map frame.
        scanner: Sensor and mount.
        rng: Source of range noise (sigma = noise_sigma); None for an exact scan.

    Returns:
        ranges: float32 (n_beams,), metres from the laser frame's origin, NaN where no
        return.
        hit_wall: int32 (n_beams,), id of the wall each beam hit first within range (glass
        included, though it gives no return), -1 for furniture, out of range or nothing.
    """
    geo = _geometry(plan)
    c, s = math.cos(yaw), math.sin(yaw)
    mount = scanner.mount_xyz
    origin = np.array([x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1], mount[2]])
    angles = yaw + scanner.angles
    rays = np.stack([np.cos(angles), np.sin(angles), np.zeros(scanner.n_beams)], axis=1)
    ranges, label, glass = _cast_vertical(geo, origin, rays, scanner.range_max)

    hit = np.isfinite(ranges)
    if rng is not None and scanner.noise_sigma > 0:
        ranges = ranges + rng.normal(size=scanner.n_beams) * scanner.noise_sigma * hit
    in_range = hit & (ranges >= scanner.range_min) & (ranges <= scanner.range_max)
    label[~in_range] = -1
    valid = in_range & ~glass
    return np.where(valid, ranges, np.nan).astype(np.float32), label


def scan_walls_seen(hit_wall: np.ndarray, ranges: np.ndarray, *, min_beams: int = 15) -> set[int]:
    """Ids of the walls the detector can see in this scan.

    A wall counts as seen when at least ``min_beams`` beams return from it (about 7 degrees
    at the default resolution), enough points for a line fit; glass never returns.
    """
    mask = (hit_wall >= 0) & np.isfinite(ranges)
    ids, counts = np.unique(hit_wall[mask], return_counts=True)
    return {int(i) for i, k in zip(ids, counts, strict=True) if k >= min_beams}
