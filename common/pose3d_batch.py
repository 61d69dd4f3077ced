"""The rigid transforms of ``pose3d`` over arrays of them at once: a stream of poses, ahead.

A player sends its pose source's poses on a 50 Hz grid, three for each frame of a 15 Hz camera;
one at a time, through the scalar helpers, they cost a quarter of its work on each frame. The same
formulas over a second of the grid at once cost a few microseconds a pose. Each function here
agrees with its scalar twin in ``pose3d`` to rounding (tested side by side).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from wallmap.common.pose3d import FORWARD_X

Array = NDArray[np.float64]


def rotation_matrices(quaternions: Array) -> Array:
    """The (n, 3, 3) rotations of (n, 4) unit quaternions (x, y, z, w): ``rotation_matrix``."""
    x, y, z, w = (quaternions[:, i] for i in range(4))
    out = np.empty((len(quaternions), 3, 3))
    out[:, 0, 0] = 1 - 2 * (y * y + z * z)
    out[:, 0, 1] = 2 * (x * y - z * w)
    out[:, 0, 2] = 2 * (x * z + y * w)
    out[:, 1, 0] = 2 * (x * y + z * w)
    out[:, 1, 1] = 1 - 2 * (x * x + z * z)
    out[:, 1, 2] = 2 * (y * z - x * w)
    out[:, 2, 0] = 2 * (x * z - y * w)
    out[:, 2, 1] = 2 * (y * z + x * w)
    out[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def transform_matrices(translations: Array, quaternions: Array) -> Array:
    """The (n, 4, 4) transforms of (n, 3) translations and (n, 4) quaternions."""
    out = np.zeros((len(translations), 4, 4))
    out[:, :3, :3] = rotation_matrices(quaternions)
    out[:, :3, 3] = translations
    out[:, 3, 3] = 1.0
    return out


def slerp_many(q0: Array, q1: Array, weights: Array) -> Array:
    """``slerp`` of each row pair of (n, 4) quaternions by its weight: the shorter arc."""
    dot = np.einsum("ij,ij->i", q0, q1)
    q1 = np.where((dot < 0.0)[:, None], -q1, q1)
    dot = np.abs(dot)
    near = dot > 0.9995  # nearly parallel: a normalised lerp, as the scalar one does
    theta = np.arccos(np.where(near, 0.5, dot))
    sin_theta = np.sin(theta)
    w0 = np.where(near, 1.0 - weights, np.sin((1.0 - weights) * theta) / sin_theta)
    w1 = np.where(near, weights, np.sin(weights * theta) / sin_theta)
    mixed = w0[:, None] * q0 + w1[:, None] * q1
    return mixed / np.sqrt(np.einsum("ij,ij->i", mixed, mixed))[:, None]


def invert_many(matrices: Array) -> Array:
    """The inverses of (n, 4, 4) rigid transforms: ``invert``."""
    out = np.zeros_like(matrices)
    rotation_t = np.swapaxes(matrices[:, :3, :3], 1, 2)
    out[:, :3, :3] = rotation_t
    out[:, :3, 3] = -np.einsum("nij,nj->ni", rotation_t, matrices[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def headings(rotations: Array, forward: int = FORWARD_X) -> Array:
    """The heading of each of (n, 3, 3) rotations' forward axis on the floor: ``heading``."""
    ahead = rotations[:, :, forward]
    side, turn = (1, -math.pi / 2) if forward == FORWARD_X else (0, math.pi / 2)
    across = rotations[:, :, side]
    looking = np.hypot(ahead[:, 0], ahead[:, 1]) > 0.2
    y = np.where(looking, ahead[:, 1], across[:, 1]).tolist()
    x = np.where(looking, ahead[:, 0], across[:, 0]).tolist()
    # math.atan2, as ``heading`` takes it: numpy's vectorized arctan2 may differ from it in the
    # last bit (numpy 2.4's does), and a pose must be the same whichever way it was levelled.
    angles = np.array(list(map(math.atan2, y, x)), dtype=np.float64)
    return np.where(looking, angles, angles + turn)
