"""The measurement model of a wall seen from a robot pose, and its Jacobians.

A wall is an infinite 2-D line. The paper parameterises it by its closest point (u, v) to the
origin and, in its equations 1-3, predicts what the robot sees by moving (u, v) into the robot
frame as if it were a *point*: ``R(yaw)^T ((u, v) - t)``. That is wrong for a line: when the robot
translates along the wall, the closest point of the wall *to the robot* slides with it, while the
transformed point does not. A filter built on the point model sees a large innovation after every
metre driven along a wall and starts a new wall each time.

The right model. Let the line be ``{p : n . p = rho}`` with unit normal ``n``. Seen from a robot at
``t`` with heading ``yaw``, its closest point is the foot of the perpendicular from ``t``::

    z = R(yaw)^T (rho - n . t) n

Every function here works with the line stored as its closest point ``s`` to an *anchor* ``a``
(the robot position when the wall was first seen), not to the map origin. The closest point to
the map origin is singular for a line through the origin (its direction is lost when (u, v) = 0);
the anchor is never on the wall because a sensor cannot see a wall it stands in. With
``d = t - a`` and ``k = 1 - (s . d) / |s|^2`` the model is ``z = k R^T s``.

All functions are pure and take plain numpy arrays: ``s``, ``anchor`` and ``z`` are shape (2,),
``pose`` is (x, y, yaw).
"""

from __future__ import annotations

import math

import numpy as np

from wallmap.common.se2 import Array, rotation

_PERP = np.array([[0.0, -1.0], [1.0, 0.0]])  # rotates a vector by +90 degrees


def _terms(
    s: Array, anchor: Array, pose: Array
) -> tuple[float, float, float, float, float, float, float]:
    """Scalars shared by the model and its Jacobians: k, |s|^2, s.d, cos, sin, and R^T s.

    Written out in scalars (``R^T s`` as in ``common.se2``, inline): these run for every
    candidate wall of every observation, where numpy's per-call cost on 2-vectors would dominate.
    """
    sx, sy = float(s[0]), float(s[1])
    dx, dy = float(pose[0]) - float(anchor[0]), float(pose[1]) - float(anchor[1])
    rho2 = sx * sx + sy * sy
    sd = sx * dx + sy * dy
    c, n = math.cos(float(pose[2])), math.sin(float(pose[2]))
    return 1.0 - sd / rho2, rho2, sd, c, n, c * sx + n * sy, -n * sx + c * sy


def predict(s: Array, anchor: Array, pose: Array) -> Array:
    """Closest point of the wall to the robot, in the robot frame (the detector's (u, v))."""
    k, _, _, _, _, a, b = _terms(s, anchor, pose)
    return np.array([k * a, k * b])


def jacobian_state(s: Array, anchor: Array, pose: Array) -> Array:
    """Jacobian of :func:`predict` with respect to the state ``s``, 2x2.

    ``R^T (k I + s grad_k^T)`` with ``grad_k = -d/|s|^2 + 2 (s.d) s/|s|^4``.
    """
    k, rho2, sd, c, n, _, _ = _terms(s, anchor, pose)
    sx, sy = float(s[0]), float(s[1])
    dx, dy = float(pose[0]) - float(anchor[0]), float(pose[1]) - float(anchor[1])
    gx = -dx / rho2 + 2.0 * sd * sx / (rho2 * rho2)
    gy = -dy / rho2 + 2.0 * sd * sy / (rho2 * rho2)
    m00, m01, m10, m11 = k + sx * gx, sx * gy, sy * gx, k + sy * gy
    return np.array(
        [[c * m00 + n * m10, c * m01 + n * m11], [-n * m00 + c * m10, -n * m01 + c * m11]]
    )


def jacobian_pose(s: Array, anchor: Array, pose: Array) -> Array:
    """Jacobian of :func:`predict` with respect to the pose (x, y, yaw), 2x3.

    It says how pose error moves the observation, so pose uncertainty can enter the gate:
    ``-R^T s s^T / |s|^2`` for the translation, ``k (-PERP) R^T s`` for the heading.
    """
    k, rho2, _, _, _, a, b = _terms(s, anchor, pose)
    sx, sy = float(s[0]), float(s[1])
    return np.array(
        [[-a * sx / rho2, -a * sy / rho2, k * b], [-b * sx / rho2, -b * sy / rho2, -k * a]]
    )


def from_observation(z: Array, pose: Array) -> tuple[Array, Array, Array, Array]:
    """Start a wall from one observation: the inverse of :func:`predict`.

    The anchor is the robot position, so the state is the observation rotated into the map.

    Returns:
        ``(s, anchor, ds_dz, ds_dpose)``: the state, its anchor and the Jacobians of the state with
        respect to the observation (2x2) and to the pose (2x3), to build its first covariance.
    """
    r = rotation(pose[2])
    s = r @ z
    anchor = np.array(pose[:2], dtype=float)
    n = s / np.linalg.norm(s)
    ds_dpose = np.column_stack([np.outer(n, n), _PERP @ s])
    return s, anchor, r, ds_dpose


def to_map_frame(s: Array, anchor: Array) -> tuple[Array, Array]:
    """The wall's closest point to the map origin, (u, v), and d(u, v)/d s.

    This is the paper's parameterisation, served to users; near a line through the origin the
    Jacobian (and so the reported covariance) grows without bound, as that parameterisation does.
    """
    rho = np.linalg.norm(s)
    n = s / rho
    offset = n @ anchor + rho
    proj = (np.eye(2) - np.outer(n, n)) / rho  # d n / d s
    jac = np.outer(n, anchor @ proj + n) + offset * proj
    return offset * n, jac


def direction(s: Array) -> Array:
    """Unit vector along the wall (the normal turned by +90 degrees)."""
    return _PERP @ (s / np.linalg.norm(s))


def foot(s: Array, anchor: Array) -> Array:
    """The wall's closest point to its anchor, in the map frame: the origin of its extent axis."""
    return anchor + s


def _terms_many(s: Array, anchor: Array, pose: Array) -> tuple[Array, ...]:
    """:func:`_terms` for n walls at once (``s`` and ``anchor`` (n, 2)), as arrays."""
    d = np.asarray(pose[:2], dtype=float) - anchor
    rho2 = np.einsum("ij,ij->i", s, s)
    sd = np.einsum("ij,ij->i", s, d)
    c, n = math.cos(float(pose[2])), math.sin(float(pose[2]))
    a = c * s[:, 0] + n * s[:, 1]
    b = -n * s[:, 0] + c * s[:, 1]
    return 1.0 - sd / rho2, rho2, sd, d, a, b


def predict_many(s: Array, anchor: Array, pose: Array) -> Array:
    """:func:`predict` for n walls seen from one pose: (n, 2).

    A frame's pose is fitted to all the walls it saw at once (``common.pose_fit``): one numpy
    call for the frame instead of one Python call per wall.
    """
    k, _, _, _, a, b = _terms_many(s, anchor, pose)
    return np.column_stack([k * a, k * b])


def jacobian_pose_many(s: Array, anchor: Array, pose: Array) -> Array:
    """:func:`jacobian_pose` for n walls seen from one pose: (n, 2, 3)."""
    return _jacobian_pose_from(s, *_terms_many(s, anchor, pose))


def _jacobian_pose_from(
    s: Array, k: Array, rho2: Array, sd: Array, d: Array, a: Array, b: Array
) -> Array:
    out = np.empty((len(s), 2, 3))
    out[:, 0, 0] = -a * s[:, 0] / rho2
    out[:, 0, 1] = -a * s[:, 1] / rho2
    out[:, 0, 2] = k * b
    out[:, 1, 0] = -b * s[:, 0] / rho2
    out[:, 1, 1] = -b * s[:, 1] / rho2
    out[:, 1, 2] = -k * a
    return out
