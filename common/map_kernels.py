"""The wall map's per-frame algebra, compiled (numba): the EKF update, the see-through test.

``WallMap.match`` scores an observation against every wall near it, on the innovation
covariance ``S = H P H^T + R + J Q J^T`` (``ekf.innovation``; compiled, the pose judge's
``pose_kernels.best_pairs``), and the most likely wall within the gate takes the EKF update
(``ekf.update``, Joseph form). In numpy each candidate's score and each update were some
thirty calls on 2x2 arrays: a tenth of the mapper's time a frame. Here the update is one pass,
with the wall model as ``pose_kernels.linearized`` writes it out (the model of
``common.wall_model``, whose Jacobians are tested against numeric differentiation). So is the
see-through test (``WallMap._see_through``): each of a frame's rays against each wall's line
near them, some forty small numpy calls a frame before. ``tests/unit/common/test_map_kernels.py``
holds these to the numpy they stand for.

Compiled once per machine and cached, as ``pose_kernels`` is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from wallmap.common.pose_kernels import _mm, _mv, linearized

Array = NDArray[np.float64]


@njit(cache=True, nogil=True)
def update(
    s: Array, p: Array, anchor: Array, z: Array, r: Array, pose: Array, pose_cov: Array
) -> tuple[Array, Array]:
    """One wall's EKF update by observation ``z`` from ``pose``: its new state and covariance.

    Joseph form, ``(I - K H) P (I - K H)^T + K (R + J Q J^T) K^T``, symmetrised, which keeps
    ``P`` positive for the tiny covariances of walls seen thousands of times.
    """
    predicted, by_state, by_pose = linearized(s.reshape(1, 2), anchor.reshape(1, 2), pose)
    h, j = by_state[0], by_pose[0]
    noise = r + _mm(_mm(j, pose_cov), j.T.copy())
    cov = _mm(_mm(h, p), h.T.copy()) + noise
    det = cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0]
    inverse = np.array([[cov[1, 1], -cov[0, 1]], [-cov[1, 0], cov[0, 0]]]) / det
    gain = _mm(_mm(p, h.T.copy()), inverse)
    s_new = s + _mv(gain, z - predicted[0])
    i_kh = np.eye(2) - _mm(gain, h)
    p_new = _mm(_mm(i_kh, p), i_kh.T.copy()) + _mm(_mm(gain, noise), gain.T.copy())
    return s_new, 0.5 * (p_new + p_new.T)


@njit(cache=True, nogil=True)
def rays_in_map(
    origin: Array, ends: Array, pose: Array, margin: float, noise: float
) -> tuple[Array, Array, Array, Array, Array]:
    """A frame's rays in the map: their start (2,), vectors (n, 2), lengths, limits and box.

    ``origin`` and ``ends`` are in the robot's frame. A ray's limit is where a wall's line must
    be crossed, at the latest, for the ray to have passed through it: its length less
    ``margin`` and its range noise, ``noise`` times the length squared. The box (low corner,
    high corner) holds the start and every end.
    """
    c, q = math.cos(pose[2]), math.sin(pose[2])
    sx = pose[0] + c * origin[0] - q * origin[1]
    sy = pose[1] + q * origin[0] + c * origin[1]
    n = len(ends)
    rays, length, limit = np.empty((n, 2)), np.empty(n), np.empty(n)
    box = np.array([[sx, sy], [sx, sy]])
    for i in range(n):
        ex = pose[0] + c * ends[i, 0] - q * ends[i, 1]
        ey = pose[1] + q * ends[i, 0] + c * ends[i, 1]
        box[0, 0], box[0, 1] = min(box[0, 0], ex), min(box[0, 1], ey)
        box[1, 0], box[1, 1] = max(box[1, 0], ex), max(box[1, 1], ey)
        rays[i, 0], rays[i, 1] = ex - sx, ey - sy
        length[i] = math.sqrt(rays[i, 0] ** 2 + rays[i, 1] ** 2)
        limit[i] = length[i] - (margin + noise * length[i] ** 2)
    return np.array([sx, sy]), rays, length, limit, box


@njit(cache=True, nogil=True)
def crossings(
    start: Array,
    rays: Array,
    length: Array,
    limit: Array,
    normals: Array,
    feet: Array,
    near: float,
) -> tuple[NDArray[np.intp], Array]:
    """Where rays crossed walls' lines, farther than ``near`` and before their limits.

    Each wall is a line (its unit normal, a point on it). Returns the wall of each crossing
    (its index) and the point where the ray crossed it, wall by wall, ray by ray. A ray along
    a line never crosses it.
    """
    which = np.empty(len(normals) * len(rays), dtype=np.intp)
    points = np.empty((len(which), 2))
    m = 0
    for j in range(len(normals)):
        nx, ny = normals[j, 0], normals[j, 1]
        offset = nx * (feet[j, 0] - start[0]) + ny * (feet[j, 1] - start[1])
        for i in range(len(rays)):
            towards = rays[i, 0] * nx + rays[i, 1] * ny
            if towards == 0.0:
                continue
            share = offset / towards  # where along the ray
            if near < share * length[i] < limit[i]:
                which[m] = j
                points[m, 0] = start[0] + share * rays[i, 0]
                points[m, 1] = start[1] + share * rays[i, 1]
                m += 1
    return which[:m].copy(), points[:m].copy()


def warm_up() -> None:
    """Compile (or load from the cache) every kernel now, not on the first frame."""
    s, p, anchor = np.array([[1.0, 0.2]]), np.array([np.eye(2) * 1e-4]), np.zeros((1, 2))
    z, r = np.array([1.0, 0.25]), np.eye(2) * 1e-3
    pose, pose_cov = np.array([0.1, 0.0, 0.05]), np.eye(3) * 1e-4
    update(s[0], p[0], anchor[0], z, r, pose, pose_cov)
    start, rays, length, limit, _ = rays_in_map(np.zeros(2), np.ones((2, 2)), pose, 0.1, 3e-3)
    crossings(start, rays, length, limit, np.array([[1.0, 0.0]]), np.array([[0.5, 0.0]]), 0.3)
