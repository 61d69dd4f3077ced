"""The robot's planar pose as an EKF: odometry moves it, walls seen again pull it back.

Wall-landmark SLAM, in the form the map already has: every wall keeps its own small EKF over its
line (``common.ekf``), and the pose (x, y, yaw) gets one of its own. Odometry is taken as relative
motion, ``delta = odom_prev^-1 * odom``, composed onto the estimate with noise that grows with the
distance and the turn; each wall observation associated with a mapped wall is a measurement of the
pose through the corrected line model (``common.wall_model``), with the wall's own uncertainty in
its innovation covariance. Cross-correlations between the pose and the walls are not kept (a
decoupled EKF): that keeps every update O(1) per wall, at the price of some overconfidence, which
the association gate and the odometry noise floor absorb.

All functions are pure over numpy arrays: a pose is (x, y, yaw), a covariance 3x3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

_EYE3 = np.eye(3)


def wrap(angle: float) -> float:
    """An angle in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def compose(a: Array, b: Array) -> Array:
    """Pose ``a`` followed by motion ``b`` in ``a``'s frame: a * b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap(a[2] + b[2])])


def between(a: Array, b: Array) -> Array:
    """The motion from pose ``a`` to pose ``b``, in ``a``'s frame: a^-1 * b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2])])


def compose_jacobians(a: Array, b: Array) -> tuple[Array, Array]:
    """The Jacobians of compose(a, b) with respect to a and to b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    ja = np.array(
        [[1.0, 0.0, -s * b[0] - c * b[1]], [0.0, 1.0, c * b[0] - s * b[1]], [0.0, 0.0, 1.0]]
    )
    jb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return ja, jb


@dataclass(frozen=True)
class OdometryNoise:
    """How uncertain a step of odometry is: standard deviations that grow with the motion.

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


def predict(x: Array, p: Array, step: Array, noise: OdometryNoise) -> tuple[Array, Array]:
    """The pose after an odometry ``step``, and its grown covariance."""
    ja, jb = compose_jacobians(x, step)
    p_new = ja @ p @ ja.T + jb @ noise.covariance(step) @ jb.T
    return compose(x, step), 0.5 * (p_new + p_new.T)


def correct(
    x: Array, p: Array, residual: Array, cov: Array, jacobian: Array
) -> tuple[Array, Array]:
    """EKF update of the pose with one wall observation (Joseph form).

    ``residual`` and ``cov`` are the observation's innovation and its covariance S (pose, wall
    and observation: ``common.ekf.innovation``); ``jacobian`` is d predicted / d pose, 2x3
    (``wall_model.jacobian_pose``).
    """
    gain = p @ jacobian.T @ np.linalg.inv(cov)
    x_new = x + gain @ residual
    x_new[2] = wrap(float(x_new[2]))
    i_kh = _EYE3 - gain @ jacobian
    r_eff = cov - jacobian @ p @ jacobian.T  # the wall's and the observation's part of S
    p_new = i_kh @ p @ i_kh.T + gain @ r_eff @ gain.T
    return x_new, 0.5 * (p_new + p_new.T)
