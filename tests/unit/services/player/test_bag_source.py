"""BagSource on bags written here with rosbags (ROS 1, ROS 2 mcap and sqlite3) and real bags,
plus the pose-source specs, pose tracks and TUM files it relies on."""

import dataclasses
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bag_records import Record, write_records
from conftest import REAL_DATA, real_bag
from rosbags.rosbag2 import StoragePlugin
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from wallmap.common.messages import Pose
from wallmap.common.scan_row import STACK, RowSelection, rows_to_search, select_points
from wallmap.common.tf_buffer import transform_matrix
from wallmap.scene import Camera, write_scene_bag
from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.errors import PlayerError, Refusal
from wallmap.services.player.pose_sources import (
    PoseSourceSpec,
    PoseTrack,
    load_tum,
    parse_pose_source,
    resolve_pose_topic,
)

# shared/ sits beside the repository checkout, locally and in CI.
REAL = REAL_DATA
T0 = 1_700_000_000  # header stamps, seconds


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


# --- message and bag builders -------------------------------------------------------------------


class Msgs:
    """Builds messages for one typestore, hiding the ROS 1 / ROS 2 differences."""

    def __init__(self, store: Stores) -> None:
        self.ros1 = store == Stores.ROS1_NOETIC
        self.store: Typestore = get_typestore(store)
        if "tf2_msgs/msg/TFMessage" not in self.store.types:
            self.store.register(
                get_types_from_msg(
                    "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
                )
            )
        self.t = self.store.types

    def header(self, stamp: float, frame: str) -> Any:
        sec = math.floor(stamp)
        time = self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9))
        if self.ros1:
            return self.t["std_msgs/msg/Header"](seq=0, stamp=time, frame_id=frame)
        return self.t["std_msgs/msg/Header"](stamp=time, frame_id=frame)

    def cloud(self, stamp: float, frame: str, xyz: np.ndarray) -> Any:
        """An organized cloud with an intensity field and point_step 32."""
        height, width, _ = xyz.shape
        points = np.zeros((height, width, 8), dtype=np.float32)
        points[..., :3] = xyz
        points[..., 4] = 0.5
        field = self.t["sensor_msgs/msg/PointField"]
        return self.t["sensor_msgs/msg/PointCloud2"](
            header=self.header(stamp, frame),
            height=height,
            width=width,
            fields=[
                field(n, o, 7, 1) for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 16))
            ],
            is_bigendian=False,
            point_step=32,
            row_step=32 * width,
            data=points.view(np.uint8).ravel(),
            is_dense=False,
        )

    def image(self, stamp: float, frame: str, pixels: np.ndarray, encoding: str) -> Any:
        height, width = pixels.shape[:2]
        data = np.ascontiguousarray(pixels).view(np.uint8).ravel()
        return self.t["sensor_msgs/msg/Image"](
            header=self.header(stamp, frame),
            height=height,
            width=width,
            encoding=encoding,
            is_bigendian=False,
            step=data.size // height,
            data=data,
        )

    def camera_info(self, stamp: float, frame: str, width: int, height: int, k: list[float]) -> Any:
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
        return self.t["sensor_msgs/msg/CameraInfo"](
            self.header(stamp, frame),
            height,
            width,
            "plumb_bob",
            np.zeros(5),
            np.array(k, dtype=np.float64),
            np.eye(3).ravel(),
            np.zeros(12),
            0,
            0,
            roi,
        )

    def scan(self, stamp: float, frame: str, ranges: list[float]) -> Any:
        return self.t["sensor_msgs/msg/LaserScan"](
            header=self.header(stamp, frame),
            angle_min=0.0,
            angle_max=math.pi / 2,
            angle_increment=math.pi / 2 / max(len(ranges) - 1, 1),
            time_increment=0.0,
            scan_time=0.1,
            range_min=0.1,
            range_max=10.0,
            ranges=np.array(ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )

    def pose(self, x: float, y: float, yaw: float) -> Any:
        t = self.t
        return t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](*yaw_quaternion(yaw)),
        )

    def tf(self, stamp: float, edges: Iterable[tuple[str, str, tuple, tuple]]) -> Any:
        t = self.t
        transforms = [
            t["geometry_msgs/msg/TransformStamped"](
                header=self.header(stamp, parent),
                child_frame_id=child,
                transform=t["geometry_msgs/msg/Transform"](
                    translation=t["geometry_msgs/msg/Vector3"](*translation),
                    rotation=t["geometry_msgs/msg/Quaternion"](*rotation),
                ),
            )
            for parent, child, translation, rotation in edges
        ]
        return t["tf2_msgs/msg/TFMessage"](transforms=transforms)

    def odometry(self, stamp: float, x: float, y: float, yaw: float, cov: np.ndarray) -> Any:
        t = self.t
        twist = t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=t["geometry_msgs/msg/Vector3"](0, 0, 0),
                angular=t["geometry_msgs/msg/Vector3"](0, 0, 0),
            ),
            covariance=np.zeros(36),
        )
        return t["nav_msgs/msg/Odometry"](
            header=self.header(stamp, "odom"),
            child_frame_id="base_footprint",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](self.pose(x, y, yaw), cov.ravel()),
            twist=twist,
        )

    def pose_with_covariance(self, stamp: float, x: float, y: float, yaw: float) -> Any:
        cov = np.zeros(36)
        cov[0], cov[7], cov[35] = 0.1, 0.2, 0.3
        return self.t["geometry_msgs/msg/PoseWithCovarianceStamped"](
            header=self.header(stamp, "map"),
            pose=self.t["geometry_msgs/msg/PoseWithCovariance"](self.pose(x, y, yaw), cov),
        )


def write_bag(
    path: Path, msgs: Msgs, records: list[Record], plugin: StoragePlugin | None = None
) -> Path:
    """Write records (in the given order) to a ROS 1 bag, or a ROS 2 bag with ``plugin``."""
    assert msgs.ros1 == (plugin is None)
    return write_records(path, msgs.store, records, plugin)


MOUNT = ((0.3, 0.0, 0.5), yaw_quaternion(0.0))  # base_link -> camera_link
OPTICAL = ((0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5))  # camera_link -> camera_optical
TFMSG = "tf2_msgs/msg/TFMessage"


def robot_tf(msgs: Msgs) -> list[Record]:
    """map -> odom (fixed offset) -> base_link (x = t - T0, yaw = 0.1 (t - T0)), static mount."""
    static = msgs.tf(
        T0, [("base_link", "camera_link", *MOUNT), ("camera_link", "camera_optical", *OPTICAL)]
    )
    records = [Record("/tf_static", TFMSG, static, T0)]
    for i in range(11):
        stamp = T0 + i * 0.5
        edges = [
            ("map", "odom", (10.0, 0.0, 0.0), yaw_quaternion(0.0)),
            ("odom", "base_link", (i * 0.5, 0.0, 0.0), yaw_quaternion(0.05 * i)),
        ]
        records.append(Record("/tf", TFMSG, msgs.tf(stamp, edges), stamp))
    return records


def read_all(path: Path, **options: Any) -> int:
    """Open a bag and decode every frame, returning how many there were."""
    with BagSource(path, **options) as source:
        return len(list(source.frames()))


def grid(height: int = 3, width: int = 4) -> np.ndarray:
    return np.arange(height * width * 3, dtype=np.float32).reshape(height, width, 3) / 10


# --- full bags ----------------------------------------------------------------------------------


def test_ros1_pointcloud_bag_with_tf(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS1_NOETIC)
    records = robot_tf(msgs)
    for i in range(4):
        stamp = T0 + 1.25 + i
        records.append(
            Record(
                "/camera/points",
                "sensor_msgs/msg/PointCloud2",
                msgs.cloud(stamp, "/camera_link", grid() + i),
                stamp + 0.01,
            )
        )
    records.sort(key=lambda r: r.receive)
    bag = write_bag(tmp_path / "robot.bag", msgs, records)

    with BagSource(bag) as source:
        assert source.sensor_topic == "/camera/points"
        assert source.sensor_type == "sensor_msgs/msg/PointCloud2"
        assert len(source) == source.frame_count == 4
        assert source.duration == pytest.approx(5.0)
        assert source.base_frame == "base_link"
        assert source.warnings == []
        assert str(source.pose_spec) == "tf:map>base_link"
        frames = list(source.frames())
    assert len(frames) == 4
    for i, (frame, pose) in enumerate(frames):
        stamp = T0 + 1.25 + i
        assert frame.stamp == pytest.approx(stamp)
        assert frame.frame_id == "camera_link"
        np.testing.assert_array_equal(frame.points, grid() + i)
        np.testing.assert_allclose(frame.T_base_sensor, transform_matrix(*MOUNT), atol=1e-12)
        assert pose is not None
        assert (pose.frame, pose.child, pose.cov) == ("map", "base_link", None)
        assert pose.x == pytest.approx(10.0 + (stamp - T0), abs=1e-6)
        assert pose.yaw == pytest.approx(0.1 * (stamp - T0), abs=1e-6)
        assert pose.stamp == frame.stamp
    # Past the last tf sample (T0 + 5) by more than the tolerance: no pose.
    with BagSource(bag) as source:
        assert source.pose_at(T0 + 5.2) is None
        assert source.pose_at(T0 + 5.04) is not None


def depth_bag_records(msgs: Msgs, *, with_tf: bool = True) -> list[Record]:
    depth = np.full((6, 8), 2000, dtype=np.uint16)
    depth[1, 2] = 0
    k = [400.0, 0, 3.5, 0, 400.0, 2.5, 0, 0, 1]
    records = robot_tf(msgs) if with_tf else []
    for i in range(3):
        stamp = T0 + 0.4 + i
        records.append(
            Record(
                "/camera/depth/camera_info",
                "sensor_msgs/msg/CameraInfo",
                msgs.camera_info(stamp, "camera_optical", 8, 6, k),
                stamp,
            )
        )
        records.append(
            Record(
                "/camera/depth/image_raw",
                "sensor_msgs/msg/Image",
                msgs.image(stamp, "camera_optical", depth, "16UC1"),
                stamp,
            )
        )
        records.append(
            Record(
                "/camera/rgb/image_raw",
                "sensor_msgs/msg/Image",
                msgs.image(stamp, "camera_optical", np.zeros((6, 8, 3), np.uint8), "rgb8"),
                stamp,
            )
        )
    records.sort(key=lambda r: r.receive)
    return records


@pytest.mark.parametrize(
    "plugin", [StoragePlugin.MCAP, StoragePlugin.SQLITE3], ids=["mcap", "sqlite3"]
)
def test_ros2_depth_bag_with_tf_chain(tmp_path: Path, plugin: StoragePlugin) -> None:
    msgs = Msgs(Stores.ROS2_HUMBLE)
    bag = write_bag(tmp_path / "depth", msgs, depth_bag_records(msgs), plugin)
    with BagSource(bag) as source:
        assert source.sensor_topic == "/camera/depth/image_raw"
        assert source.sensor_type == "sensor_msgs/msg/Image"
        frames = list(source.frames())
    assert len(frames) == 3
    mount = transform_matrix(*MOUNT) @ transform_matrix(*OPTICAL)
    for i, (frame, pose) in enumerate(frames):
        assert frame.points.shape == (6, 8, 3)
        assert frame.frame_id == "camera_optical"
        np.testing.assert_allclose(
            frame.points[4, 7], [3.5 / 400 * 2, 1.5 / 400 * 2, 2.0], rtol=1e-6
        )
        assert np.isnan(frame.points[1, 2]).all()
        np.testing.assert_allclose(frame.T_base_sensor, mount, atol=1e-12)
        # The optical axis (z) points along the robot's x axis.
        np.testing.assert_allclose(frame.T_base_sensor[:3, 2], [1, 0, 0], atol=1e-12)
        assert pose is not None
        assert pose.x == pytest.approx(10.4 + i, abs=1e-6)
    # The mcap file itself (not its folder) opens too.
    if plugin == StoragePlugin.MCAP:
        (file,) = bag.glob("*.mcap")
        assert read_all(file) == 3


def test_ros2_laserscan_with_odometry_pose_source(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS2_HUMBLE)
    cov = np.diag([0.01, 0.02, 0.0, 0.0, 0.0, 0.03])
    records = [
        Record(
            "/odom", "nav_msgs/msg/Odometry", msgs.odometry(T0 + i, i, 2 * i, 0.1 * i, cov), T0 + i
        )
        for i in range(5)
    ]
    records += [
        Record(
            "scan",
            "sensor_msgs/msg/LaserScan",
            msgs.scan(T0 + 0.5 + i, "base_footprint", [1, 2, 3]),
            T0 + 0.5 + i,
        )
        for i in range(5)
    ]
    records.sort(key=lambda r: r.receive)
    bag = write_bag(tmp_path / "odom", msgs, records, StoragePlugin.SQLITE3)
    with BagSource(bag, pose_source="odom") as source:
        assert source.base_frame == "base_footprint"  # the odometry's child frame
        assert source.sensor_topic == "scan"
        frames = list(source.frames())
    assert len(frames) == 5
    frame, pose = frames[1]
    assert frame.points.shape == (1, 3, 3)
    np.testing.assert_allclose(frame.T_base_sensor, np.eye(4), atol=1e-12)
    assert pose is not None
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((1.5, 3.0, 0.15))
    assert (pose.frame, pose.child) == ("odom", "base_footprint")
    np.testing.assert_allclose(pose.cov, np.diag([0.01, 0.02, 0.03]))
    assert frames[-1][1] is None  # 4.5 s is past the last odometry sample (4 s)
    # odom:TOPIC with or without the slash.
    with BagSource(bag, pose_source="odom:odom", sensor_topic="/scan") as source:
        assert next(source.frames())[1] is not None


def test_odometry_child_frame_bridged_to_base_frame_through_tf(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS2_HUMBLE)
    records = [
        Record(
            "/tf_static",
            TFMSG,
            msgs.tf(T0, [("base_footprint", "base_link", (1.0, 0, 0), yaw_quaternion(0))]),
            T0,
        )
    ]
    records += [
        Record(
            "/odom",
            "nav_msgs/msg/Odometry",
            msgs.odometry(T0 + i, i, 0, math.pi / 2, np.zeros(36)),
            T0 + i,
        )
        for i in range(3)
    ]
    records += [
        Record("/scan", "sensor_msgs/msg/LaserScan", msgs.scan(T0 + 1, "base_link", [1.0]), T0 + 1)
    ]
    bag = write_bag(tmp_path / "bridge", msgs, records, StoragePlugin.MCAP)
    with BagSource(bag, pose_source="odom", base_frame="base_link") as source:
        ((frame, pose),) = source.frames()
    np.testing.assert_allclose(frame.T_base_sensor, np.eye(4), atol=1e-12)
    assert pose is not None
    assert (pose.x, pose.y, pose.yaw, pose.child, pose.cov) == pytest.approx(
        (1.0, 1.0, math.pi / 2, "base_link", None)
    )


def test_pose_topic_source_and_zero_header_stamp(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS1_NOETIC)
    records = [
        Record(
            "/amcl_pose",
            "geometry_msgs/msg/PoseWithCovarianceStamped",
            msgs.pose_with_covariance(T0 + i, i, 0, 0),
            T0 + i,
        )
        for i in range(3)
    ]
    records.append(
        Record("/scan", "sensor_msgs/msg/LaserScan", msgs.scan(0.0, "base_link", [1.0]), T0 + 1.5)
    )
    records.sort(key=lambda r: r.receive)
    bag = write_bag(tmp_path / "amcl.bag", msgs, records)
    with BagSource(bag, pose_source="pose") as source:
        ((frame, pose),) = source.frames()
    assert frame.stamp == pytest.approx(T0 + 1.5)  # zero header stamp: receive time
    assert pose is not None
    assert pose.x == pytest.approx(1.5)
    np.testing.assert_allclose(pose.cov, np.diag([0.1, 0.2, 0.3]))


def test_tum_pose_source(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS1_NOETIC)
    bag = write_bag(
        tmp_path / "scan.bag",
        msgs,
        [Record("scan", "sensor_msgs/msg/LaserScan", msgs.scan(T0 + 1, "laser", [1.0]), T0 + 1)],
    )
    tum = tmp_path / "poses.txt"
    tum.write_text(
        f"# t x y z qx qy qz qw\n{T0} 0 0 0 0 0 0 1\n{T0 + 2} 2 4 0 0 0 0.7071068 0.7071068\n"
    )
    with BagSource(bag, pose_source=f"tum:{tum}", base_frame="laser") as source:
        assert source.warnings == []
        ((_, pose),) = source.frames()
    assert pose is not None
    assert (pose.x, pose.y, pose.yaw, pose.child) == pytest.approx((1, 2, math.pi / 4, "laser"))


# --- sensor topic detection ---------------------------------------------------------------------


def test_autodetect_picks_the_depth_image_over_rgb(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS2_HUMBLE)
    bag = write_bag(tmp_path / "bag", msgs, depth_bag_records(msgs), StoragePlugin.MCAP)
    with BagSource(bag, pose_source="none") as source:
        assert source.sensor_topic == "/camera/depth/image_raw"
    with pytest.raises(
        PlayerError, match=r"'/camera/rgb/image_raw' cannot be used: its encoding 'rgb8'"
    ):
        BagSource(bag, sensor_topic="camera/rgb/image_raw")


def test_autodetect_none_several_and_slashes(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS1_NOETIC)
    flat = msgs.cloud(T0, "lidar", grid(1, 5))
    organized = msgs.cloud(T0, "cam", grid())
    records = [
        Record("/flat", "sensor_msgs/msg/PointCloud2", flat, T0),
        Record(
            "/depth/image",
            "sensor_msgs/msg/Image",
            msgs.image(T0, "cam", np.ones((2, 2), np.float32), "32FC1"),
            T0,
        ),
        Record("/odom", "nav_msgs/msg/Odometry", msgs.odometry(T0, 0, 0, 0, np.zeros(36)), T0),
    ]
    none_bag = write_bag(tmp_path / "none.bag", msgs, records)
    with pytest.raises(PlayerError) as err:
        BagSource(none_bag, pose_source="none")
    text = str(err.value)
    assert "no usable sensor topic" in text
    assert "/flat rejected: it is an unorganized PointCloud2 (height 1, width 5)" in text
    assert (
        "/depth/image rejected: no sensor_msgs/msg/CameraInfo topic in its namespace '/depth'"
        in text
    )
    assert "/odom (nav_msgs/msg/Odometry)" in text
    assert "\n" not in text
    with pytest.raises(PlayerError, match="unorganized PointCloud2"):
        BagSource(none_bag, sensor_topic="flat", pose_source="none")
    with pytest.raises(
        PlayerError, match="'/odom' cannot be used: nav_msgs/msg/Odometry is not a supported"
    ):
        BagSource(none_bag, sensor_topic="/odom", pose_source="none")
    with pytest.raises(
        PlayerError, match=r"sensor topic '/nothing' is not in .* \(topics: /depth/image"
    ):
        BagSource(none_bag, sensor_topic="/nothing", pose_source="none")

    records += [
        Record("scan", "sensor_msgs/msg/LaserScan", msgs.scan(T0, "laser", [1.0]), T0),
        Record("/cam/points", "sensor_msgs/msg/PointCloud2", organized, T0),
    ]
    several = write_bag(tmp_path / "several.bag", msgs, records)
    with pytest.raises(
        PlayerError,
        match=r"several sensor topics .*/cam/points \(sensor_msgs/msg/PointCloud2\), scan .*"
        r"--sensor-topic",
    ):
        BagSource(several, pose_source="none")
    for name in ("/scan", "scan"):
        with BagSource(several, sensor_topic=name, pose_source="none") as source:
            assert source.sensor_topic == "scan"
    with BagSource(several, sensor_topic="cam/points", pose_source="none") as source:
        assert source.sensor_topic == "/cam/points"
        assert any("identity sensor mounting" in w for w in source.warnings)


# --- sensor mounting and pose-source failures ---------------------------------------------------


def test_mounting_policies(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS1_NOETIC)
    records = [
        *robot_tf(msgs),
        Record("/scan", "sensor_msgs/msg/LaserScan", msgs.scan(T0 + 1, "laser", [1.0]), T0 + 1),
    ]
    records.sort(key=lambda r: r.receive)
    bag = write_bag(tmp_path / "laser.bag", msgs, records)
    with pytest.raises(PlayerError) as err:
        BagSource(bag)
    text = str(err.value)
    assert "no tf chain from sensor frame 'laser' to base frame 'base_link'" in text
    assert "'laser' is not in tf" in text
    with BagSource(bag, pose_source="none") as source:
        assert source.warnings == [
            "no tf from sensor frame 'laser' to base frame 'base_link' (pose source is none): "
            "using an identity sensor mounting"
        ]
        frame, pose = next(source.frames())
    np.testing.assert_allclose(frame.T_base_sensor, np.eye(4), atol=1e-12)
    assert pose is None
    with BagSource(bag, pose_source="none", base_frame="/laser") as source:
        assert source.base_frame == "laser"
        assert source.warnings == []
        np.testing.assert_array_equal(next(source.frames())[0].T_base_sensor, np.eye(4))
    with pytest.raises(
        PlayerError,
        match=r"pose source tf:map>nowhere: no tf path .*'nowhere' is not in tf.*"
        r"choose another --pose-source",
    ):
        BagSource(bag, pose_source="tf:map>nowhere")


def test_pose_source_failures(tmp_path: Path) -> None:
    msgs = Msgs(Stores.ROS1_NOETIC)
    records = [Record("scan", "sensor_msgs/msg/LaserScan", msgs.scan(T0, "base_link", [1.0]), T0)]
    bag = write_bag(tmp_path / "plain.bag", msgs, records)
    with pytest.raises(
        PlayerError, match=r"pose source tf:map>base_link: the bag has no /tf or /tf_static; choose"
    ):
        BagSource(bag)
    with pytest.raises(
        PlayerError,
        match=r"pose source odom: the bag has no nav_msgs/msg/Odometry topic \(topics: scan",
    ):
        BagSource(bag, pose_source="odom")
    with pytest.raises(
        PlayerError, match="invalid pose source 'odometry'; accepted forms: tf, tf:PARENT>CHILD"
    ):
        BagSource(bag, pose_source="odometry")
    with pytest.raises(PlayerError, match="cannot read TUM pose file"):
        BagSource(bag, pose_source=f"tum:{tmp_path / 'missing.txt'}")


# --- unreadable bags ----------------------------------------------------------------------------


def test_unreadable_paths(tmp_path: Path) -> None:
    with pytest.raises(PlayerError, match=r"bag not found: .*missing\.bag"):
        BagSource(tmp_path / "missing.bag")
    text_file = tmp_path / "notes.bag"
    text_file.write_text("hello, not a bag\n")
    with pytest.raises(
        PlayerError, match=r"notes.bag is not a ROS bag; expected a ROS 1 .bag file"
    ):
        BagSource(text_file)
    (tmp_path / "folder").mkdir()
    with pytest.raises(PlayerError, match=r"folder without metadata\.yaml"):
        BagSource(tmp_path / "folder")

    msgs = Msgs(Stores.ROS1_NOETIC)
    records = [
        Record(
            "scan", "sensor_msgs/msg/LaserScan", msgs.scan(T0 + i, "base_link", [1.0] * 50), T0 + i
        )
        for i in range(50)
    ]
    bag = write_bag(tmp_path / "good.bag", msgs, records)
    truncated = tmp_path / "truncated.bag"
    truncated.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    with pytest.raises(PlayerError) as err:
        BagSource(truncated, pose_source="none")
    assert str(err.value).startswith(f"cannot read bag {truncated}; it looks damaged")
    assert "\n" not in str(err.value)
    corrupt = bytearray(bag.read_bytes())
    corrupt[len(corrupt) // 2 : len(corrupt) // 2 + 200] = b"\xff" * 200
    (tmp_path / "corrupt.bag").write_bytes(corrupt)
    with pytest.raises(PlayerError, match=r"corrupt\.bag; it looks damaged"):
        read_all(tmp_path / "corrupt.bag", pose_source="none")
    renamed = tmp_path / "good.rosbag"
    renamed.write_bytes(bag.read_bytes())
    with pytest.raises(PlayerError, match=r"holds a .bag bag; rename it to end in .bag"):
        BagSource(renamed)


# --- real recordings ----------------------------------------------------------------------------


def test_real_hallway_laserscan_bag() -> None:
    with BagSource(real_bag("hallway.bag"), pose_source="none") as source:
        assert source.sensor_topic == "scan"
        assert len(source) == 881
        assert len(source.warnings) == 1
        count = 0
        for frame, pose in source.frames():
            assert frame.points.shape == (1, 360, 3)
            assert frame.frame_id == "laser_frame"
            assert pose is None
            count += 1
    assert count == 881


def test_real_rosrecord_v12_bag_is_rejected_in_one_line() -> None:
    with pytest.raises(PlayerError) as err:
        BagSource(real_bag("sparsifier_demo_rosrecord_v1.2.bag"))
    text = str(err.value)
    assert "'#ROSRECORD V1.x'" in text
    assert "\n" not in text


def test_real_bag_with_damaged_index_is_rejected() -> None:
    with pytest.raises(PlayerError) as err:
        BagSource(real_bag("lsm_demo_2010.bag"))
    text = str(err.value)
    assert "looks damaged or was written by an unsupported recorder" in text
    assert "`rosbag reindex " in text
    assert "roslib/Header" in text
    assert "\n" not in text


# --- pose sources -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("tf", PoseSourceSpec("tf", "map", "base_link")),
        ("tf:odom>base_footprint", PoseSourceSpec("tf", "odom", "base_footprint", named=True)),
        (" tf:/map > /base_link ", PoseSourceSpec("tf", "map", "base_link", named=True)),
        ("odom", PoseSourceSpec("odom")),
        ("odom:/wheel/odometry", PoseSourceSpec("odom", topic="/wheel/odometry")),
        ("pose", PoseSourceSpec("pose")),
        ("pose:amcl_pose", PoseSourceSpec("pose", topic="amcl_pose")),
        ("tum:/tmp/traj.txt", PoseSourceSpec("tum", path=Path("/tmp/traj.txt"))),
        ("none", PoseSourceSpec("none")),
    ],
)
def test_parse_pose_source(text: str, expected: PoseSourceSpec) -> None:
    assert parse_pose_source(text) == expected


@pytest.mark.parametrize(
    "text",
    [
        "",
        "tf:",
        "tf:map",
        "tf:map>",
        "tf:>base",
        "tf:a>b>c",
        "tf:a>a",
        "odom:",
        "pose:a b",
        "tum",
        "tum:",
        "none:x",
        "gps",
        "TF",
    ],
)
def test_parse_pose_source_rejects(text: str) -> None:
    with pytest.raises(PlayerError) as err:
        parse_pose_source(text)
    assert str(err.value) == (
        f"invalid pose source {text!r}; accepted forms: "
        "tf, tf:PARENT>CHILD, odom, odom:TOPIC, pose, pose:TOPIC, tum:FILE, none"
    )


def test_resolve_pose_topic() -> None:
    topics = {
        "/odom": "nav_msgs/msg/Odometry",
        "/a_odom": "nav_msgs/msg/Odometry",
        "pose": "geometry_msgs/msg/PoseStamped",
    }
    assert resolve_pose_topic(PoseSourceSpec("odom"), topics) == "/a_odom"
    assert resolve_pose_topic(PoseSourceSpec("pose"), topics) == "pose"
    assert resolve_pose_topic(PoseSourceSpec("pose", topic="/pose"), topics) == "pose"
    assert resolve_pose_topic(PoseSourceSpec("pose", topic="odom"), topics) == Refusal(
        "pose source pose:odom: topic '/odom' is nav_msgs/msg/Odometry, expected "
        "geometry_msgs/msg/PoseStamped or geometry_msgs/msg/PoseWithCovarianceStamped"
    )
    topics["/amcl_pose"] = "geometry_msgs/msg/PoseWithCovarianceStamped"
    assert resolve_pose_topic(PoseSourceSpec("pose"), topics) == Refusal(
        "pose source pose: several pose topics (/amcl_pose, pose); choose one with pose:TOPIC"
    )


def test_pose_track_interpolation_and_coverage() -> None:
    cov = np.eye(3)
    poses = [
        Pose(2.0, 2.0, 0.0, -3.0, 3 * cov, "odom", "base"),
        Pose(0.0, 0.0, 0.0, 3.0, cov, "odom", "base"),
        Pose(1.0, 1.0, 0.0, 3.1, None, "odom", "base"),
    ]
    track = PoseTrack.from_poses(poses)
    assert len(track) == 3
    np.testing.assert_array_equal(track.stamps, [0.0, 1.0, 2.0])
    mid = track.at(1.5)
    assert mid is not None
    assert mid.x == pytest.approx(1.5)
    # 3.1 -> -3.0 crosses +-pi: halfway is 3.1 + 0.0916, wrapped to -3.0916 (not 0.05).
    assert mid.yaw == pytest.approx(3.1 + (2 * math.pi - 6.1) / 2 - 2 * math.pi)
    assert mid.cov is None  # one side has no covariance
    first = track.at(-0.04)
    assert first is not None
    assert (first.stamp, first.x, first.yaw) == (-0.04, 0.0, pytest.approx(3.0))
    np.testing.assert_array_equal(first.cov, cov)
    assert track.at(-0.06) is None
    assert track.at(2.2) is None
    assert track.at(2.2, tolerance=0.3) is not None


def test_tum_file(tmp_path: Path) -> None:
    path = tmp_path / "traj.tum"
    path.write_text(
        "# timestamp tx ty tz qx qy qz qw\n\n"
        "2.0 2 0 0 0 0 1 0   # facing backwards\n"
        "1.0 1 5 9 0 0 0 1\n"
    )
    track = load_tum(path)
    np.testing.assert_array_equal(track.stamps, [1.0, 2.0])
    np.testing.assert_array_equal(track.positions, [[1.0, 5.0, 9.0], [2.0, 0.0, 0.0]])
    assert abs(track.at(2.0).yaw) == pytest.approx(math.pi)
    assert (track.frame, track.child, track.cov) == ("map", "base_link", None)
    path.write_text("1.0 1 2 3 0 0 0 1\n1.5 1 2 3 0 0 0\n")
    with pytest.raises(
        PlayerError,
        match=r"line 2: expected 8 numbers 't x y z qx qy qz qw', got '1.5 1 2 3 0 0 0'",
    ):
        load_tum(path)
    path.write_text("# only comments\n")
    with pytest.raises(PlayerError, match="holds no poses"):
        load_tum(path)


def test_player_rows_are_the_detectors_rows(tmp_path: Path) -> None:
    """Decoding only the searched rows picks the very points a whole cloud would give."""
    bag = tmp_path / "tall.bag"
    write_scene_bag(
        bag,
        seed=5,
        n_frames=6,
        fmt="ros1",
        sensor="pointcloud",
        camera=Camera(width=48, height=200),
    )
    how = RowSelection(band=(1.3, 2.1))  # a whole cloud would choose its own band otherwise
    assert rows_to_search(how, 200).step == 3
    with BagSource(bag) as source:
        whole = [frame for frame, _ in source.frames()]
        rows = [frame for frame, _ in source.frames(how)]
    assert len(rows) == len(whole) == 6
    for full, row in zip(whole, rows, strict=True):
        assert row.points.shape == (STACK, 48, 3)
        assert row.band == how.band
        expected = select_points(full.points, full.T_base_sensor, how)
        picked = select_points(row.points, row.T_base_sensor, how, stacked=True)
        np.testing.assert_array_equal(picked, expected)
        assert np.isfinite(expected).all(axis=1).sum() > 24  # the band is seen: a real check


def test_the_rows_that_cannot_see_the_band_are_not_read(tmp_path: Path) -> None:
    """A level camera 1 m up, under the band: its lower rows are left in the bag, and the
    stacks are those of every searched row, to the bit."""
    bag = tmp_path / "level.bag"
    write_scene_bag(
        bag, seed=5, n_frames=8, fmt="ros1", sensor="pointcloud", camera=Camera(160, 120)
    )
    how = RowSelection()
    with BagSource(bag) as source:
        assert source.placement.rays is not None, "a generated camera is a pinhole"
        assert "rows that cannot see the band are not read" in source.placement.describe()
        read: list[slice] = []
        decode = source._decode
        source._decode = lambda msg, rows: read.append(rows) or decode(msg, rows)
        pruned = [frame for frame, _ in source.frames(how)]
        source._decode = decode
        source.placement = dataclasses.replace(source.placement, rays=None)
        assert "every searched row is read" in source.placement.describe()
        every = [frame for frame, _ in source.frames(how)]
    searched = len(range(120)[rows_to_search(how, 120)])
    assert len(read) == len(pruned) == len(every) == 8
    assert all(rows.start == 0 and len(range(120)[rows]) < 0.7 * searched for rows in read)
    for kept, whole in zip(pruned, every, strict=True):
        np.testing.assert_array_equal(kept.points, whole.points)
        assert np.isfinite(kept.points).all(axis=-1).sum() > 100  # the band is seen
