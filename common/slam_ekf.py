"""Wall-landmark EKF-SLAM: the robot's pose and a window of walls in one Gaussian.

The state is ``[x, y, yaw, k, b, s_1, s_2, ...]``: the planar pose, the odometry's calibration
(its scale error ``k`` and its heading bias ``b`` per metre driven), then each wall of the window
as its anchored closest point (``common.wall_model``), with one full covariance. Keeping the
cross-covariances is what lets a correction travel: a wall started from a pose that had drifted
carries that pose's error, and when a wall seen earlier pulls the pose back, the new wall moves
with it. A pose and walls filtered apart (each wall its own EKF, the pose its own) cannot do that,
and through a stretch of new walls the heading then drifts for good.

The window is bounded (the caller decides which walls it holds), so every operation costs
O(n^2) in the window's size, whatever the size of the map. A wall leaves the window with its
marginal (its 2x2 block, which the per-wall map keeps) and comes back uncorrelated.

Wheel odometry errs mostly by calibration: a wheel a little smaller than the other turns every
metre by the same fraction of a degree, worn tyres shorten every metre by the same share. Errors
like these are not noise: through a stretch with nothing but new walls to see, a heading bias
of 1 degree per metre leaves the map metres off. Estimated with the rest (the walls see it), it
is taken off every step before it can accumulate.

Pure functions over numpy arrays: ``x`` is the state vector, ``p`` its covariance; wall ``i``
is ``x[5 + 2 i : 7 + 2 i]``. The Jacobians are those of ``common.wall_model`` and
``common.se2``, each tested against numeric differentiation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wallmap.common import ekf, se2, wall_model
from wallmap.common.se2 import Array

POSE = 3  # state entries of the pose
ROBOT = 5  # ...and of the odometry's calibration after it


@dataclass(frozen=True)
class OdometryNoise:
    """How uncertain a step of odometry is: standard deviations that grow with the motion.

    Odometry enters as relative motion, ``step = se2.between(odom_prev, odom)``: where it
    thinks the robot is drifts without bound, its steps do not. The calibration in the state
    takes the systematic part of a step's error off; this is what is left, random per step.

    Attributes:
        per_metre: Position error per metre driven (0.05 = 5 %: a wheel's scale error and slip).
        turn_per_radian: Heading error per radian turned.
        turn_per_metre: Heading error per metre driven (rad/m: a yaw bias).
        floor_xy: Position noise every step (m), so a robot standing still is never certain.
        floor_yaw: Heading noise every step (rad).
    """

    per_metre: float = 0.05
    turn_per_radian: float = 0.05
    turn_per_metre: float = math.radians(3.0)
    floor_xy: float = 0.002
    floor_yaw: float = math.radians(0.05)

    def covariance(self, step: Array) -> Array:
        """The covariance of one odometry step (x, y, yaw in the robot's frame)."""
        distance = math.hypot(step[0], step[1])
        sigma_xy = self.per_metre * distance + self.floor_xy
        sigma_yaw = (
            self.turn_per_radian * abs(step[2]) + self.turn_per_metre * distance + self.floor_yaw
        )
        return np.diag([sigma_xy**2, sigma_xy**2, sigma_yaw**2])


def wall_slice(slot: int) -> slice:
    """Where wall ``slot`` lies in the state vector."""
    return slice(ROBOT + 2 * slot, ROBOT + 2 * slot + 2)


def start(pose: Array, pose_cov: Array, calibration_sd: tuple[float, float]) -> tuple[Array, Array]:
    """The state before any wall: ``pose`` with its covariance, the calibration not yet known."""
    p = np.zeros((ROBOT, ROBOT))
    p[:POSE, :POSE] = pose_cov
    p[POSE:, POSE:] = np.diag(np.square(calibration_sd))
    return np.concatenate([pose, [0.0, 0.0]]), p


def calibrated(step: Array, calibration: Array) -> Array:
    """An odometry ``step`` with its scale error ``k`` and heading bias ``b`` taken off."""
    k, b = float(calibration[0]), float(calibration[1])
    distance = math.hypot(float(step[0]), float(step[1]))
    return np.array([step[0] * (1.0 + k), step[1] * (1.0 + k), step[2] - b * distance])


def calibrated_jacobian(step: Array) -> Array:
    """The Jacobian of :func:`calibrated` with respect to (k, b), 3x2."""
    distance = math.hypot(float(step[0]), float(step[1]))
    return np.array([[step[0], 0.0], [step[1], 0.0], [0.0, -distance]])


def predict(
    x: Array, p: Array, step: Array, noise: OdometryNoise, drift: tuple[float, float]
) -> tuple[Array, Array]:
    """Move the pose by an odometry ``step``, calibrated; the walls stay.

    ``drift``: how far (standard deviation per metre driven) the scale error and the heading
    bias may change, so that a calibration that varies with the floor is followed.
    """
    motion = calibrated(step, x[POSE:ROBOT])
    ja, jb = se2.compose_jacobians(x[:POSE], motion)
    f = np.eye(ROBOT)
    f[:POSE, :POSE] = ja
    f[:POSE, POSE:] = jb @ calibrated_jacobian(step)
    x_new = x.copy()
    x_new[:POSE] = se2.compose(x[:POSE], motion)
    p_new = p.copy()
    p_new[:ROBOT, :] = f @ p[:ROBOT, :]
    p_new[:, :ROBOT] = p_new[:, :ROBOT] @ f.T
    p_new[:POSE, :POSE] += jb @ noise.covariance(motion) @ jb.T
    distance = math.hypot(float(step[0]), float(step[1]))
    p_new[POSE:ROBOT, POSE:ROBOT] += np.diag(np.square(drift)) * distance
    return x_new, 0.5 * (p_new + p_new.T)


@dataclass(frozen=True)
class JointInnovation:
    """An observation of wall ``slot`` compared with the joint state's prediction.

    Attributes:
        slot: the wall's place in the window.
        residual: observation minus prediction (2,).
        cov: innovation covariance S = H P H^T + R over pose and wall, correlations included.
        jacobian: d prediction / d (pose, wall), 2x5.
        mahalanobis2: squared Mahalanobis distance of the residual under S.
        log_likelihood: Gaussian log-density of the residual under S.
    """

    slot: int
    residual: Array
    cov: Array
    jacobian: Array
    mahalanobis2: float
    log_likelihood: float


def _columns(slot: int) -> Array:
    first = ROBOT + 2 * slot
    return np.array([0, 1, 2, first, first + 1])


def innovation(x: Array, p: Array, slot: int, anchor: Array, z: Array, r: Array) -> JointInnovation:
    """Compare observation ``z`` (covariance ``r``) with wall ``slot`` seen from the pose."""
    pose, s = x[:POSE], x[wall_slice(slot)]
    h = np.hstack(
        [wall_model.jacobian_pose(s, anchor, pose), wall_model.jacobian_state(s, anchor, pose)]
    )
    cols = _columns(slot)
    cov = h @ p[np.ix_(cols, cols)] @ h.T + r
    residual = z - wall_model.predict(s, anchor, pose)
    inverse, det = ekf.inverse_and_det(cov)
    m2 = float(residual @ inverse @ residual)
    return JointInnovation(
        slot, residual, cov, h, m2, -0.5 * (m2 + math.log(det)) - math.log(2.0 * math.pi)
    )


def update(x: Array, p: Array, innov: JointInnovation) -> tuple[Array, Array]:
    """The EKF update of the whole state with one observation of one wall.

    ``P H^T`` touches five columns only, so the update costs O(n^2) for n state entries.
    """
    cols = _columns(innov.slot)
    pht = p[:, cols] @ innov.jacobian.T
    gain = pht @ ekf.inverse_and_det(innov.cov)[0]
    x_new = x + gain @ innov.residual
    x_new[2] = se2.wrap(float(x_new[2]))
    p_new = p - gain @ pht.T
    return x_new, 0.5 * (p_new + p_new.T)


def update_wall_only(x: Array, p: Array, innov: JointInnovation) -> tuple[Array, Array]:
    """The update of wall ``innov.slot`` alone, the rest of the state considered, not estimated.

    A Schmidt (consider) update: the pose, the calibration and the other walls keep their
    estimates, while every covariance, their correlations with this wall included, is the
    exact one of the suboptimal gain (Joseph form). For walls too young to steer the pose: a
    wall started from a few short pieces is less sure of its direction than its fits say, and
    would turn the robot to agree with it.
    """
    cols = _columns(innov.slot)
    wall = cols[POSE:]
    pht = p[:, cols] @ innov.jacobian.T
    gain = np.zeros_like(pht)
    gain[wall] = pht[wall] @ ekf.inverse_and_det(innov.cov)[0]
    x_new = x + gain @ innov.residual
    hp = pht.T  # H P, 2 x n
    # (I - K H) P (I - K H)^T + K R K^T, with H P H^T + R = S:
    p_new = p - gain @ hp - hp.T @ gain.T + gain @ innov.cov @ gain.T
    return x_new, 0.5 * (p_new + p_new.T)


def augment(x: Array, p: Array, z: Array, r: Array) -> tuple[Array, Array, Array]:
    """Add a wall first seen as ``z`` (covariance ``r``) from the state's pose.

    Its covariance and its correlations with the pose and every wall of the window come from
    the Jacobians of ``wall_model.from_observation``. Returns ``(x, p, anchor)``.
    """
    s, anchor, ds_dz, ds_dpose = wall_model.from_observation(z, x[:POSE])
    n = len(x)
    cross = ds_dpose @ p[:POSE, :]  # the new wall against everything before it, 2 x n
    p_new = np.zeros((n + 2, n + 2))
    p_new[:n, :n] = p
    p_new[n:, :n] = cross
    p_new[:n, n:] = cross.T
    p_new[n:, n:] = ds_dpose @ p[:POSE, :POSE] @ ds_dpose.T + ds_dz @ r @ ds_dz.T
    return np.concatenate([x, s]), 0.5 * (p_new + p_new.T), anchor


def insert(x: Array, p: Array, s: Array, p_wall: Array) -> tuple[Array, Array]:
    """Bring a wall back into the window with its marginal, uncorrelated with the rest."""
    n = len(x)
    p_new = np.zeros((n + 2, n + 2))
    p_new[:n, :n] = p
    p_new[n:, n:] = p_wall
    return np.concatenate([x, s]), p_new


def remove(x: Array, p: Array, slots: list[int]) -> tuple[Array, Array]:
    """Marginalise walls out of the state: for a Gaussian, drop their rows and columns."""
    drop = [i for slot in slots for i in range(ROBOT + 2 * slot, ROBOT + 2 * slot + 2)]
    keep = np.setdiff1d(np.arange(len(x)), drop)
    return x[keep], p[np.ix_(keep, keep)]
