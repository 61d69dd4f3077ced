"""The mapper's pose decoders: the contract's msgpack, and ROS 2 CDR as the bridges carry it."""

import math

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from wallmap.common.codec import MessageError
from wallmap.common.messages import Pose, pack
from wallmap.services.mapper.pose_input import FORMATS, make_pose_input

STORE = get_typestore(Stores.ROS2_HUMBLE)
T = STORE.types


def header(stamp: float, frame: str):
    sec = math.floor(stamp)
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9)),
        frame_id=frame,
    )


def ros_pose(x: float, y: float, yaw: float):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        ),
    )


def cdr(msg, msgtype: str) -> bytes:
    return bytes(STORE.serialize_cdr(msg, msgtype))


def transform(stamp, parent, child, x, y, yaw):
    tf = T["geometry_msgs/msg/Transform"](
        translation=T["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0),
        rotation=T["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
        ),
    )
    return T["geometry_msgs/msg/TransformStamped"](
        header=header(stamp, parent), child_frame_id=child, transform=tf
    )


def tf_message(*transforms) -> bytes:
    msgtype = "tf2_msgs/msg/TFMessage"
    return cdr(T[msgtype](transforms=list(transforms)), msgtype)


def test_wallmap_format_is_the_contract_pose():
    pose = make_pose_input("wallmap").decode(pack(Pose(5.0, 1.0, 2.0, 0.3)), "wallmap/pose")
    assert [(p.stamp, p.x, p.y, p.yaw) for p in pose] == [(5.0, 1.0, 2.0, 0.3)]


def test_odometry_cdr_gives_the_pose_and_its_planar_covariance():
    cov = np.zeros(36)
    cov[[0, 7, 35]] = [0.01, 0.02, 0.03]
    msgtype = "nav_msgs/msg/Odometry"
    msg = T[msgtype](
        header=header(12.5, "odom"),
        child_frame_id="base_footprint",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=ros_pose(1.0, -2.0, 0.7), covariance=cov
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](
                linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            ),
            covariance=np.zeros(36),
        ),
    )
    (pose,) = make_pose_input(f"ros2:{msgtype}").decode(cdr(msg, msgtype), "rt/odom")
    assert (pose.stamp, pose.x, pose.y) == (12.5, 1.0, -2.0)
    assert pose.yaw == pytest.approx(0.7)
    np.testing.assert_allclose(np.diag(pose.cov), [0.01, 0.02, 0.03])
    assert (pose.frame, pose.child) == ("odom", "base_footprint")


@pytest.mark.parametrize(
    "msgtype", ["geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped"]
)
def test_pose_topics_cdr(msgtype):
    if msgtype.endswith("Covariance" + "Stamped"):
        inner = T["geometry_msgs/msg/PoseWithCovariance"](
            pose=ros_pose(3.0, 4.0, -1.0), covariance=np.zeros(36)
        )
    else:
        inner = ros_pose(3.0, 4.0, -1.0)
    msg = T[msgtype](header=header(7.25, "map"), pose=inner)
    (pose,) = make_pose_input(f"ros2:{msgtype}").decode(cdr(msg, msgtype), "amcl_pose")
    assert (pose.stamp, pose.x, pose.y, pose.cov) == (7.25, 3.0, 4.0, None)
    assert pose.yaw == pytest.approx(-1.0)


def test_tf_messages_wait_for_the_whole_chain_like_a_message_filter():
    tf = make_pose_input("ros2:tf2_msgs/msg/TFMessage", "map>base_link")
    # odom -> base_link runs ahead of map -> odom, as with a real localiser.
    assert tf.decode(tf_message(transform(1.0, "map", "odom", 10.0, 0.0, 0.0)), "rt/tf") == []
    first = tf.decode(tf_message(transform(1.0, "odom", "base_link", 1.0, 0.0, 0.0)), "rt/tf")
    assert [(p.stamp, p.x) for p in first] == [(1.0, 11.0)]
    assert tf.decode(tf_message(transform(2.0, "odom", "base_link", 2.0, 0.0, 0.0)), "rt/tf") == []
    later = tf.decode(tf_message(transform(3.0, "map", "odom", 10.0, 1.0, math.pi / 2)), "rt/tf")
    assert len(later) == 1
    pose = later[0]
    # At t=2 map->odom is halfway: (10, 0.5) and 45 degrees; odom->base_link is (2, 0).
    assert pose.stamp == 2.0
    assert pose.x == pytest.approx(10 + 2 * math.cos(math.pi / 4))
    assert pose.y == pytest.approx(0.5 + 2 * math.sin(math.pi / 4))
    assert pose.yaw == pytest.approx(math.pi / 4)


def test_static_transforms_come_on_the_tf_static_key():
    tf = make_pose_input("ros2:tf2_msgs/msg/TFMessage", "map>base_link")
    tf.decode(tf_message(transform(0.0, "map", "odom", 5.0, 0.0, 0.0)), "rt/tf_static")
    (pose,) = tf.decode(tf_message(transform(9.0, "odom", "base_link", 1.0, 0.0, 0.0)), "rt/tf")
    assert (pose.stamp, pose.x) == (9.0, 6.0)


def test_bad_payloads_and_formats_are_refused_with_reasons():
    for fmt in FORMATS[1:]:
        with pytest.raises(MessageError, match="not a CDR"):
            make_pose_input(fmt).decode(b"\x00\x01\x00\x00garbage", "rt/x")
    with pytest.raises(ValueError, match="unknown --pose-format"):
        make_pose_input("ros2:std_msgs/msg/String")
    with pytest.raises(ValueError, match="PARENT>CHILD"):
        make_pose_input("ros2:tf2_msgs/msg/TFMessage", "map")
    msgtype = "geometry_msgs/msg/PoseStamped"
    nan = T[msgtype](header=header(1.0, "map"), pose=ros_pose(math.nan, 0.0, 0.0))
    with pytest.raises(MessageError, match="non-finite"):
        make_pose_input(f"ros2:{msgtype}").decode(cdr(nan, msgtype), "pose")
