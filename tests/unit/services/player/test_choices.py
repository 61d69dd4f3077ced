"""The player's choices about a bag, as pure functions of its contents read once.

Each test writes a small ROS 1 bag, reads its contents (``read_contents``) and checks one choice:
what it chose, or its refusal in the words the player's error uses.
"""

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bag_records import Record, write_records
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from wallmap.common.messages import Pose
from wallmap.services.player.bag_contents import BagContents, read_contents, read_stamps
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.bag_frames import read_survey_frames
from wallmap.services.player.choices import (
    Mount,
    Plan,
    SensorChoice,
    SensorRefusal,
    SurveyFrame,
    choose_mount,
    choose_placement,
    choose_sensor,
    plan_playback,
    select_topics,
)
from wallmap.services.player.errors import Refusal
from wallmap.services.player.pose_choice import PoseChoice, choose_poses
from wallmap.services.player.pose_sources import PoseSourceSpec, PoseTrack, parse_pose_source

T0 = 1_700_000_000  # header stamps, seconds
STORE = get_typestore(Stores.ROS1_NOETIC)
STORE.register(  # tf2's message is not among the noetic typestore's built-in types
    get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
)
T = STORE.types
SCAN, CLOUD, IMAGE = (
    "sensor_msgs/msg/LaserScan",
    "sensor_msgs/msg/PointCloud2",
    "sensor_msgs/msg/Image",
)
INFO, TF, ODOM = "sensor_msgs/msg/CameraInfo", "tf2_msgs/msg/TFMessage", "nav_msgs/msg/Odometry"
POSE = "geometry_msgs/msg/PoseStamped"


# --- messages -----------------------------------------------------------------------------------


def header(stamp: float, frame: str) -> Any:
    sec = math.floor(stamp)
    time = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9))
    return T["std_msgs/msg/Header"](seq=0, stamp=time, frame_id=frame)


def scan(stamp: float, frame: str = "laser") -> Any:
    return T[SCAN](
        header=header(stamp, frame),
        angle_min=0.0,
        angle_max=1.0,
        angle_increment=0.5,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=10.0,
        ranges=np.array([1.0, 2.0, 3.0], dtype=np.float32),
        intensities=np.zeros(0, np.float32),
    )


def cloud(stamp: float, frame: str, height: int, width: int = 4) -> Any:
    field = T["sensor_msgs/msg/PointField"]
    data = np.ones((height, width, 3), dtype=np.float32)
    return T[CLOUD](
        header=header(stamp, frame),
        height=height,
        width=width,
        fields=[field(n, o, 7, 1) for n, o in (("x", 0), ("y", 4), ("z", 8))],
        is_bigendian=False,
        point_step=12,
        row_step=12 * width,
        data=data.view(np.uint8).ravel(),
        is_dense=False,
    )


def image(stamp: float, frame: str, encoding: str = "16UC1") -> Any:
    data = np.full((3, 4), 1000, dtype=np.uint16).view(np.uint8).ravel()
    return T[IMAGE](
        header=header(stamp, frame),
        height=3,
        width=4,
        encoding=encoding,
        is_bigendian=False,
        step=8,
        data=data,
    )


def camera_info(stamp: float, frame: str) -> Any:
    roi = T["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
    k = np.array([100.0, 0, 2, 0, 100.0, 1.5, 0, 0, 1])
    return T[INFO](
        header(stamp, frame),
        3,
        4,
        "plumb_bob",
        np.zeros(5),
        k,
        np.eye(3).ravel(),
        np.zeros(12),
        0,
        0,
        roi,
    )


def tf(stamp: float, *links: tuple[str, str], x: float = 0.1) -> Any:
    def transform(parent: str, child: str) -> Any:
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(stamp, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
                rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )

    return T[TF](transforms=[transform(parent, child) for parent, child in links])


def pose(x: float) -> Any:
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )


def odometry(stamp: float, child: str) -> Any:
    vector = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=vector, angular=vector), covariance=np.zeros(36)
    )
    return T[ODOM](
        header=header(stamp, "odom"),
        child_frame_id=child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose(stamp - T0), np.zeros(36)),
        twist=twist,
    )


def pose_stamped(stamp: float) -> Any:
    return T[POSE](header=header(stamp, "map"), pose=pose(stamp - T0))


# --- bags ---------------------------------------------------------------------------------------


def contents_of(path: Path, records: list[Record], **read: Any) -> BagContents:
    """Write the records as a ROS 1 bag and read its contents."""
    write_records(path, STORE, sorted(records, key=lambda r: r.receive))
    with BagFile(path) as bag:
        return read_contents(bag, **read)


def scans(n: int = 5, frame: str = "laser", topic: str = "/scan") -> list[Record]:
    return [Record(topic, SCAN, scan(T0 + i, frame), T0 + i) for i in range(n)]


def robot_tf(n: int = 5) -> list[Record]:
    """map -> odom -> base_link over n seconds, base_link -> laser static."""
    records = [Record("/tf_static", TF, tf(T0, ("base_link", "laser")), T0)]
    for i in range(n):
        links = (("map", "odom"), ("odom", "base_link"))
        records.append(Record("/tf", TF, tf(T0 + i, *links, x=float(i)), T0 + i))
    return records


def sensor_of(choice: SensorChoice | Refusal) -> tuple[str, str, str]:
    """A sensor choice's topic, type and frame."""
    assert isinstance(choice, SensorChoice), choice
    return choice.topic, choice.msgtype, choice.frame_id


def chosen_sensor(contents: BagContents) -> SensorChoice:
    sensor = choose_sensor(contents, None)
    assert isinstance(sensor, SensorChoice)
    return sensor


# --- contents -----------------------------------------------------------------------------------


def test_contents_hold_tf_links_poses_and_first_messages(tmp_path: Path) -> None:
    bad = Record("/tf", TF, tf(T0 + 0.5, ("odom", "odom")), T0 + 0.5)  # tf2 refuses a self-link
    odom = [Record("/odom", ODOM, odometry(T0 + i, ""), T0 + i) for i in range(3)]
    records = [*robot_tf(3), bad, *odom, *scans(3)]
    contents = contents_of(tmp_path / "robot.bag", records)
    assert set(contents.topics) == {"/tf", "/tf_static", "/odom", "/scan"}
    links = contents.tf_links
    assert not links[("odom", "base_link")].static
    assert links[("base_link", "laser")].static
    assert links[("map", "odom")].stamps == [T0, T0 + 1, T0 + 2]
    assert contents.tf_refused == [
        "invalid tf edge 'odom' -> 'odom': frames must differ and be named"
    ]
    assert contents.tf.has_path("map", "laser")
    # Odometry naming no child frame leaves it to the pose source's choice.
    assert [(p.x, p.child) for p in contents.poses["/odom"]] == [(0, ""), (1, ""), (2, "")]
    assert contents.pose_stamps["/odom"].stamps == [T0, T0 + 1, T0 + 2]
    assert contents.firsts["/scan"].header.stamp.sec == T0
    assert contents.find("scan") == "/scan"
    assert contents.find("/odom") == "/odom"


def test_contents_read_only_the_pose_topics_asked_for(tmp_path: Path) -> None:
    records = [*scans(2), Record("/odom", ODOM, odometry(T0, "base_link"), T0)]
    records.append(Record("/pose", POSE, pose_stamped(T0), T0))
    contents = contents_of(tmp_path / "two.bag", records, pose_topics=["/pose"])
    assert list(contents.poses) == ["/pose"]


def test_stamps_of_the_sensor_count_frames_and_zero_stamps(tmp_path: Path) -> None:
    records = [*scans(3), Record("/scan", SCAN, scan(0.0, "/other"), T0 + 3.5)]
    write_records(tmp_path / "s.bag", STORE, records)
    with BagFile(tmp_path / "s.bag") as bag:
        stamps = read_stamps(bag, bag.topics["/scan"])
    assert stamps.stamps == [T0, T0 + 1, T0 + 2, T0 + 3.5]  # a zero stamp: the receive time
    assert stamps.zero == 1
    assert stamps.frame_ids == {"laser": 3, "other": 1}


# --- topics and the sensor ----------------------------------------------------------------------


def test_select_topics(tmp_path: Path) -> None:
    write_records(tmp_path / "t.bag", STORE, [*scans(1), *robot_tf(1)])
    with BagFile(tmp_path / "t.bag") as bag:
        assert set(select_topics(bag.topics, ["scan", "/tf"], bag.path)) == {"/scan", "/tf"}
        assert select_topics(bag.topics, None, bag.path) is bag.topics
        refused = select_topics(bag.topics, ["/nothing", "scan"], bag.path)
    assert refused == Refusal(
        f"--topics names nothing, not in {tmp_path / 't.bag'} (topics: /scan "
        "(sensor_msgs/msg/LaserScan), /tf (tf2_msgs/msg/TFMessage), /tf_static "
        "(tf2_msgs/msg/TFMessage))"
    )


def test_the_only_usable_sensor_is_chosen_with_its_first_frame(tmp_path: Path) -> None:
    records = [*scans(2, frame="/laser"), Record("/flat", CLOUD, cloud(T0, "lidar", 1), T0)]
    contents = contents_of(tmp_path / "one.bag", records)
    assert sensor_of(choose_sensor(contents, None)) == ("/scan", SCAN, "laser")
    refused = choose_sensor(contents, "flat")
    assert isinstance(refused, SensorRefusal)
    assert refused.candidates == ()
    assert refused.reason == (
        "sensor topic '/flat' cannot be used: it is an unorganized PointCloud2 (height 1, "
        "width 4); the detector needs organized rows"
    )


def test_several_usable_sensors_are_a_refusal_naming_them(tmp_path: Path) -> None:
    records = [*scans(2, topic="/front"), *scans(2, topic="/rear")]
    records.append(Record("/points", CLOUD, cloud(T0, "lidar", 3), T0))
    contents = contents_of(tmp_path / "three.bag", records)
    refused = choose_sensor(contents, None)
    assert isinstance(refused, SensorRefusal)
    assert refused.candidates == ("/front", "/points", "/rear")
    assert refused.reason.startswith(f"several sensor topics in {tmp_path / 'three.bag'}: /front")
    assert sensor_of(choose_sensor(contents, "rear")) == ("/rear", SCAN, "laser")


def test_no_usable_sensor_lists_every_rejection(tmp_path: Path) -> None:
    records = [
        Record("/depth/image", IMAGE, image(T0, "cam"), T0),
        Record("/rgb/image", IMAGE, image(T0, "cam", "rgb8"), T0),
        Record("/odom", ODOM, odometry(T0, "base_link"), T0),
    ]
    contents = contents_of(tmp_path / "none.bag", records)
    refused = choose_sensor(contents, None)
    assert isinstance(refused, SensorRefusal)
    assert refused.candidates == ()
    assert "; /depth/image rejected: no sensor_msgs/msg/CameraInfo topic in its namespace" in (
        refused.reason
    )
    assert "; /rgb/image rejected: its encoding 'rgb8' is not a depth encoding" in refused.reason
    assert refused.reason.endswith("bag topics: " + contents.listing())
    missing = choose_sensor(contents, "/missing")
    assert isinstance(missing, SensorRefusal)
    assert missing.reason.startswith("sensor topic '/missing' is not in ")


def test_a_depth_image_comes_with_its_camera_info(tmp_path: Path) -> None:
    records = [
        Record("/cam/image", IMAGE, image(T0, "cam_optical"), T0),
        Record("/cam/info", INFO, camera_info(T0, "cam_optical"), T0),
    ]
    sensor = chosen_sensor(contents_of(tmp_path / "depth.bag", records))
    assert sensor_of(sensor) == ("/cam/image", IMAGE, "cam_optical")
    assert list(sensor.camera_info.K) == [100.0, 0, 2, 0, 100.0, 1.5, 0, 0, 1]


def test_a_camera_info_topic_without_messages_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "empty_info.bag"
    with Writer1(path) as writer:
        images = writer.add_connection("/cam/image", IMAGE, typestore=STORE)
        writer.add_connection("/cam/info", INFO, typestore=STORE)  # no message is written
        writer.write(images, T0 * 10**9, STORE.serialize_ros1(image(T0, "cam"), IMAGE))
    with BagFile(path) as bag:
        contents = read_contents(bag)
    assert contents.firsts["/cam/info"] is None
    assert choose_sensor(contents, None) == Refusal("camera info topic '/cam/info' has no messages")


# --- pose sources -------------------------------------------------------------------------------


def test_tf_poses_follow_the_chain_to_base_link(tmp_path: Path) -> None:
    contents = contents_of(tmp_path / "tf.bag", [*robot_tf(3), *scans(3)])
    poses = choose_poses(contents, "laser", parse_pose_source("tf"))
    assert isinstance(poses, PoseChoice)
    assert (str(poses.spec), poses.base_frame, poses.warnings) == (
        "tf:map>base_link",
        "base_link",
        (),
    )
    at = poses.at(T0 + 1.5)
    assert at is not None
    assert at.x == pytest.approx(3.0)  # map -> odom and odom -> base_link: x = 1.5 m each
    assert poses.at(T0 + 2.06) is None  # past the last sample by more than the tolerance
    refused = choose_poses(contents, "laser", parse_pose_source("tf:map>nowhere"))
    assert isinstance(refused, Refusal)
    assert refused.reason.startswith("pose source tf:map>nowhere: no tf path from 'nowhere' to")
    assert refused.reason.endswith("; choose another --pose-source (odom, pose, tum:FILE or none)")


def test_without_base_link_tf_poses_are_those_of_the_frame_carrying_the_sensor(
    tmp_path: Path,
) -> None:
    records = [Record("/tf_static", TF, tf(T0, ("camera_link", "optical")), T0)]
    records += [Record("/tf", TF, tf(T0 + i, ("map", "camera_link")), T0 + i) for i in range(3)]
    contents = contents_of(tmp_path / "handheld.bag", records)
    poses = choose_poses(contents, "optical", parse_pose_source("tf"))
    assert isinstance(poses, PoseChoice)
    assert (str(poses.spec), poses.base_frame) == ("tf:map>camera_link", "camera_link")
    assert poses.warnings == (
        "no tf map -> base_link: the poses are those of 'camera_link' in 'map', the chain to the "
        "sensor's frame 'optical' (--pose-source tf:map>camera_link; name other frames the same "
        "way)",
    )
    # Named frames, or a base frame asked for, are taken as they are: here, refused.
    for spec, base in (("tf:map>base_link", None), ("tf", "base_link")):
        refused = choose_poses(contents, "optical", parse_pose_source(spec), base_frame=base)
        assert isinstance(refused, Refusal)


def test_odometry_names_its_base_frame_and_is_bridged_or_taken_as_it_is(tmp_path: Path) -> None:
    odom = [Record("/odom", ODOM, odometry(T0 + i, "base_footprint"), T0 + i) for i in range(3)]
    bridge = Record("/tf_static", TF, tf(T0, ("base_footprint", "base_link")), T0)
    contents = contents_of(tmp_path / "odom.bag", [*odom, bridge, *scans(3)])
    own = choose_poses(contents, "laser", parse_pose_source("odom"))
    assert isinstance(own, PoseChoice)
    assert (own.base_frame, own.bridged, own.warnings) == ("base_footprint", False, ())
    bridged = choose_poses(contents, "laser", parse_pose_source("odom"), base_frame="base_link")
    assert isinstance(bridged, PoseChoice)
    assert (bridged.base_frame, bridged.bridged, bridged.warnings) == ("base_link", True, ())
    at = bridged.at(T0 + 1)
    assert at is not None
    assert (at.x, at.child) == (pytest.approx(1.1), "base_link")  # 1 m, then 0.1 m to base_link
    loose = choose_poses(contents, "laser", parse_pose_source("odom"), base_frame="laser")
    assert isinstance(loose, PoseChoice)
    assert loose.track is not None
    assert (loose.bridged, loose.track.child) == (False, "laser")
    assert loose.warnings == (
        "no tf between the pose source's frame 'base_footprint' and base frame 'laser': its "
        "poses are used as 'laser' poses",
    )


def test_pose_topic_refusals(tmp_path: Path) -> None:
    contents = contents_of(tmp_path / "scan.bag", scans(2))
    refused = choose_poses(contents, "laser", parse_pose_source("pose"))
    assert refused == Refusal(
        "pose source pose: the bag has no geometry_msgs/msg/PoseStamped or "
        "geometry_msgs/msg/PoseWithCovarianceStamped topic (topics: /scan "
        "(sensor_msgs/msg/LaserScan))"
    )
    assert choose_poses(contents, "laser", parse_pose_source("tf")) == Refusal(
        "pose source tf:map>base_link: the bag has no /tf or /tf_static; choose another "
        "--pose-source (odom, pose, tum:FILE or none)"
    )
    none = choose_poses(contents, "laser", PoseSourceSpec("none"))
    assert isinstance(none, PoseChoice)
    assert (none.base_frame, none.at(T0)) == ("base_link", None)


def test_a_tum_track_describes_the_base_frame(tmp_path: Path) -> None:
    contents = contents_of(tmp_path / "scan.bag", scans(2))
    track = PoseTrack.from_poses([Pose(T0, 1.0, 2.0, 0.0, None, "map", "laser")])
    spec = PoseSourceSpec("tum", path=Path("t.tum"))
    poses = choose_poses(contents, "laser", spec, base_frame="laser", track=track)
    assert isinstance(poses, PoseChoice)
    at = poses.at(T0)
    assert at is not None
    assert (at.x, at.y, at.child, poses.warnings) == (1.0, 2.0, "laser", ())


# --- mounts -------------------------------------------------------------------------------------


def test_mounts_come_from_tf_or_are_assumed_and_said(tmp_path: Path) -> None:
    contents = contents_of(tmp_path / "tf.bag", [*robot_tf(3), *scans(3)])
    poses = choose_poses(contents, "laser", parse_pose_source("tf"))
    assert isinstance(poses, PoseChoice)
    laser = choose_mount(poses, "/scan", "laser")
    assert isinstance(laser, Mount)
    assert (laser.T_base_sensor, laser.warning) == (None, None)  # looked up in tf per stamp
    np.testing.assert_allclose(laser.at(T0 + 99)[:3, 3], [0.1, 0.0, 0.0])  # static: any time
    base = choose_mount(poses, "/scan", "base_link")
    assert isinstance(base, Mount)
    np.testing.assert_array_equal(base.at(T0), np.eye(4))
    unnamed = choose_mount(poses, "/scan", "")
    assert isinstance(unnamed, Mount)
    assert unnamed.warning == (
        "sensor messages on /scan have no frame_id; assuming they are in base frame 'base_link'"
    )
    refused = choose_mount(poses, "/scan", "sonar")
    assert isinstance(refused, Refusal)
    assert refused.reason.startswith(
        "no tf chain from sensor frame 'sonar' to base frame 'base_link': no tf path from "
        "'sonar' to 'base_link': 'sonar' is not in tf"
    )
    none = choose_poses(contents, "sonar", PoseSourceSpec("none"))
    assert isinstance(none, PoseChoice)
    assumed = choose_mount(none, "/scan", "sonar")
    assert isinstance(assumed, Mount)
    assert assumed.warning == (
        "no tf from sensor frame 'sonar' to base frame 'base_link' (pose source is none): using "
        "an identity sensor mounting"
    )


# --- plans and placement ------------------------------------------------------------------------


def test_a_plan_says_what_it_assumed_in_the_order_it_decided(tmp_path: Path) -> None:
    bad = Record("/tf", TF, tf(T0, ("map", "")), T0)
    records = [Record("/tf", TF, tf(T0 + i, ("map", "camera_link")), T0 + i) for i in range(3)]
    records += [bad, *scans(3, frame="")]
    contents = contents_of(tmp_path / "assumed.bag", records)
    sensor = chosen_sensor(contents)
    plan = plan_playback(contents, sensor, parse_pose_source("tf:map>camera_link"))
    assert isinstance(plan, Plan)
    assert plan.warnings == [
        "ignored 1 invalid tf transforms, e.g. invalid tf edge 'map' -> '': frames must differ "
        "and be named",
        "sensor messages on /scan have no frame_id; assuming they are in base frame 'camera_link'",
    ]
    assert list(plan.mounts) == [""]
    assert plan_playback(contents, sensor, parse_pose_source("odom")) == Refusal(
        "pose source odom: the bag has no nav_msgs/msg/Odometry topic (topics: /scan "
        "(sensor_msgs/msg/LaserScan), /tf (tf2_msgs/msg/TFMessage))"
    )


def test_placement_surveys_posed_frames_only(tmp_path: Path) -> None:
    records = [*robot_tf(3)]
    records += [Record("/points", CLOUD, cloud(T0 + i, "laser", 3), T0 + i) for i in range(5)]
    path = tmp_path / "clouds.bag"
    contents = contents_of(path, records)
    sensor = chosen_sensor(contents)
    plan = plan_playback(contents, sensor, parse_pose_source("tf"))
    assert isinstance(plan, Plan)
    assert plan.surveys
    with BagFile(path) as bag:
        frames = read_survey_frames(bag, sensor)
    assert [f.stamp for f in frames] == [T0 + i for i in range(5)]
    assert all(isinstance(f.points, np.ndarray) for f in frames)
    # A frame no pose covers (after 2 s) is not looked at, even when it cannot be decoded; a
    # new sensor frame is mounted as the first one was.
    broken = SurveyFrame(T0 + 4, "sonar", Refusal("cannot decode"))
    on_base = SurveyFrame(T0 + 2, "base_link", frames[2].points)
    placed = choose_placement(plan, [*frames[:2], on_base, broken], level="none", floor_z=0.5)
    assert not isinstance(placed, Refusal)
    plan_after, placement = placed
    assert placement.band is not None
    assert placement.levelling[2, 3] == -0.5
    assert list(plan_after.mounts) == ["laser", "base_link"]
    assert list(plan.mounts) == ["laser"]  # the plan itself is left as it was
    assert choose_placement(plan, [SurveyFrame(T0 + 1, "laser", Refusal("cannot decode"))]) == (
        Refusal("cannot decode")
    )
    assert isinstance(
        choose_placement(plan, [SurveyFrame(T0 + 1, "sonar", frames[0].points)]), Refusal
    )
    none = plan_playback(contents, sensor, PoseSourceSpec("none"))
    assert isinstance(none, Plan)
    assert not none.surveys
    unposed = choose_placement(none, [broken])
    assert not isinstance(unposed, Refusal)
    assert (unposed[1].level, unposed[1].band) == (None, None)
