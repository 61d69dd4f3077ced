"""Which way is up, and where the floor is, found from depth data alone.

Trajectories from SLAM, visual odometry or a reconstruction system (KinectFusion, a TUM
sequence's first camera) live in a frame that is rarely level and whose floor is rarely at
z = 0. The map needs both: walls are vertical, and the height band is measured from the floor.
Buildings give the answer themselves: floors, tables and counters are horizontal planes, walls
and cabinet fronts are vertical ones. So the large planes of a few frames, put into the fixed
frame with their poses, say where up is: the direction most of their normals are either
parallel or perpendicular to. The sensor's own up axis (a camera is held roughly upright)
decides between the directions that explain the planes equally well; the floor is the lowest
horizontal plane seen in several frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

PLANE_TOLERANCE = 0.02  # m: a point within this of a plane lies on it
ANGLE_TOLERANCE = math.radians(6.0)  # a normal this close to up (or to level) counts
PRIOR_SPREAD = math.radians(40.0)  # how far up may lie from the sensor's own up axis
LEVEL_ENOUGH_DEG = 1.0  # a frame tilted less than this is taken as level as it is
KEEP_AS_IS = 0.8  # the frame's own z stays up unless another explains 1/0.8 times more
MIN_POINTS = 2000  # points over all surveyed frames below which nothing can be told


@dataclass(frozen=True)
class Plane:
    """A plane found in one frame, in the fixed frame: points p with ``normal @ p == offset``."""

    normal: Array
    offset: float
    support: int
    frame: int


def find_planes(
    points: Array,
    rng: np.random.Generator,
    frame: int = 0,
    *,
    max_planes: int = 4,
    min_share: float = 0.06,
    iterations: int = 150,
) -> list[Plane]:
    """The largest planes among ``points`` (N x 3), one after the other, by RANSAC.

    Each plane is refit to its inliers by least squares; the search stops when the next plane
    holds less than ``min_share`` of the points.
    """
    rest = points[np.isfinite(points).all(axis=1)]
    total = len(rest)
    planes: list[Plane] = []
    while len(planes) < max_planes and len(rest) >= max(3, min_share * total):
        triples = rest[rng.integers(0, len(rest), size=(iterations, 3))]
        normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
        norms = np.linalg.norm(normals, axis=1)
        good = norms > 1e-9
        if not good.any():
            break
        normals = normals[good] / norms[good, None]
        offsets = np.einsum("ij,ij->i", normals, triples[good, 0])
        # Count inliers for every hypothesis at once (iterations x points, small).
        counts = (np.abs(rest @ normals.T - offsets) < PLANE_TOLERANCE).sum(axis=0)
        best = int(np.argmax(counts))
        inliers = np.abs(rest @ normals[best] - offsets[best]) < PLANE_TOLERANCE
        if inliers.sum() < min_share * total:
            break
        on_plane = rest[inliers]
        centre = on_plane.mean(axis=0)
        normal = np.linalg.svd(on_plane - centre, full_matrices=False)[2][2]
        planes.append(Plane(normal, float(normal @ centre), int(inliers.sum()), frame))
        rest = rest[~inliers]
    return planes


@dataclass(frozen=True)
class Level:
    """Up and the floor of a fixed frame, and how sure.

    Attributes:
        up: The fixed frame's up direction (unit vector in that frame).
        floor: Height of the floor along ``up`` in the fixed frame; None when no floor was seen.
        tilt_deg: Angle between ``up`` and the fixed frame's z axis.
        explained: Share of the planes' points on planes that are horizontal or vertical for
            ``up`` (how well it explains what was seen).
        floor_frames: Frames in which the floor was seen.
        frames: Frames looked at.
    """

    up: Array
    floor: float | None
    tilt_deg: float
    explained: float
    floor_frames: int
    frames: int

    @property
    def is_level(self) -> bool:
        """Whether the fixed frame is level enough to be used as it is."""
        return self.tilt_deg < LEVEL_ENOUGH_DEG

    def matrix(self, floor: float | None = None) -> Array:
        """T_level_fixed: turns up onto z (the smallest turn) and puts the floor at z = 0.

        A frame level to within ``LEVEL_ENOUGH_DEG`` is not turned, so the map stays exactly
        in it. ``floor`` overrides the floor found (its height along up).
        """
        out = np.eye(4)
        if not self.is_level:
            out[:3, :3] = rotation_onto_z(self.up)
        height = floor if floor is not None else self.floor
        out[2, 3] = -(height or 0.0)
        return out

    def describe(self) -> str:
        """One line for people: tilt, floor, how sure."""
        if self.frames == 0:
            return "no depth frames with poses to level the frame from"
        tilt = (
            f"level within {LEVEL_ENOUGH_DEG:.0f} degree (used as it is)"
            if self.is_level
            else f"tilted {self.tilt_deg:.1f} degrees from level (levelled)"
        )
        floor = (
            f"floor at {self.floor:+.2f} m along up, seen in {self.floor_frames} of "
            f"{self.frames} frames"
            if self.floor is not None
            else f"no floor seen in {self.frames} frames (taken at 0; --floor-z sets it)"
        )
        return f"{tilt}; {floor}; {100 * self.explained:.0f} % of plane points level or upright"


def rotation_onto_z(up: Array) -> Array:
    """The smallest rotation taking the unit vector ``up`` onto +z (Rodrigues)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    sine, cosine = float(np.linalg.norm(axis)), float(up @ z)
    if sine < 1e-12:
        return np.eye(3) if cosine > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / sine
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + sine * cross + (1.0 - cosine) * cross @ cross


def _fit(normals: Array, weights: Array, up: Array) -> tuple[Array, Array, Array]:
    """How each normal agrees with ``up``: as a level plane, as an upright one (0..1 each)."""
    along = np.clip(np.abs(normals @ up), 0.0, 1.0)
    off_level = np.arccos(along)  # 0 for a level plane
    off_upright = np.abs(np.pi / 2 - off_level)
    level = np.clip(1.0 - off_level / ANGLE_TOLERANCE, 0.0, None) * weights
    upright = np.clip(1.0 - off_upright / ANGLE_TOLERANCE, 0.0, None) * weights
    return level, upright, along


def _score(normals: Array, weights: Array, up: Array, prior: Array | None) -> float:
    score = _explained(normals, weights, up)
    if prior is not None:
        angle = math.acos(max(-1.0, min(1.0, float(up @ prior))))
        score *= math.exp(-((angle / PRIOR_SPREAD) ** 2))
    return score


def _refine(normals: Array, weights: Array, up: Array) -> Array:
    """Least squares on the planes ``up`` explains: level normals along it, upright ones across."""
    for _ in range(3):
        level, upright, _ = _fit(normals, weights, up)
        if level.sum() + upright.sum() == 0:
            return up
        outer = np.einsum("i,ij,ik->jk", upright, normals, normals)
        outer += level.sum() * np.eye(3) - np.einsum("i,ij,ik->jk", level, normals, normals)
        refined = np.linalg.eigh(outer)[1][:, 0]
        up = refined if refined @ up > 0 else -refined
    return up


def estimate_up(planes: list[Plane], sensor_ups: Array | None = None) -> tuple[Array, float]:
    """Up from planes found in several frames (all in the fixed frame), and how well it fits.

    Args:
        planes: The planes.
        sensor_ups: (m, 3) the sensor's up axis in the fixed frame at those frames (a camera's
            -y, a body frame's z): which way is roughly up, and which way round.

    Returns:
        The up direction and the share of the planes' points it explains.
    """
    z = np.array([0.0, 0.0, 1.0])
    prior = None
    if sensor_ups is not None and len(sensor_ups):
        mean = np.asarray(sensor_ups, dtype=np.float64).mean(axis=0)
        prior = mean / np.linalg.norm(mean) if np.linalg.norm(mean) > 1e-6 else None
    if not planes:
        return z, 0.0
    normals = np.array([p.normal for p in planes])
    weights = np.array([p.support for p in planes], dtype=np.float64)
    weights /= weights.sum()
    candidates = [z, *normals]
    if prior is not None:
        candidates.append(prior)
    heaviest = np.argsort(weights)[::-1][:40]
    for i in heaviest:
        for j in heaviest:
            if i < j and abs(normals[i] @ normals[j]) < 0.5:  # 60 to 120 degrees apart
                cross = np.cross(normals[i], normals[j])
                candidates.append(cross / np.linalg.norm(cross))
    toward = prior if prior is not None else z
    oriented = [c if c @ toward >= 0 else -c for c in candidates]
    best = _refine(
        normals, weights, max(oriented, key=lambda c: _score(normals, weights, c, prior))
    )
    # The frame as it is, unless another up explains clearly more of what was seen.
    as_is = z if z @ toward >= 0 else -z
    best_explains, as_is_explains = (_explained(normals, weights, up) for up in (best, as_is))
    if as_is_explains >= KEEP_AS_IS * best_explains:
        return as_is, as_is_explains
    return best, best_explains


def _explained(normals: Array, weights: Array, up: Array) -> float:
    level, upright, _ = _fit(normals, weights, up)
    return float(level.sum() + upright.sum())


FLOOR_SLICE = 0.02  # m: the thickness of the slice a floor's points fall into
FLOOR_SHARE = 0.01  # of all points: what a slice must hold to be the floor


def find_floor(heights: list[Array], below: float) -> tuple[float | None, int]:
    """The floor: the lowest thin slice of points, seen in several frames, below the sensor.

    A floor is level and lies under everything else, so along up its points pile into one thin
    slice at the bottom of what the sensor saw (a few stray returns may lie below it).

    Args:
        heights: Per frame, the heights (along up) of the points seen.
        below: The floor lies below this height (the sensor's lowest height, less a margin).

    Returns:
        The floor's height and the number of frames it was seen in; (None, 0) if not found.
    """
    finite = [h[np.isfinite(h)] for h in heights]
    total = sum(h.size for h in finite)
    every = np.concatenate(finite) if finite else np.array([])
    every = every[every < below]
    if every.size < 100:
        return None, 0
    start = math.floor(float(every.min()) / FLOOR_SLICE) * FLOOR_SLICE
    edges = np.arange(start, float(every.max()) + 2 * FLOOR_SLICE, FLOOR_SLICE)
    counts, _ = np.histogram(every, edges)
    dense = np.flatnonzero(counts >= FLOOR_SHARE * total)
    if not dense.size:
        return None, 0
    first = int(dense[0])
    if counts[:first].sum() > FLOOR_SHARE * total:
        return None, 0  # much lies below the first dense slice: that is no floor
    peak = first + int(np.argmax(counts[first : first + 3]))
    centre = 0.5 * (edges[peak] + edges[peak + 1])
    floor = float(np.median(every[np.abs(every - centre) < 1.5 * FLOOR_SLICE]))
    frames = sum(int((np.abs(h - floor) < FLOOR_SLICE).sum() >= 20) for h in finite)
    return (floor, frames) if frames >= min(2, len(finite)) else (None, 0)


def level_from_frames(
    points: list[Array], sensor_ups: Array, sensor_positions: Array, rng: np.random.Generator
) -> Level:
    """Up and the floor of the fixed frame, from some frames' points in it.

    Args:
        points: Per frame, points (N x 3) in the fixed frame (a few thousand are plenty).
        sensor_ups: (m, 3) the sensor's up axis in the fixed frame at those frames.
        sensor_positions: (m, 3) the sensor's positions in the fixed frame: the floor is below.
        rng: For RANSAC.
    """
    if sum(len(cloud) for cloud in points) < MIN_POINTS:
        return Level(np.array([0.0, 0.0, 1.0]), None, 0.0, 0.0, 0, len(points))
    planes = [plane for i, cloud in enumerate(points) for plane in find_planes(cloud, rng, i)]
    up, explained = estimate_up(planes, sensor_ups)
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(up[2])))))
    lowest = float(np.min(sensor_positions @ up)) if len(sensor_positions) else math.inf
    floor, seen_in = find_floor([cloud @ up for cloud in points], lowest - 0.2)
    return Level(up, floor, tilt, explained, seen_in, len(points))
