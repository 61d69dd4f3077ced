"""Planar poses (SE(2)): the one home of the maths every part of the map shares.

A pose is ``(x, y, yaw)``: a position on the floor and a heading, counter-clockwise from the x
axis, in radians. It also names the frame it places: ``pose`` maps points of that frame into its
parent (``p_parent = R(yaw) p + (x, y)``). The same pose as a 3x3 homogeneous matrix is
:func:`matrix`; the vector form is what filters estimate, the matrix form chains frames.

Pure functions over numpy arrays, in scalars where the map calls them for every observation
(``math.cos`` on a float costs a fraction of ``np.cos``). :func:`rotate` and :func:`unrotate` also
take whole trajectories, column-wise. The planar model's own hot loops (``common.wall_model``)
keep their rotations inline in floats and follow the same conventions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]
PoseLike = Sequence[float] | Array
Angle = TypeVar("Angle", float, Array)


def wrap(angle: Angle) -> Angle:
    """An angle, or each of an array of angles, in [-pi, pi).

    Headings are compared and filtered as differences; unwrapped, a turn of 359 degrees would
    read as a large error instead of a small one.
    """
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def rotation(yaw: float) -> Array:
    """The 2x2 matrix turning vectors by ``yaw`` radians."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def rotate(vector: ArrayLike, yaw: float | Array) -> Array:
    """``R(yaw) v`` for one vector (2,), or column-wise for components (2, N) and yaws (N,).

    Column-wise, it turns a whole trajectory's body-frame steps into the map frame at once.
    """
    v = np.asarray(vector, dtype=float)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def unrotate(vector: ArrayLike, yaw: float | Array) -> Array:
    """``R(yaw)^T v``, the inverse of :func:`rotate`: a map-frame vector in the turned frame."""
    v = np.asarray(vector, dtype=float)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1]])


def rotate_points(points: Array, yaw: float) -> Array:
    """Points (N x 2, one per row) turned by ``yaw``: ``R p`` for every row."""
    c, s = math.cos(yaw), math.sin(yaw)
    return points @ np.array([[c, s], [-s, c]])


def transform_points(points: ArrayLike, pose: PoseLike) -> Array:
    """Points (N x 2) of the frame ``pose`` places, in its parent frame: ``R p + t`` per row.

    How a scan, or an observed segment's ends, in the robot's frame land on the map.
    """
    x, y, yaw = pose
    return rotate_points(np.asarray(points, dtype=float), yaw) + np.array([x, y])


def rotate_covariance(cov: Array, yaw: float) -> Array:
    """A covariance of (x, y, yaw) expressed in a frame turned by ``yaw``: ``A cov A^T``.

    The heading's variance is the same in every frame; only the position block turns.
    """
    a = np.eye(3)
    a[:2, :2] = rotation(yaw)
    return a @ cov @ a.T


def matrix(pose: PoseLike) -> Array:
    """The 3x3 homogeneous matrix of a pose, for chaining frames by matrix products."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def from_matrix(t: Array) -> Array:
    """The pose (x, y, yaw) of a 3x3 homogeneous matrix; yaw in (-pi, pi]."""
    return np.array([t[0, 2], t[1, 2], math.atan2(t[1, 0], t[0, 0])])


def invert_matrix(t: Array) -> Array:
    """The inverse of a 3x3 rigid transform, by transposing its rotation (no general inverse)."""
    r = t[:2, :2]
    out = np.eye(3)
    out[:2, :2] = r.T
    out[:2, 2] = -r.T @ t[:2, 2]
    return out


def compose(a: Array, b: Array) -> Array:
    """Pose ``a`` followed by motion ``b`` in ``a``'s frame: a * b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap(a[2] + b[2])])


def between(a: Array, b: Array) -> Array:
    """The motion from pose ``a`` to pose ``b``, in ``a``'s frame: a^-1 * b.

    Odometry is used this way: only its steps are trusted, never where it thinks it is.
    """
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2])])


def inverse(a: Array) -> Array:
    """Where the parent frame's origin lies, seen from ``a``: a^-1, so a * a^-1 = 0.

    The pose the map -> odom correction composes with: the corrected pose after the odometry's.
    """
    return between(a, np.zeros(3))


def inverse_jacobian(a: Array) -> Array:
    """The Jacobian of :func:`inverse` with respect to ``a``, 3x3.

    A frame placed with some uncertainty places its parent's origin with the uncertainty
    this carries over (a robot's map frame in a fleet's, seen the other way round).
    """
    c, s = math.cos(a[2]), math.sin(a[2])
    x, y = float(a[0]), float(a[1])
    return np.array([[-c, -s, s * x - c * y], [s, -c, c * x + s * y], [0.0, 0.0, -1.0]])


def compose_jacobians(a: Array, b: Array) -> tuple[Array, Array]:
    """The Jacobians of ``compose(a, b)`` with respect to ``a`` and to ``b``, 3x3 each.

    An EKF moves a pose's covariance through a motion with them.
    """
    c, s = math.cos(a[2]), math.sin(a[2])
    ja = np.array(
        [[1.0, 0.0, -s * b[0] - c * b[1]], [0.0, 1.0, c * b[0] - s * b[1]], [0.0, 0.0, 1.0]]
    )
    jb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return ja, jb
