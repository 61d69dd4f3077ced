"""A live robot's messages placed as the player places a bag's: waits for tf, drops, restarts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallmap.common.ros2_types import ros2_typestore
from wallmap.services.player.bag_contents import IMAGE, LASERSCAN
from wallmap.services.player.pose_sources import parse_pose_source
from wallmap.services.ros2_source.live import LiveFrames

T = ros2_typestore().types


def _header(stamp: float, frame: str):
    sec = math.floor(stamp)
    time = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9))
    return T["std_msgs/msg/Header"](stamp=time, frame_id=frame)


def _tf(stamp: float, parent: str, child: str, x: float = 0.0, yaw: float = 0.0):
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    v = T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0)
    transform = T["geometry_msgs/msg/Transform"](translation=v, rotation=q)
    stamped = T["geometry_msgs/msg/TransformStamped"](
        header=_header(stamp, parent), child_frame_id=child, transform=transform
    )
    return T["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def _scan(stamp: float, n: int = 90):
    return T["sensor_msgs/msg/LaserScan"](
        header=_header(stamp, "laser"),
        angle_min=-math.pi / 4,
        angle_max=math.pi / 4,
        angle_increment=(math.pi / 2) / (n - 1),
        time_increment=0.0,
        scan_time=0.0,
        range_min=0.1,
        range_max=10.0,
        ranges=np.full(n, 2.0, np.float32),
        intensities=np.zeros(0, np.float32),
    )


def _live(pose: str = "tf") -> tuple[LiveFrames, list[tuple[str, str]]]:
    reported: list[tuple[str, str]] = []
    report = lambda counter, line: reported.append((counter, line))  # noqa: E731
    return LiveFrames(LASERSCAN, parse_pose_source(pose), "base_link", 0.5, report=report), reported


def test_a_scan_waits_for_its_tf_then_comes_out_mounted_and_its_pose_with_it() -> None:
    live, reported = _live()
    live.add_tf(_tf(0.0, "base_link", "laser", x=0.2), static=True)
    live.add_sensor(_scan(1.0))
    assert live.ready() == []  # no map -> base_link yet: it waits
    live.add_tf(_tf(0.9, "map", "base_link", x=1.0), static=False)
    live.add_tf(_tf(1.1, "map", "base_link", x=1.2, yaw=0.1), static=False)
    frames, poses = live.ready(), live.take_poses()
    assert [f.stamp for f in frames] == [1.0]
    np.testing.assert_allclose(frames[0].T_base_sensor[:3, 3], [0.2, 0.0, 0.0], atol=1e-12)
    assert frames[0].points.shape == (1, 90, 3)
    assert [(p.stamp, round(p.x, 6)) for p in poses] == [(0.9, 1.0), (1.1, 1.2)]
    assert reported == []


def test_a_scan_whose_tf_does_not_come_is_dropped_with_the_missing_transform() -> None:
    live, reported = _live()
    live.add_sensor(_scan(1.0))
    live.add_sensor(_scan(1.2))
    assert live.ready() == []
    live.add_sensor(_scan(1.6))  # the robot's time is 0.6 s past the first
    assert live.ready() == []
    assert [counter for counter, _ in reported] == ["no_tf"]
    assert "laser" in reported[0][1]
    assert "0.5 s" in reported[0][1]


def _image(stamp: float, size: int = 8):
    millimetres = np.full(size * size, 2000, "<u2")  # a wall 2 m ahead
    return T["sensor_msgs/msg/Image"](
        header=_header(stamp, "camera"),
        height=size,
        width=size,
        encoding="16UC1",
        is_bigendian=0,
        step=2 * size,
        data=millimetres.view(np.uint8),
    )


def _camera_info(stamp: float, size: int = 8):
    k = np.array([size, 0.0, size / 2, 0.0, size, size / 2, 0.0, 0.0, 1.0])
    roi = T["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return T["sensor_msgs/msg/CameraInfo"](
        header=_header(stamp, "camera"),
        height=size,
        width=size,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=k,
        r=np.eye(3).ravel(),
        p=np.hstack([k.reshape(3, 3), np.zeros((3, 1))]).ravel(),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def _camera(pose: str) -> tuple[LiveFrames, list[tuple[str, str]]]:
    reported: list[tuple[str, str]] = []
    report = lambda counter, line: reported.append((counter, line))  # noqa: E731
    live = LiveFrames(IMAGE, parse_pose_source(pose), tf_wait=0.5, report=report)
    live.add_tf(_tf(0.0, "base_link", "camera"), static=True)
    return live, reported


def test_an_image_waits_for_the_camera_info_sent_after_it() -> None:
    live, reported = _camera("none")
    live.add_sensor(_image(1.0))
    assert live.ready() == []
    live.add_camera_info(_camera_info(1.0))
    assert [f.stamp for f in live.ready()] == [1.0]
    assert reported == []


def test_an_image_whose_camera_info_never_comes_is_dropped_and_counted() -> None:
    live, reported = _camera("none")
    live.add_sensor(_image(1.0))
    live.add_sensor(_image(1.6))  # the robot's time is 0.6 s past the first
    assert live.ready() == []
    assert reported == [("no_camera_info", "an image dropped after 0.5 s without a CameraInfo")]


def test_frames_held_for_a_survey_the_robot_never_finished_go_out_when_asked() -> None:
    live, reported = _camera("tf")
    live.add_camera_info(_camera_info(1.0))
    live.add_tf(_tf(0.9, "map", "base_link"), static=False)
    live.add_tf(_tf(1.1, "map", "base_link", x=0.1), static=False)
    live.add_sensor(_image(1.0))
    assert live.ready() == []  # held: the survey wants 10 frames or 2 s
    frames = live.end_survey()
    assert [f.stamp for f in frames] == [1.0]
    assert [p.stamp for p in live.take_poses()] == [0.9, 1.1]
    assert [counter for counter, _ in reported] == ["surveyed"]
    assert live.end_survey() == []  # once
    live.add_tf(_tf(1.3, "map", "base_link", x=0.2), static=False)
    live.add_sensor(_image(1.2))
    assert [f.stamp for f in live.ready()] == [1.2]  # no survey now: straight out


@pytest.mark.parametrize("pose", ["none", "odom"])
def test_without_a_tf_pose_only_the_mount_is_waited_for(pose: str) -> None:
    live, _ = _live(pose)
    live.add_sensor(_scan(1.0))
    assert live.ready() == []
    live.add_tf(_tf(0.0, "base_link", "laser"), static=True)
    assert [f.stamp for f in live.ready()] == [1.0]


def test_a_clock_that_jumps_back_starts_over_and_keeps_the_static_transforms() -> None:
    live, reported = _live()
    live.add_tf(_tf(0.0, "base_link", "laser"), static=True)
    live.add_tf(_tf(100.0, "map", "base_link"), static=False)
    live.add_sensor(_scan(100.2))  # waits: map -> base_link ends at 100.0
    live.add_tf(_tf(1.0, "map", "base_link"), static=False)  # a new session of the robot
    assert [counter for counter, _ in reported] == ["restarts"]
    live.add_tf(_tf(1.2, "map", "base_link", x=0.5), static=False)
    live.add_sensor(_scan(1.1))
    assert [f.stamp for f in live.ready()] == [1.1]  # the old frame is gone, the mount kept


def test_without_a_map_frame_the_poses_are_taken_in_odom_after_the_wait() -> None:
    live, reported = _live()
    live.add_tf(_tf(0.0, "base_link", "laser"), static=True)
    poses, frames = [], []
    for k in range(11):  # a robot without a localiser: odom -> base_link only
        live.add_tf(_tf(1.0 + 0.1 * k, "odom", "base_link", x=0.1 * k), static=False)
        live.add_sensor(_scan(1.0 + 0.1 * k))
        frames += live.ready()
        poses += live.take_poses()
        if k < 5:  # map -> base_link is what the source waits for, for tf_wait...
            assert (frames, poses) == ([], [])
    # ...then it takes the poses in odom, says so once, and loses no frame.
    assert [counter for counter, _ in reported] == ["pose_source_changed"]
    assert "tf:odom>base_link" in reported[0][1]
    assert [round(f.stamp, 1) for f in frames] == [round(1.0 + 0.1 * k, 1) for k in range(11)]
    assert {p.frame for p in poses} == {"odom"}


def _odometry(stamp: float, child: str, pitch: float):
    half = pitch / 2
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=math.sin(half), z=0.0, w=math.cos(half))
    point = T["geometry_msgs/msg/Point"](x=1.0, y=0.0, z=0.0)
    pose = T["geometry_msgs/msg/PoseWithCovariance"](
        pose=T["geometry_msgs/msg/Pose"](position=point, orientation=q), covariance=np.zeros(36)
    )
    still = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=still, angular=still), covariance=np.zeros(36)
    )
    return T["nav_msgs/msg/Odometry"](
        header=_header(stamp, "odom"), child_frame_id=child, pose=pose, twist=twist
    )


def test_an_odometry_topic_names_the_robot_frame_and_its_tilt_goes_into_the_mount() -> None:
    live, reported = _live("odom")
    live.add_tf(_tf(0.0, "base_footprint", "laser", x=0.2), static=True)
    live.add_pose(_odometry(1.0, "base_footprint", pitch=0.1))
    (pose,) = live.take_poses()
    assert (pose.child, round(pose.x, 9), pose.pitch) == ("base_footprint", 1.0, 0.0)
    assert [counter for counter, _ in reported] == ["pose_source_changed"]
    live.add_pose(_odometry(2.0, "base_footprint", pitch=0.3))
    live.add_sensor(_scan(1.1))  # nearest pose in time: the one at 1.0 s, pitched 0.1 rad
    (frame,) = live.ready()
    mount = frame.T_base_sensor
    assert math.atan2(-mount[2, 0], mount[0, 0]) == pytest.approx(0.1)
    np.testing.assert_allclose(mount[:3, 3], [0.2 * math.cos(0.1), 0.0, -0.2 * math.sin(0.1)])
