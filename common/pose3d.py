"""Rigid transforms in 3-D, and the split of a 6-DoF pose into the plane the map lives in.

A handheld camera, a legged robot or a SLAM system gives the sensor's pose with all six degrees
of freedom. The map is planar: it needs the sensor's position on the floor and its heading, and
nothing else. The rest (height, roll and pitch) belongs with the frame's own geometry: it says at
what height each point of that frame lies. ``split_planar`` cuts a pose exactly into the two, so
that ``planar(x, y, yaw) @ tilt`` is the pose again.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from wallmap.common import se2

Array = NDArray[np.float64]
Quaternion = tuple[float, float, float, float]
Vector3 = tuple[float, float, float]

# The axis a frame looks along: x for REP-103 body frames, z for camera optical frames.
FORWARD_X, FORWARD_Z = 0, 2


def transform_matrix(translation: Vector3, quaternion: Quaternion) -> Array:
    """The 4x4 homogeneous transform of a translation and a unit quaternion (x, y, z, w)."""
    out = np.eye(4)
    out[:3, :3] = rotation_matrix(quaternion)
    out[:3, 3] = translation
    return out


def rotation_matrix(quaternion: Quaternion) -> Array:
    """The 3x3 rotation of a unit quaternion (x, y, z, w)."""
    x, y, z, w = quaternion
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_matrix(rotation: Array) -> Quaternion:
    """The unit quaternion (x, y, z, w) of a 3x3 rotation (Shepperd's method, w >= 0)."""
    m = rotation
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4)
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-12))
        v = [0.0, 0.0, 0.0]
        v[i] = s / 4
        v[j] = (m[j, i] + m[i, j]) / s
        v[k] = (m[k, i] + m[i, k]) / s
        q = (v[0], v[1], v[2], (m[k, j] - m[j, k]) / s)
    x, y, z, w = (float(c) for c in q)
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    return (x / norm, y / norm, z / norm, w / norm)


def rpy_matrix(roll: float, pitch: float, yaw: float) -> Array:
    """The rotation R = Rz(yaw) Ry(pitch) Rx(roll) (ROS's fixed-axis roll, pitch, yaw)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def rpy_from_matrix(rotation: Array) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation, the inverse of ``rpy_matrix`` (pitch in [-pi/2, pi/2])."""
    pitch = math.asin(max(-1.0, min(1.0, -float(rotation[2, 0]))))
    roll = math.atan2(float(rotation[2, 1]), float(rotation[2, 2]))
    yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    return roll, pitch, yaw


def rpy_from_quaternion(quaternion: Quaternion) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a unit quaternion (x, y, z, w)."""
    return rpy_from_matrix(rotation_matrix(quaternion))


def pose_matrix(x: float, y: float, z: float, roll: float, pitch: float, yaw: float) -> Array:
    """The 4x4 transform of a position and roll, pitch, yaw."""
    out = np.eye(4)
    out[:3, :3] = rpy_matrix(roll, pitch, yaw)
    out[:3, 3] = (x, y, z)
    return out


def planar_matrix(x: float, y: float, yaw: float) -> Array:
    """The 4x4 transform of a pose on the floor: position (x, y, 0), heading yaw about z."""
    out = np.eye(4)
    out[:2, :2] = se2.rotation(yaw)
    out[:2, 3] = (x, y)
    return out


def invert(matrix: Array) -> Array:
    """Invert a rigid transform without a general matrix inverse."""
    out = np.eye(4)
    rotation_t = matrix[:3, :3].T
    out[:3, :3] = rotation_t
    out[:3, 3] = -rotation_t @ matrix[:3, 3]
    return out


def slerp(q0: Quaternion, q1: Quaternion, weight: float) -> Quaternion:
    """Spherical interpolation along the shorter arc, as tf2 does between two samples."""
    ax, ay, az, aw = q0
    bx, by, bz, bw = q1
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        bx, by, bz, bw, dot = -bx, -by, -bz, -bw, -dot
    if dot > 0.9995:
        # Nearly parallel: the sine ratios are ill-conditioned, a normalised lerp is exact enough.
        w0, w1 = 1.0 - weight, weight
    else:
        theta = math.acos(dot)
        sin_theta = math.sin(theta)
        w0 = math.sin((1.0 - weight) * theta) / sin_theta
        w1 = math.sin(weight * theta) / sin_theta
    x, y, z, w = w0 * ax + w1 * bx, w0 * ay + w1 * by, w0 * az + w1 * bz, w0 * aw + w1 * bw
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    return (x / norm, y / norm, z / norm, w / norm)


def forward_axis(frame: str) -> int:
    """The axis a frame looks along, by ROS convention: z for ``*optical*`` frames, else x."""
    return FORWARD_Z if "optical" in frame else FORWARD_X


def heading(rotation: Array, forward: int = FORWARD_X) -> float:
    """The heading (about z) of a frame's forward axis, projected onto the floor.

    A frame looking nearly straight up or down has no forward heading to speak of; its sideways
    axis (y for body frames, x for optical ones), turned a quarter, stands in for it.
    """
    ahead = rotation[:, forward]
    if math.hypot(ahead[0], ahead[1]) > 0.2:
        return math.atan2(float(ahead[1]), float(ahead[0]))
    # Body frames: y is left of forward. Optical frames: x is right of forward.
    side, turn = (1, -math.pi / 2) if forward == FORWARD_X else (0, math.pi / 2)
    across = rotation[:, side]
    return math.atan2(float(across[1]), float(across[0])) + turn


def split_planar(pose: Array, forward: int = FORWARD_X) -> tuple[float, float, float, Array]:
    """Cut a 6-DoF pose (level frame <- child) into a pose on the floor and what is left.

    Returns:
        (x, y, yaw, tilt) with ``planar_matrix(x, y, yaw) @ tilt == pose``: the floor point
        below the child, its heading, and the child in that floor frame (its height, roll and
        pitch; no heading and no horizontal offset).
    """
    x, y = float(pose[0, 3]), float(pose[1, 3])
    yaw = heading(pose[:3, :3], forward)
    return x, y, yaw, invert(planar_matrix(x, y, yaw)) @ pose
