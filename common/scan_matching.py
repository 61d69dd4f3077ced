"""Odometry from 2-D scans, and correction of a pose against mapped walls.

A recording with scans but no poses needs odometry. ``docs/research/scan-matching.md`` measured
the candidates on the real bags; the best map came from point-to-line ICP against a *local map* of
the last keyframes with a weak constant-velocity prior, in plain numpy. Matching against several
keyframes rather than the previous scan averages the noise of a cheap lidar; point-to-line
residuals let a scan slide along a wall where point-to-point would pull it onto the nearest
sample; and the prior is what keeps a featureless corridor, where the scan constrains nothing
along the walls, from sliding or spiking.

Poses are (x, y, yaw); as 3x3 homogeneous matrices internally (``common.se2``), so that composing
them is one product. Solver increments are applied on the right, ``T = T @ se2.matrix(d)``: they
live in the sensor frame, where the Jacobian of a point is simplest and independent of where the
odometry frame is.

:func:`register_to_walls` is the other half: refining a pose against walls already in the map,
so that a corridor's walls remove the drift across it while the pose's own prior keeps what the
walls cannot see.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wallmap.common import se2
from wallmap.common.se2 import Array

_BIAS = 1 << 30  # grid indices are shifted by this so that keys are non-negative
_NEIGHBOURS = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)], dtype=np.int64)
_REGULARISER = 1e-9  # keeps the normal equations solvable with the prior switched off


@dataclass(frozen=True)
class MatcherConfig:
    """Every tuning value of the scan matcher and of :func:`register_to_walls`.

    The defaults are the study's best configuration on ``hallway.bag``, ``eng403_good.bag`` and
    ``lsm_demo_2010.bag`` (360-beam lidars at ~14 Hz on robots at ~0.5 m/s), see
    ``docs/research/scan-matching.md``.

    Attributes:
        cell: Side of the local map's grid cells (m). Each cell holding enough points on a line
            becomes one map point (their centroid) with one line normal (their PCA), so the cell
            is both the nearest-neighbour index and the neighbourhood of the normal. 0.25 and
            0.4 m each gave a less crisp map of eng403_good.bag.
        keyframes: Keyframe scans kept in the local map: enough to average a noisy lidar (10
            lost a third of the crispness on lsm_demo_2010.bag), few enough to carry little
            drift (40 was no better).
        keyframe_distance: A scan becomes a keyframe once it is this far (m) from the last one.
        keyframe_angle: ... or turned this much (rad) from it.
        min_cell_points: Fewest points for a cell to be a map point; fewer give no line.
        flatness: Largest ratio of a cell's smaller to larger scatter eigenvalue for it to count
            as a line; corners and clutter fail and are not matched at all.
        max_distance: Correspondence cut-off (m) for the first ``coarse_iterations``, wide
            enough to catch the prediction's error.
        fine_max_distance: Cut-off (m) afterwards, so that near-misses of other walls drop out.
        coarse_iterations: Iterations with the wide cut-off.
        iterations: Most Gauss-Newton iterations per registration.
        convergence: Stop when no increment component exceeds this (m or rad).
        huber: Residual (m) beyond which a point's weight falls as 1/|r| (Huber), so people
            walking by and glass reflections pull with bounded force.
        min_range: Points nearer than this (m) to the base frame's origin are ignored (the
            robot's own body, dust on the window).
        max_range: Points farther than this (m) from the base frame's origin are ignored. Set
            it a little below the sensor's own limit when that limit cuts noisy ranges: near
            it only the returns that came out short survive, so a wall seen there looks
            nearer than it is.
        point_sigma: Standard deviation (m) of a point's distance to its line (range noise and
            wall roughness). It scales the covariances and weighs the points of
            :func:`register_to_walls` against the guess's covariance.
        prior_weight: Weight of the constant-velocity prior in the normal equations, in
            points: the prediction counts as this many points constraining every direction.
            Weak enough that any wall overrules it, strong enough to hold a corridor: 0 let
            hallway.bag jump 7 times; 5 and 20 gave a less crisp eng403_good.bag.
        rotation_scale: Metres per radian of the prior's yaw term, so that it is about as
            strong as a point ``rotation_scale`` away from the sensor.
        max_speed: Largest plausible speed (m/s); a registration implying a faster step since
            the previous scan is rejected (the step gate).
        max_turn_rate: Largest plausible turn rate (rad/s), the step gate's yaw limit.
        min_points: Fewest valid points in a scan, and fewest correspondences, for a
            registration to be accepted.
        period_smoothing: Gain of the running average of the time between scans, which turns
            a gap in the stamps into a whole number of scan periods for the prediction.
    """

    cell: float = 0.3
    keyframes: int = 20
    keyframe_distance: float = 0.25
    keyframe_angle: float = math.radians(10.0)
    min_cell_points: int = 4
    flatness: float = 0.1
    max_distance: float = 0.5
    fine_max_distance: float = 0.25
    coarse_iterations: int = 5
    iterations: int = 30
    convergence: float = 1e-5
    huber: float = 0.05
    min_range: float = 0.1
    max_range: float = 20.0
    point_sigma: float = 0.02
    prior_weight: float = 10.0
    rotation_scale: float = 2.0
    max_speed: float = 2.0
    max_turn_rate: float = math.radians(180.0)
    min_points: int = 30
    period_smoothing: float = 0.1

    def __post_init__(self) -> None:
        if self.cell <= 0 or self.keyframes < 1 or self.iterations < 1:
            raise ValueError("cell, keyframes and iterations must be positive")
        if self.prior_weight < 0 or self.point_sigma <= 0 or self.huber <= 0:
            raise ValueError("prior_weight must be >= 0, point_sigma and huber > 0")


@dataclass(frozen=True, eq=False)
class Registration:
    """The outcome of matching one scan.

    Attributes:
        pose: (x, y, yaw) of the base frame in the odometry frame (3,).
        cov: Covariance (3, 3) of ``pose`` from this registration alone (not the accumulated
            drift), in the odometry frame: sigma^2 times the inverse of the solver's
            information matrix, prior included. Along a degenerate corridor it is large,
            bounded by the motion prior. For a rejected scan, the motion prior's covariance;
            zero for the first scan, which defines the frame.
        matched: Fraction of the scan's valid points with a correspondence in the local map
            (1.0 for the first scan, which defines the map).
        iterations: Gauss-Newton iterations run.
        accepted: False when the step gate, too few points or a stamp not after the previous
            one rejected the registration; the pose is then the motion-prior prediction and
            the scan is not added to the map.
        reason: Why it was rejected; empty if accepted.
        stamp: The scan's stamp (s).
        keyframe: Whether the scan was added to the local map.
    """

    pose: Array
    cov: Array
    matched: float
    iterations: int
    accepted: bool
    reason: str = ""
    stamp: float = 0.0
    keyframe: bool = False


@dataclass(frozen=True, eq=False)
class WallLine:
    """A mapped wall: the line ``normal . p = offset`` in the map frame, between p0 and p1.

    The end points matter: a point may only match a wall where the wall is, so that collinear
    walls of different rooms and the wall behind a doorway's gap are not confused.
    """

    normal: Array
    offset: float
    p0: Array
    p1: Array

    @classmethod
    def from_points(cls, p0: ArrayLike, p1: ArrayLike) -> WallLine:
        """The wall through two end points (its normal points to the left of p0 -> p1)."""
        a, b = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
        direction = (b - a) / np.linalg.norm(b - a)
        normal = np.array([-direction[1], direction[0]])
        return cls(normal, float(normal @ a), a, b)


def _huber_weights(residuals: Array, k: float) -> Array:
    return k / np.maximum(np.abs(residuals), k)


def _usable_points(points: ArrayLike, config: MatcherConfig) -> Array:
    """The rows that are finite and within the range limits, as float64 (M, 2)."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (N, 2), not {p.shape}")
    p = p[np.isfinite(p).all(axis=1)]
    r2 = np.einsum("ij,ij->i", p, p)
    return p[(r2 >= config.min_range**2) & (r2 <= config.max_range**2)]


def _cell_keys(ij: Array) -> Array:
    """One int64 per grid cell, so that a sorted key array is the hash table."""
    return (ij[..., 0] + _BIAS) * (1 << 31) + (ij[..., 1] + _BIAS)


class _LocalMap:
    """Keyframe points in the odometry frame, one centroid and line normal per grid cell.

    The cells are found by binary search in their sorted keys: no tree to build, and building
    takes one ``np.unique`` per keyframe. Only cells whose points form a line are kept.
    """

    def __init__(self, points: Array, config: MatcherConfig) -> None:
        self._cell = config.cell
        keys, inverse, counts = np.unique(
            _cell_keys(np.floor(points / config.cell).astype(np.int64)),
            return_inverse=True,
            return_counts=True,
        )
        mx = np.bincount(inverse, points[:, 0]) / counts
        my = np.bincount(inverse, points[:, 1]) / counts
        dx, dy = points[:, 0] - mx[inverse], points[:, 1] - my[inverse]
        cxx = np.bincount(inverse, dx * dx) / counts
        cyy = np.bincount(inverse, dy * dy) / counts
        cxy = np.bincount(inverse, dx * dy) / counts
        half_trace = (cxx + cyy) / 2
        spread = np.sqrt(np.maximum(half_trace**2 - (cxx * cyy - cxy**2), 0.0))
        larger = half_trace + spread
        line = (counts >= config.min_cell_points) & (
            half_trace - spread <= config.flatness * larger
        )
        along = 0.5 * np.arctan2(2 * cxy, cxx - cyy)  # direction of the larger eigenvalue
        self.keys = keys[line]
        self.centroids = np.column_stack([mx, my])[line]
        self.normals = np.column_stack([-np.sin(along), np.cos(along)])[line]

    def match(self, points: Array, max_distance: float) -> tuple[Array, Array, Array]:
        """Nearest map point among the 3x3 cells around each point: (centroid, normal, found)."""
        if len(self.keys) == 0:
            return np.zeros_like(points), np.zeros_like(points), np.zeros(len(points), bool)
        ij = np.floor(points / self._cell).astype(np.int64)
        wanted = _cell_keys(ij[:, None, :] + _NEIGHBOURS[None])  # (N, 9)
        slot = np.minimum(np.searchsorted(self.keys, wanted), len(self.keys) - 1)
        d2 = np.where(
            self.keys[slot] == wanted,
            ((self.centroids[slot] - points[:, None, :]) ** 2).sum(axis=-1),
            np.inf,
        )
        best = d2.argmin(axis=1)
        rows = np.arange(len(points))
        index = slot[rows, best]
        found = d2[rows, best] < max_distance**2
        return self.centroids[index], self.normals[index], found


@dataclass(frozen=True)
class _Fit:
    transform: Array
    information: Array  # sum of w J^T J plus the prior, in units of 1 / point_sigma^2
    found: Array
    iterations: int


def _align(local_map: _LocalMap, points: Array, prediction: Array, config: MatcherConfig) -> _Fit:
    """Point-to-line Gauss-Newton from the prediction, with the prediction as a prior."""
    prior = config.prior_weight * np.array([1.0, 1.0, config.rotation_scale**2])
    to_prediction = se2.invert_matrix(prediction)
    t = prediction.copy()
    information = np.diag(prior + _REGULARISER)  # what is left if nothing matches
    for iteration in range(1, config.iterations + 1):
        moved = points @ t[:2, :2].T + t[:2, 2]
        reach = (
            config.max_distance
            if iteration <= config.coarse_iterations
            else config.fine_max_distance
        )
        centroid, normal, found = local_map.match(moved, reach)
        if np.count_nonzero(found) < config.min_points:
            break
        residual = np.einsum("ij,ij->i", moved[found] - centroid[found], normal[found])
        local_normal = normal[found] @ t[:2, :2]  # R^T n: the normal in the sensor frame
        p = points[found]
        jacobian = np.column_stack(
            [local_normal, local_normal[:, 1] * p[:, 0] - local_normal[:, 0] * p[:, 1]]
        )
        weighted = jacobian * _huber_weights(residual, config.huber)[:, None]
        information = weighted.T @ jacobian + np.diag(prior + _REGULARISER)
        deviation = se2.from_matrix(to_prediction @ t)  # where the prior pulls back from
        step = -np.linalg.solve(information, weighted.T @ residual + prior * deviation)
        t = t @ se2.matrix(step)
        if np.abs(step).max() < config.convergence:
            break
    return _Fit(t, information, found, iteration)


class ScanMatcher:
    """Odometry from a stream of 2-D scans: each scan is matched against a local map.

    The odometry frame is the base frame at the first usable scan. Each scan is predicted by
    repeating the last accepted step in the base frame (a robot's constant twist), registered
    by point-to-line ICP against the last ``config.keyframes`` keyframes, checked against the
    step gate, and becomes a keyframe when it has moved far enough from the last one.

    A rejected scan changes neither the map nor the velocity, so a few bad scans are bridged;
    a matcher that keeps rejecting (the sensor was carried elsewhere) dead-reckons and does not
    recover by itself. Not thread-safe: one instance per stream.
    """

    def __init__(self, config: MatcherConfig = MatcherConfig()) -> None:
        self.config = config
        self._keyframes: deque[Array] = deque(maxlen=config.keyframes)
        self._map: _LocalMap | None = None
        self._pose = np.eye(3)
        self._keyframe_pose = np.eye(3)
        self._step = np.zeros(3)  # body-frame motion per scan period, from the last accepted scan
        self._period = math.nan  # smoothed time between scans (s)
        self._stamp = -math.inf

    def update(self, points: np.ndarray, stamp: float) -> Registration:
        """Register one scan and advance the odometry.

        Args:
            points: (N, 2) scan points in the base frame; rows with NaN are ignored.
            stamp: Time of the scan (s); must increase from scan to scan.

        Returns:
            The registration. A rejected one still advances the pose, to the prediction,
            so that the odometry keeps going through a few bad scans.

        Raises:
            ValueError: If ``points`` is not of shape (N, 2).
        """
        config = self.config
        usable = _usable_points(points, config)
        if self._map is None:
            return self._start(usable, float(stamp))

        stamp = float(stamp)
        dt = stamp - self._stamp
        if dt <= 0:
            return self._reject(self._pose, stamp, "stamp not after the previous scan")
        periods = self._periods(dt)
        prediction = self._pose @ se2.matrix(self._step * periods)
        if len(usable) < config.min_points:
            return self._reject(prediction, stamp, f"only {len(usable)} valid points")

        fit = _align(self._map, usable, prediction, config)
        n_found = int(np.count_nonzero(fit.found))
        matched = n_found / len(usable)
        if n_found < config.min_points:
            return self._reject(prediction, stamp, f"only {n_found} points matched", matched, fit)
        step = se2.from_matrix(se2.invert_matrix(self._pose) @ fit.transform)
        reason = self._beyond_gate(step, dt)
        if reason:
            return self._reject(prediction, stamp, reason, matched, fit)
        return self._accept(usable, fit, step / periods, stamp, matched)

    def _periods(self, dt: float) -> int:
        """Whole scan periods in ``dt`` (at least one), and the smoothed period updated.

        Constant velocity per scan period, not per second: a lidar turns at a constant rate
        while its stamps jitter (+-10 % on hallway.bag), and the stamps' jitter made a worse
        map. Dropped scans are bridged by whole periods.
        """
        period = dt if math.isnan(self._period) else self._period
        periods = max(1, round(dt / period))
        self._period = period + self.config.period_smoothing * (dt / periods - period)
        return periods

    def _beyond_gate(self, step: Array, dt: float) -> str | None:
        """Why a step is faster than the robot can move in ``dt``, or None if it is not."""
        distance, turn = math.hypot(step[0], step[1]), abs(step[2])
        if distance > self.config.max_speed * dt or turn > self.config.max_turn_rate * dt:
            return (
                f"step of {distance:.2f} m and {math.degrees(turn):.1f} deg in {dt:.3f} s "
                "is beyond the gate"
            )
        return None

    def _accept(
        self, usable: Array, fit: _Fit, step: Array, stamp: float, matched: float
    ) -> Registration:
        """Move to the fit, keep its step per period, and make a keyframe if far enough."""
        config = self.config
        self._pose, self._step, self._stamp = fit.transform, step, stamp
        from_keyframe = se2.from_matrix(se2.invert_matrix(self._keyframe_pose) @ fit.transform)
        keyframe = (
            math.hypot(from_keyframe[0], from_keyframe[1]) > config.keyframe_distance
            or abs(from_keyframe[2]) > config.keyframe_angle
        )
        if keyframe:
            self._add_keyframe(usable)
        pose = se2.from_matrix(fit.transform)
        cov = config.point_sigma**2 * np.linalg.inv(fit.information)
        return Registration(
            _frozen(pose),
            _frozen(se2.rotate_covariance(cov, pose[2])),
            matched,
            fit.iterations,
            accepted=True,
            stamp=stamp,
            keyframe=keyframe,
        )

    def _start(self, usable: Array, stamp: float) -> Registration:
        """The first usable scan defines the odometry frame and the first keyframe."""
        if len(usable) < self.config.min_points:
            return Registration(
                _frozen(np.zeros(3)),
                _frozen(np.zeros((3, 3))),
                0.0,
                0,
                accepted=False,
                reason=f"only {len(usable)} valid points to start the map with",
                stamp=stamp,
            )
        self._stamp = stamp
        self._add_keyframe(usable)
        return Registration(
            _frozen(np.zeros(3)),
            _frozen(np.zeros((3, 3))),
            1.0,
            0,
            accepted=True,
            stamp=stamp,
            keyframe=True,
        )

    def _reject(
        self,
        prediction: Array,
        stamp: float,
        reason: str,
        matched: float = 0.0,
        fit: _Fit | None = None,
    ) -> Registration:
        """Dead-reckon on the prediction; the step per period stays, the map does not change."""
        config = self.config
        self._pose = prediction
        self._stamp = max(self._stamp, stamp)
        pose = se2.from_matrix(prediction)
        prior_cov = (
            config.point_sigma**2
            / max(config.prior_weight, _REGULARISER)
            * np.diag([1.0, 1.0, config.rotation_scale**-2])
        )
        return Registration(
            _frozen(pose),
            _frozen(se2.rotate_covariance(prior_cov, pose[2])),
            matched,
            0 if fit is None else fit.iterations,
            accepted=False,
            reason=reason,
            stamp=stamp,
        )

    def _add_keyframe(self, usable: Array) -> None:
        t = self._pose
        self._keyframes.append(usable @ t[:2, :2].T + t[:2, 2])
        self._keyframe_pose = t.copy()
        self._map = _LocalMap(np.vstack(self._keyframes), self.config)


def _frozen(a: Array) -> Array:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


def register_to_walls(
    points: np.ndarray,
    guess: ArrayLike,
    guess_cov: ArrayLike,
    walls: Sequence[WallLine],
    config: MatcherConfig = MatcherConfig(),
) -> tuple[np.ndarray, np.ndarray, int]:
    """Refine a pose against mapped walls, keeping the guess where the walls say nothing.

    Odometry drifts; the walls already in the map do not. Each scan point is matched to the
    nearest wall whose extent its projection falls in, and the pose (x, y, yaw) in the map frame
    minimises the Huber-weighted point-to-line distances (sigma ``config.point_sigma``) plus the
    guess as a Gaussian prior. A corridor's two walls then fix the offset across it and the yaw,
    while the position along it stays with the guess, as its covariance shows.

    Args:
        points: (N, 2) scan points in the base frame; rows with NaN are ignored.
        guess: (x, y, yaw) of the base frame in the map frame, e.g. from odometry.
        guess_cov: (3, 3) covariance of the guess; must be positive definite.
        walls: The walls near the pose (every point is compared with every wall).
        config: Correspondence cut-offs, robust weight, iterations and point sigma.

    Returns:
        The refined pose (3,), its covariance (3, 3) and the number of points matched to a wall
        in the last iteration (with none, the guess and its covariance come back).
    """
    usable = _usable_points(points, config)
    x0 = np.asarray(guess, dtype=float).reshape(3)
    prior = np.linalg.inv(np.asarray(guess_cov, dtype=float).reshape(3, 3))
    information = prior
    if not walls or len(usable) == 0:
        return x0.copy(), np.linalg.inv(information), 0

    lines = _WallArrays.of(walls)
    x = x0.copy()
    matched = 0
    for iteration in range(1, config.iterations + 1):
        rotated = se2.rotate_points(usable, x[2])
        reach = (
            config.max_distance
            if iteration <= config.coarse_iterations
            else config.fine_max_distance
        )
        distance, wall, found = lines.nearest(rotated + x[:2], reach)
        matched = int(np.count_nonzero(found))
        deviation = x - x0
        deviation[2] = se2.wrap(deviation[2])
        step, information = _wall_step(
            rotated[found], lines.normal[wall[found]], distance[found], deviation, prior, config
        )
        x += step
        if np.abs(step).max() < config.convergence:
            break
    x[2] = se2.wrap(x[2])
    return x, np.linalg.inv(information), matched


@dataclass(frozen=True)
class _WallArrays:
    """Walls as arrays, so that every scan point is compared with every wall at once.

    Attributes:
        normal: (W, 2) unit normals.
        offset: (W,) the lines' offsets along their normals.
        start: (W, 2) the first end of each wall.
        span: (W, 2) from the first end to the second.
        span2: (W,) the squared lengths.
    """

    normal: Array
    offset: Array
    start: Array
    span: Array
    span2: Array

    @classmethod
    def of(cls, walls: Sequence[WallLine]) -> _WallArrays:
        """The arrays of some walls, their normals made unit length."""
        normal = np.array([w.normal for w in walls], dtype=float).reshape(-1, 2)
        length = np.linalg.norm(normal, axis=1)
        normal /= length[:, None]
        offset = np.array([w.offset for w in walls], dtype=float) / length
        start = np.array([w.p0 for w in walls], dtype=float).reshape(-1, 2)
        span = np.array([w.p1 for w in walls], dtype=float).reshape(-1, 2) - start
        return cls(normal, offset, start, span, np.einsum("ij,ij->i", span, span))

    def nearest(self, moved: Array, reach: float) -> tuple[Array, Array, Array]:
        """Per map point (N, 2): the signed distance to its wall, the wall, and if it matched.

        A point's wall is the nearest one its projection falls within; it matches when that
        wall is nearer than ``reach``.
        """
        distance = moved @ self.normal.T - self.offset  # (N, W) signed point-to-line distances
        along = ((moved[:, None, :] - self.start[None]) * self.span[None]).sum(axis=-1) / self.span2
        candidate = np.where((along >= 0) & (along <= 1), np.abs(distance), np.inf)
        wall = candidate.argmin(axis=1)
        rows = np.arange(len(moved))
        return distance[rows, wall], wall, candidate[rows, wall] < reach


def _wall_step(
    rotated: Array,
    normal: Array,
    residual: Array,
    deviation: Array,
    prior: Array,
    config: MatcherConfig,
) -> tuple[Array, Array]:
    """One Gauss-Newton step of the matched points' distances plus the prior, and its information.

    Args:
        rotated: The matched scan points turned by the pose's yaw, ``R p`` (M, 2).
        normal: Their walls' unit normals (M, 2).
        residual: Their signed distances to their walls (M,).
        deviation: The pose minus the guess, heading wrapped (3,).
        prior: The guess's information (3, 3).
        config: The point sigma and the Huber threshold.
    """
    # d(n . (R p + t)) / d(x, y, yaw) = (n, n . perp(R p)) with perp(v) = (-v_y, v_x)
    jacobian = np.column_stack(
        [normal, normal[:, 1] * rotated[:, 0] - normal[:, 0] * rotated[:, 1]]
    )
    weight = 1.0 / config.point_sigma**2
    weighted = jacobian * (weight * _huber_weights(residual, config.huber))[:, None]
    information = weighted.T @ jacobian + prior
    step = -np.linalg.solve(information, weighted.T @ residual + prior @ deviation)
    return step, information
