"""A ``pose`` topic's message is read as whichever of the two pose types it is."""

from __future__ import annotations

import numpy as np
import pytest

from wallmap.common.codec import MessageError
from wallmap.common.ros2_types import ros2_typestore
from wallmap.services.ros2_source.service import _pose

T = ros2_typestore().types


def _stamped_pose():
    header = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=3, nanosec=0), frame_id="map"
    )
    point = T["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0)
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    return header, T["geometry_msgs/msg/Pose"](position=point, orientation=q)


def test_both_pose_types_are_read_and_garbage_is_refused() -> None:
    header, pose = _stamped_pose()
    stamped = T["geometry_msgs/msg/PoseStamped"](header=header, pose=pose)
    covariance = T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.eye(6).ravel())
    with_cov = T["geometry_msgs/msg/PoseWithCovarianceStamped"](header=header, pose=covariance)
    for msg in (stamped, with_cov):
        raw = ros2_typestore().serialize_cdr(msg, msg.__msgtype__)
        assert _pose(bytes(raw)).__msgtype__ == msg.__msgtype__
    with pytest.raises(MessageError, match="not a CDR"):
        _pose(b"\x00\x01\x00\x00garbage")
