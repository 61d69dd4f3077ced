"""ROS pose messages and tf transforms as poses, with all six degrees of freedom.

Shared by the player (poses read from bags) and the mapper (poses received from a ROS 2 system
over Zenoh as CDR bytes). The mapper uses the planar part (x, y, yaw: yaw is the heading of the
child's x axis); the player keeps height, roll and pitch with the frame they belong to.
"""

from typing import Any

import numpy as np

from wallmap.common.messages import Pose
from wallmap.common.pose3d import rpy_from_matrix, rpy_from_quaternion
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


def planar_covariance(covariance: Any) -> np.ndarray | None:
    """The (x, y, yaw) block of a ROS 6x6 pose covariance; None when it is all zero (unset)."""
    full = np.asarray(covariance, dtype=np.float64).reshape(6, 6)
    if not full.any():
        return None
    return full[_PLANAR]


def pose_from_matrix(matrix: np.ndarray, stamp: float, frame: str, child: str) -> Pose:
    """A 4x4 tf transform (frame <- child) as a pose."""
    roll, pitch, yaw = rpy_from_matrix(matrix[:3, :3])
    x, y, z = (float(v) for v in matrix[:3, 3])
    return Pose(stamp, x, y, yaw, None, frame, child, z, roll, pitch)


def pose_from_message(msg: Any, receive_time_ns: int, child: str) -> Pose:
    """An Odometry, PoseStamped or PoseWithCovarianceStamped message as a pose.

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
    roll, pitch, yaw = rpy_from_quaternion((q.x, q.y, q.z, q.w))
    return Pose(
        stamp,
        float(pose.position.x),
        float(pose.position.y),
        yaw,
        cov,
        normalize_frame(msg.header.frame_id) or DEFAULT_PARENT,
        child,
        float(pose.position.z),
        roll,
        pitch,
    )
