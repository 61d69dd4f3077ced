"""Where the mapper's poses come from: wallmap's pose messages, or a ROS 2 system over Zenoh.

A ROS 2 system reaches Zenoh through zenoh-bridge-ros2dds (key = the topic name without its
leading slash, e.g. ``odom``, prefixed by the bridge's namespace if it has one) or through
rmw_zenoh (key = ``<domain>/<topic>/<type>/<type hash>``, e.g.
``0/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_…``; subscribe with ``0/odom/**``). Both carry the
message as CDR bytes, which the rosbags typestore decodes without a ROS installation.
"""

from __future__ import annotations

import collections
import time
from typing import Protocol

import numpy as np

from wallmap.common.codec import MessageError
from wallmap.common.messages import Pose, unpack_pose
from wallmap.common.ros2_types import deserialize_cdr
from wallmap.common.ros_poses import (
    DEFAULT_CHILD,
    DEFAULT_PARENT,
    ODOMETRY_TYPE,
    POSE_TYPES,
    pose_from_matrix,
    pose_from_message,
)
from wallmap.common.tf_buffer import TfBuffer, TfError, normalize_frame

TF_TYPE = "tf2_msgs/msg/TFMessage"
ROS2_TYPES = (ODOMETRY_TYPE, *POSE_TYPES, TF_TYPE)
FORMATS = ("wallmap", *(f"ros2:{t}" for t in ROS2_TYPES))
MAX_PENDING_STAMPS = 500  # tf stamps waiting for the rest of their chain...
PENDING_SECONDS = 10.0  # ...for at most this long (in stamp time)


class PoseInput(Protocol):
    """Turns one received payload into the poses it carries."""

    def decode(self, payload: bytes, key: str) -> list[Pose]:
        """Decode; raises MessageError with the reason when the payload is unusable."""
        ...


class WallmapPoses:
    """The contract's msgpack pose, one per sample."""

    def decode(self, payload: bytes, key: str) -> list[Pose]:
        """One validated pose."""
        return [unpack_pose(payload)]


def _checked(pose: Pose) -> Pose:
    if not np.isfinite([pose.stamp, pose.x, pose.y, pose.yaw]).all():
        msg = "pose holds non-finite numbers"
        raise MessageError(msg)
    if pose.cov is not None and not np.isfinite(pose.cov).all():
        msg = "pose covariance holds non-finite numbers"
        raise MessageError(msg)
    return pose


class RosPoses:
    """``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or ``PoseWithCovarianceStamped``."""

    def __init__(self, msgtype: str) -> None:
        self.msgtype = msgtype

    def decode(self, payload: bytes, key: str) -> list[Pose]:
        """One pose, stamped from the header (or the arrival time when the header has none)."""
        msg = deserialize_cdr(payload, self.msgtype)
        return [_checked(pose_from_message(msg, time.time_ns(), DEFAULT_CHILD))]


class RosTfPoses:
    """``tf2_msgs/TFMessage``: the pose of ``child`` in ``parent`` through the tf tree.

    Like a tf2 message filter, a stamp of the child's own transform waits until every edge of the
    chain covers it (``map -> odom`` often lags ``odom -> base_link``). Keys ending in
    ``tf_static`` carry static transforms.
    """

    def __init__(self, parent: str = DEFAULT_PARENT, child: str = DEFAULT_CHILD) -> None:
        self.parent, self.child = normalize_frame(parent), normalize_frame(child)
        self.tf = TfBuffer()
        self.pending: collections.deque[float] = collections.deque(maxlen=MAX_PENDING_STAMPS)

    def decode(self, payload: bytes, key: str) -> list[Pose]:
        """Add the transforms; return the poses of every waiting stamp the tree now covers."""
        msg = deserialize_cdr(payload, TF_TYPE)
        static = key.rstrip("/").endswith("tf_static")
        added, refused = self.tf.add_message(msg, static=static)
        if refused:
            raise MessageError(refused[0])
        if not static:
            self.pending.extend(stamp for child, stamp in added if child == self.child)
        poses, waiting = [], []
        for stamp in self.pending:
            try:
                matrix = self.tf.lookup(self.parent, self.child, stamp)
            except TfError:
                if stamp > self.pending[-1] - PENDING_SECONDS:
                    waiting.append(stamp)  # the rest of the chain may still catch up
                continue
            poses.append(_checked(pose_from_matrix(matrix, stamp, self.parent, self.child)))
        self.pending = collections.deque(waiting, maxlen=MAX_PENDING_STAMPS)
        return poses


def make_pose_input(fmt: str, frames: str = f"{DEFAULT_PARENT}>{DEFAULT_CHILD}") -> PoseInput:
    """The decoder for a ``--pose-format``; ValueError names the accepted formats."""
    if fmt == "wallmap":
        return WallmapPoses()
    msgtype = fmt.removeprefix("ros2:")
    if fmt.startswith("ros2:") and msgtype == TF_TYPE:
        parent, _, child = frames.partition(">")
        if not parent or not child:
            msg = f"--pose-frames must be PARENT>CHILD, got {frames!r}"
            raise ValueError(msg)
        return RosTfPoses(parent, child)
    if fmt.startswith("ros2:") and msgtype in ROS2_TYPES:
        return RosPoses(msgtype)
    msg = f"unknown --pose-format {fmt!r}; accepted: {', '.join(FORMATS)}"
    raise ValueError(msg)
