"""Planar poses and odometry: composition, its Jacobians, and how uncertain a step is.

Odometry is taken as relative motion, ``step = odom_prev^-1 * odom``, composed onto a pose
estimate (``common.slam_ekf``) with noise that grows with the distance and the turn.

All functions are pure over numpy arrays: a pose is (x, y, yaw), a covariance 3x3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


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
