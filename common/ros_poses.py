"""ROS pose messages and tf transforms reduced to planar poses.

Shared by the player (poses read from bags) and the mapper (poses received from a ROS 2 system
over Zenoh as CDR bytes). The robot is assumed level: yaw is the rotation about z.
"""

import math
from typing import Any

import numpy as np

from wallmap.common.messages import Pose
from wallmap.common.tf_buffer import normalize_frame

ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
DEFAULT_PARENT = "map"
DEFAULT_CHILD = "base_link"
# Indices of x, y and yaw (rotation about z) in ROS's row-major 6x6 pose covariance.
_PLANAR = np.ix_([0, 1, 5], [0, 1, 5])


def header_stamp(header: Any, receive_time_ns: int) -> float:
    """Return a message's header stamp in float seconds, or its receive time if unset.

    Some drivers leave the header stamp at zero; the receive time is then the best estimate.
    """
    stamp = header.stamp
    if stamp.sec == 0 and stamp.nanosec == 0:
        return receive_time_ns * 1e-9
    return stamp.sec + stamp.nanosec * 1e-9


def yaw_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> float:
    """Heading about z of a rotation, assuming the robot stays level (planar motion)."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def planar_covariance(covariance: Any) -> np.ndarray | None:
    """The (x, y, yaw) block of a ROS 6x6 pose covariance; None when it is all zero (unset)."""
    full = np.asarray(covariance, dtype=np.float64).reshape(6, 6)
    if not full.any():
        return None
    return full[_PLANAR]


def pose_from_matrix(matrix: np.ndarray, stamp: float, frame: str, child: str) -> Pose:
    """Reduce a 4x4 tf transform (frame <- child) to a planar pose."""
    yaw = math.atan2(float(matrix[1, 0]), float(matrix[0, 0]))
    return Pose(stamp, float(matrix[0, 3]), float(matrix[1, 3]), yaw, None, frame, child)


def pose_from_message(msg: Any, receive_time_ns: int, child: str) -> Pose:
    """Reduce an Odometry, PoseStamped or PoseWithCovarianceStamped message to a planar pose.

    Args:
        msg: The deserialized message.
        receive_time_ns: Bag receive time, used when the header stamp is zero.
        child: Robot frame to report when the message does not name one (only Odometry does).

    Returns:
        The pose, with the x/y/yaw covariance when the message carries a non-zero one.
    """
    stamp = header_stamp(msg.header, receive_time_ns)
    if msg.__msgtype__ == "geometry_msgs/msg/PoseStamped":
        pose, cov = msg.pose, None
    else:
        pose, cov = msg.pose.pose, planar_covariance(msg.pose.covariance)
    if msg.__msgtype__ == ODOMETRY_TYPE and msg.child_frame_id:
        child = normalize_frame(msg.child_frame_id)
    q = pose.orientation
    return Pose(
        stamp,
        float(pose.position.x),
        float(pose.position.y),
        yaw_from_quaternion(q.x, q.y, q.z, q.w),
        cov,
        normalize_frame(msg.header.frame_id) or DEFAULT_PARENT,
        child,
    )
