"""Synthetic scenes written as real ROS 1 / ROS 2 bags, with ground truth beside them.

A bag holds what a robot with a Kinect-like depth camera or a 2-D laser scanner and a
perfect localiser would record: static tf for the sensor mount, odometry that drifts
(``odom → base_link`` on /tf and /odom), a ``map → odom`` correction that makes the chain
equal the true pose, the true pose on /ground_truth and, as an AMCL-like localiser would
publish it, on /amcl_pose, and the sensor data as a point cloud, a depth image or a laser
scan. The ground truth file ``<bag>.truth.json`` holds the plan, the true trajectory and
how often the detector could have seen each wall, all in the plan's (the world's) frame, and
where the bag's map frame lies in it: the world frame itself, or, for a robot of a fleet
whose map starts where it was switched on, its first pose (``own_frame``).

The topics of :func:`write_scene_bag`: /tf_static (base_link → camera_link →
camera_optical_frame for the camera, base_link → laser for the scanner), /tf (odom → base_link
at the sensor stamps and midway between them, map → odom at 2/3 of the sensor rate), /odom
(drifting odometry at sensor stamps), /ground_truth (true pose in map), /amcl_pose (the true
pose again, with a 2 cm / 1 degree covariance, as from a localiser), and the sensor data:
either /camera/depth/points (organized PointCloud2, fields x, y, z, rgb, point_step 32, NaN for
no return), /camera/depth/image_raw (16UC1 millimetres with 0 for no return, or 32FC1 metres
with NaN) with /camera/depth/camera_info, or /scan (LaserScan in frame laser, +inf for no
return). Header stamps and bag times are the trajectory stamps. ``map → odom ∘ odom →
base_link``, interpolated at a sensor stamp, is the true pose to well under 1 mm. With pose
faults, /odom, /ground_truth and /amcl_pose carry them too, and ``map → odom ∘ odom →
base_link`` is the faulty pose.
"""

from __future__ import annotations

import json
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from wallmap.common import se2
from wallmap.scene.floorplan import FloorPlan, generate_floorplan
from wallmap.scene.pose_faults import PoseFaults
from wallmap.scene.render import (
    Camera,
    Scanner,
    depth_to_points,
    render_depth,
    render_scan,
    scan_walls_seen,
    walls_seen,
)
from wallmap.scene.trajectory import (
    Trajectory,
    drifting_odometry,
    generate_trajectory,
    write_tum,
)

BagFormat = Literal["ros1", "ros2-mcap", "ros2-sqlite3"]
SensorKind = Literal["pointcloud", "depth16", "depth32", "laserscan"]

MAP_FRAME = "map"
ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
CAMERA_LINK_FRAME = "camera_link"
OPTICAL_FRAME = "camera_optical_frame"
LASER_FRAME = "laser"

TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
ODOM_TOPIC = "/odom"
GROUND_TRUTH_TOPIC = "/ground_truth"
AMCL_POSE_TOPIC = "/amcl_pose"
POINTS_TOPIC = "/camera/depth/points"
IMAGE_TOPIC = "/camera/depth/image_raw"
CAMERA_INFO_TOPIC = "/camera/depth/camera_info"
SCAN_TOPIC = "/scan"

# camera_link → optical frame, REP-103: the quaternion (x, y, z, w) of R_LINK_OPTICAL.
OPTICAL_QUATERNION = (-0.5, 0.5, -0.5, 0.5)

# Point cloud layout with padding and an rgb field, so readers must honour the offsets.
CLOUD_DTYPE = np.dtype(
    {
        "names": ["x", "y", "z", "rgb"],
        "formats": ["<f4"] * 4,
        "offsets": [0, 4, 8, 16],
        "itemsize": 32,
    }
)
_FLOAT32 = 7  # sensor_msgs/PointField datatype

# map → odom is published every third sample of the doubled-rate trajectory: 10 Hz for a
# 15 Hz sensor. The correction is smooth, so interpolating it is exact to < 0.1 mm.
_MAP_ODOM_EVERY = 3

# Covariance of /amcl_pose, row-major 6x6 over (x, y, z, roll, pitch, yaw): a converged
# localiser's 2 cm and 1 degree; like AMCL, the dimensions it does not estimate are 0.
AMCL_COVARIANCE = np.zeros(36)
AMCL_COVARIANCE[[0, 7]] = 0.02**2
AMCL_COVARIANCE[35] = math.radians(1.0) ** 2
AMCL_COVARIANCE.flags.writeable = False


@dataclass(frozen=True, eq=False)
class SceneInfo:
    """What :func:`write_scene_bag` wrote.

    Attributes:
        path: The bag (ROS 1 file or ROS 2 folder).
        truth_path: The ground-truth JSON beside it.
        n_frames: Sensor frames written (fewer than asked if the route ended first).
        plan: The scene.
        trajectory: True base_link poses at the sensor stamps.
        seen_counts: Per wall id, the number of frames in which the detector could see it.
        map_in_world: Where the bag's map frame lies in the plan's frame, ``(x, y, yaw)``:
            ``world_point = map_in_world * map_point`` (see :func:`load_map_in_world`).
    """

    path: Path
    truth_path: Path
    n_frames: int
    plan: FloorPlan
    trajectory: Trajectory
    seen_counts: dict[int, int]
    map_in_world: tuple[float, float, float] = (0.0, 0.0, 0.0)


def stamp_to_ns(stamp: float) -> int:
    """Nanoseconds for a float stamp in seconds, as used for headers and bag times."""
    return round(stamp * 1e9)


def tum_path_for(path: str | Path) -> Path:
    """Where a scene with pose faults keeps its faulty poses as a TUM file."""
    return Path(f"{path}.poses.tum")


def truth_path_for(path: str | Path) -> Path:
    """Ground-truth file of a bag: ``<bag>.truth.json`` (beside a ROS 2 bag's folder)."""
    return Path(str(Path(path)) + ".truth.json")


class BagSink:
    """One bag writer, ROS 1 or ROS 2, behind a format-independent interface."""

    def __init__(self, path: Path, fmt: BagFormat, *, compress: bool = False) -> None:
        self.ros1 = fmt == "ros1"
        if self.ros1:
            self.typestore = get_typestore(Stores.ROS1_NOETIC)
            # Noetic's store lacks tf2_msgs; this definition has the canonical md5.
            self.typestore.register(
                get_types_from_msg(
                    "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
                )
            )
            self.writer: Writer1 | Writer2 = Writer1(path)
            if compress:
                self.writer.set_compression(Writer1.CompressionFormat.LZ4)
        else:
            self.typestore = get_typestore(Stores.ROS2_HUMBLE)
            plugin = StoragePlugin.MCAP if fmt == "ros2-mcap" else StoragePlugin.SQLITE3
            self.writer = Writer2(path, version=9, storage_plugin=plugin)
        self.types = self.typestore.types
        self._seq: dict[str, int] = {}

    def __enter__(self) -> BagSink:
        self.writer.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.writer.close()

    def topic(self, name: str, msgtype: str, *, latched: bool = False) -> Connection:
        """A new topic; ``latched`` as tf_static is (ROS 1 latching, ROS 2 transient local)."""
        if isinstance(self.writer, Writer1):
            return self.writer.add_connection(
                name, msgtype, typestore=self.typestore, latching=1 if latched else None
            )
        qos = ()
        if latched:
            zero = QosTime(0, 0)
            qos = (
                Qos(
                    QosHistory.KEEP_LAST,
                    1,
                    QosReliability.RELIABLE,
                    QosDurability.TRANSIENT_LOCAL,
                    zero,
                    zero,
                    QosLiveliness.AUTOMATIC,
                    zero,
                    False,
                ),
            )
        return self.writer.add_connection(
            name, msgtype, typestore=self.typestore, offered_qos_profiles=qos
        )

    def header(self, topic: str, stamp_ns: int, frame_id: str) -> Any:
        """A std_msgs/Header; ROS 1 headers also count a per-topic sequence number."""
        stamp = self.types["builtin_interfaces/msg/Time"](
            sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000
        )
        header_type = self.types["std_msgs/msg/Header"]
        if not self.ros1:
            return header_type(stamp=stamp, frame_id=frame_id)
        seq = self._seq.get(topic, 0)
        self._seq[topic] = seq + 1
        return header_type(seq=seq, stamp=stamp, frame_id=frame_id)

    def write(self, connection: Connection, stamp_ns: int, msg: object) -> None:
        """Serialize a message for the bag's ROS version and write it at ``stamp_ns``."""
        if self.ros1:
            data = self.typestore.serialize_ros1(msg, connection.msgtype)
        else:
            data = self.typestore.serialize_cdr(msg, connection.msgtype)
        self.writer.write(connection, stamp_ns, data)


def sub_seeds(seed: int, n: int) -> list[int]:
    """Independent seeds for the parts of a scene, all derived from one."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]


def _yaw_quaternion(sink: BagSink, yaw: float) -> Any:
    return sink.types["geometry_msgs/msg/Quaternion"](
        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
    )


def transform_stamped(
    sink: BagSink,
    topic: str,
    stamp_ns: int,
    parent: str,
    child: str,
    xyz: tuple[float, float, float],
    quaternion: tuple[float, float, float, float],
) -> Any:
    """A geometry_msgs/TransformStamped parent <- child."""
    t = sink.types
    return t["geometry_msgs/msg/TransformStamped"](
        header=sink.header(topic, stamp_ns, parent),
        child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
            rotation=t["geometry_msgs/msg/Quaternion"](
                x=quaternion[0], y=quaternion[1], z=quaternion[2], w=quaternion[3]
            ),
        ),
    )


def _planar_transform(
    sink: BagSink, stamp_ns: int, parent: str, child: str, pose: np.ndarray
) -> Any:
    x, y, yaw = se2.from_matrix(pose)
    return transform_stamped(
        sink,
        TF_TOPIC,
        stamp_ns,
        parent,
        child,
        (float(x), float(y), 0.0),
        (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)),
    )


def tf_message(sink: BagSink, *transforms: Any) -> Any:
    """A tf2_msgs/TFMessage of some transforms."""
    return sink.types["tf2_msgs/msg/TFMessage"](transforms=list(transforms))


def _camera_static_tf(sink: BagSink, stamp_ns: int, camera: Camera) -> Any:
    half = math.radians(-camera.tilt_deg) / 2  # rotation about y, see Camera.R_base_link
    return tf_message(
        sink,
        transform_stamped(
            sink,
            TF_STATIC_TOPIC,
            stamp_ns,
            BASE_FRAME,
            CAMERA_LINK_FRAME,
            camera.mount_xyz,
            (0.0, math.sin(half), 0.0, math.cos(half)),
        ),
        transform_stamped(
            sink,
            TF_STATIC_TOPIC,
            stamp_ns,
            CAMERA_LINK_FRAME,
            OPTICAL_FRAME,
            (0.0, 0.0, 0.0),
            OPTICAL_QUATERNION,
        ),
    )


def _laser_static_tf(sink: BagSink, stamp_ns: int, scanner: Scanner) -> Any:
    return tf_message(
        sink,
        transform_stamped(
            sink,
            TF_STATIC_TOPIC,
            stamp_ns,
            BASE_FRAME,
            LASER_FRAME,
            scanner.mount_xyz,
            (0.0, 0.0, 0.0, 1.0),
        ),
    )


def _pose(sink: BagSink, x: float, y: float, yaw: float) -> Any:
    t = sink.types
    return t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
        orientation=_yaw_quaternion(sink, yaw),
    )


def _odometry(
    sink: BagSink, stamp_ns: int, pose: tuple[float, float, float], twist: np.ndarray
) -> Any:
    t = sink.types
    # Planar odometry: tight in x, y, yaw; the unused dimensions get a huge variance.
    covariance = np.diag([1e-4, 1e-4, 1e6, 1e6, 1e6, 1e-3]).ravel()
    return t["nav_msgs/msg/Odometry"](
        header=sink.header(ODOM_TOPIC, stamp_ns, ODOM_FRAME),
        child_frame_id=BASE_FRAME,
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=_pose(sink, *pose), covariance=covariance
        ),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=t["geometry_msgs/msg/Vector3"](x=twist[0], y=twist[1], z=0.0),
                angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=twist[2]),
            ),
            covariance=covariance.copy(),
        ),
    )


def _amcl_pose(sink: BagSink, stamp_ns: int, pose: tuple[float, float, float]) -> Any:
    t = sink.types
    return t["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=sink.header(AMCL_POSE_TOPIC, stamp_ns, MAP_FRAME),
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=_pose(sink, *pose), covariance=AMCL_COVARIANCE.copy()
        ),
    )


def _ground_truth(sink: BagSink, stamp_ns: int, pose: tuple[float, float, float]) -> Any:
    return sink.types["geometry_msgs/msg/PoseStamped"](
        header=sink.header(GROUND_TRUTH_TOPIC, stamp_ns, MAP_FRAME), pose=_pose(sink, *pose)
    )


def _body_twist(odom: Trajectory) -> np.ndarray:
    """Velocities (N, 3): forward, left, yaw rate, in base_link, by central differences."""
    vx = np.gradient(odom.x, odom.stamps)
    vy = np.gradient(odom.y, odom.stamps)
    yaw_rate = np.gradient(np.unwrap(odom.yaw), odom.stamps)
    forward, left = se2.unrotate((vx, vy), odom.yaw)
    return np.stack([forward, left, yaw_rate], axis=1)


def _point_cloud(sink: BagSink, stamp_ns: int, depth: np.ndarray, camera: Camera) -> Any:
    t = sink.types
    cloud = np.zeros(depth.size, dtype=CLOUD_DTYPE)
    points = depth_to_points(depth, camera).reshape(-1, 3)
    cloud["x"], cloud["y"], cloud["z"] = points.T
    # Grey by distance, packed as 0x00RRGGBB in the float's bits like PCL does.
    grey = np.nan_to_num(255 - 200 * depth.ravel() / camera.max_range).astype(np.uint32)
    cloud["rgb"] = (grey * 0x010101).view(np.float32)
    return t["sensor_msgs/msg/PointCloud2"](
        header=sink.header(POINTS_TOPIC, stamp_ns, OPTICAL_FRAME),
        height=camera.height,
        width=camera.width,
        fields=[
            t["sensor_msgs/msg/PointField"](name=name, offset=offset, datatype=_FLOAT32, count=1)
            for name, offset in (("x", 0), ("y", 4), ("z", 8), ("rgb", 16))
        ],
        is_bigendian=False,
        point_step=CLOUD_DTYPE.itemsize,
        row_step=CLOUD_DTYPE.itemsize * camera.width,
        data=cloud.view(np.uint8),
        is_dense=False,
    )


def depth_image(
    sink: BagSink,
    stamp_ns: int,
    depth: np.ndarray,
    camera: Camera,
    sensor: SensorKind,
    frame: str = OPTICAL_FRAME,
) -> Any:
    """A depth sensor_msgs/Image (16UC1 millimetres, or 32FC1 metres) of depths in metres."""
    if sensor == "depth16":
        millimetres = np.clip(np.nan_to_num(np.round(depth * 1000.0)), 0, 65535)
        pixels, encoding = millimetres.astype("<u2"), "16UC1"
    else:
        pixels, encoding = depth.astype("<f4"), "32FC1"
    return sink.types["sensor_msgs/msg/Image"](
        header=sink.header(IMAGE_TOPIC, stamp_ns, frame),
        height=camera.height,
        width=camera.width,
        encoding=encoding,
        is_bigendian=0,
        step=pixels.itemsize * camera.width,
        data=pixels.reshape(-1).view(np.uint8),
    )


def _laser_scan(
    sink: BagSink, stamp_ns: int, ranges: np.ndarray, scanner: Scanner, rate_hz: float
) -> Any:
    # REP 117: +inf is "nothing within range"; the renderer's NaN means just that here.
    return sink.types["sensor_msgs/msg/LaserScan"](
        header=sink.header(SCAN_TOPIC, stamp_ns, LASER_FRAME),
        angle_min=scanner.angle_min,
        angle_max=scanner.angle_max,
        angle_increment=scanner.angle_increment,
        time_increment=0.0,  # all beams at the header stamp: the scan is not skewed
        scan_time=1.0 / rate_hz,
        range_min=scanner.range_min,
        range_max=scanner.range_max,
        ranges=np.where(np.isnan(ranges), np.inf, ranges).astype(np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


def camera_info(sink: BagSink, stamp_ns: int, camera: Camera, frame: str = OPTICAL_FRAME) -> Any:
    """The sensor_msgs/CameraInfo of a pinhole camera without distortion."""
    t = sink.types
    projection = np.hstack([camera.K, np.zeros((3, 1))]).ravel()
    # ROS 1 spells the matrices in capitals, ROS 2 in lower case.
    names = ("D", "K", "R", "P") if sink.ros1 else ("d", "k", "r", "p")
    matrices = (np.zeros(5), camera.K.ravel(), np.eye(3).ravel(), projection)
    return t["sensor_msgs/msg/CameraInfo"](
        header=sink.header(CAMERA_INFO_TOPIC, stamp_ns, frame),
        height=camera.height,
        width=camera.width,
        distortion_model="plumb_bob",
        **dict(zip(names, matrices, strict=True)),
        binning_x=0,
        binning_y=0,
        roi=t["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )


def _pose_sources(
    fine: Trajectory,
    seed: int,
    drift: tuple[float, float],
    faults: PoseFaults | None,
    map_in_world: tuple[float, float, float],
) -> tuple[Trajectory, Trajectory]:
    """What the bag's pose sources say of the true drive ``fine``: (poses, odometry).

    The odometry drifts from the true first pose; the poses are the truth, or the truth as a
    source with ``faults`` has it (and so is the odometry then). Both in the map frame placed
    at ``map_in_world`` in the plan's frame, as a robot whose map starts where it was switched
    on has them; a rigid move changes neither the drift nor the faults. The identity leaves
    them bit for bit as they are, so bags in the plan's frame stay the same.
    """
    odom = drifting_odometry(fine, seed, drift_xy=drift[0], drift_yaw_deg=drift[1])
    posed = fine
    if faults is not None and faults.any:
        posed, odom = faults.apply(fine), faults.apply(odom)
    if map_in_world == (0.0, 0.0, 0.0):
        return posed, odom
    return posed.relative_to(map_in_world), odom.relative_to(map_in_world)


@dataclass(frozen=True, eq=False)
class _Drive:
    """A scene's drive as its bag records it, sampled at twice the sensor rate.

    Even samples are sensor frames, odd ones the extra odom → base_link transforms between them.

    Attributes:
        fine: The true poses, in the plan's frame.
        posed: What the bag's pose sources say: the truth, or the truth as a faulty source has
            it; in the bag's map frame.
        odom: The drifting odometry, in the bag's map frame.
        twist: The odometry's body velocities (N, 3), for /odom.
        stamps_ns: Every sample's stamp.
        map_in_world: Where the bag's map frame lies in the plan's frame.
        faulty: Whether ``posed`` has faults.
    """

    fine: Trajectory
    posed: Trajectory
    odom: Trajectory
    twist: np.ndarray
    stamps_ns: list[int]
    map_in_world: tuple[float, float, float]
    faulty: bool

    @property
    def map_odom_every(self) -> int:
        """Samples from one map → odom transform to the next.

        Every sample with faults, so that map → base_link is the faulty pose at each stamp, not
        an interpolation across a glitch.
        """
        return 1 if self.faulty else _MAP_ODOM_EVERY


def _true_drive(
    plan: FloorPlan, seed: int, *, n_frames: int, rate_hz: float, reverse: bool
) -> Trajectory:
    """The true drive at twice the sensor rate, cut to ``n_frames`` sensor frames at most.

    Raises:
        ValueError: If ``n_frames`` is not positive.
    """
    if n_frames < 1:
        raise ValueError("n_frames must be positive")
    fine = generate_trajectory(plan, seed, rate_hz=2 * rate_hz, reverse=reverse)
    n_frames = min(n_frames, (len(fine) + 1) // 2)
    return fine.sliced(slice(0, 2 * n_frames - 1))


def _as_recorded(
    fine: Trajectory,
    seed: int,
    *,
    drift: tuple[float, float],
    faults: PoseFaults | None,
    own_frame: bool,
) -> _Drive:
    """The true drive ``fine`` with what the bag's pose sources say of it (``_pose_sources``)."""
    map_in_world = fine.pose_at(0) if own_frame else (0.0, 0.0, 0.0)
    posed, odom = _pose_sources(fine, seed, drift, faults, map_in_world)
    return _Drive(
        fine=fine,
        posed=posed,
        odom=odom,
        twist=_body_twist(odom),
        stamps_ns=[stamp_to_ns(s) for s in fine.stamps],
        map_in_world=map_in_world,
        faulty=faults is not None and faults.any,
    )


_Pose = tuple[float, float, float]  # x, y, yaw
_TopicList = tuple[tuple[str, str], ...]  # (name, message type), in opening order
_Outputs = tuple[Connection, ...]  # a sensor's connections, in its topics' order


@dataclass(frozen=True, eq=False)
class _Sensor(ABC):
    """A bag's sensor: what it sees of the plan, its topics and how it writes a frame.

    One subclass a kind of sensor, chosen once (:func:`_sensor_for`); the poses, tf and truth
    around its frames are the same for every kind.

    Attributes:
        kind: The sensor kind, as the truth file names it.
        plan: The scene it sees.
        rate_hz: Its frame rate.
        rng: Its noise.
    """

    kind: SensorKind
    plan: FloorPlan
    rate_hz: float
    rng: np.random.Generator
    topics: ClassVar[_TopicList]

    @abstractmethod
    def truth_mount(self) -> dict[str, Any]:
        """The sensor and its mount, for the truth file."""

    @abstractmethod
    def static_tf(self, sink: BagSink, stamp_ns: int) -> Any:
        """The /tf_static message: where the sensor sits on base_link."""

    @abstractmethod
    def write_frame(self, sink: BagSink, out: _Outputs, stamp_ns: int, pose: _Pose) -> set[int]:
        """Render, and write to ``out`` (its ``topics``), what it sees from ``pose``.

        Returns:
            The walls the detector could see in the frame.
        """


@dataclass(frozen=True, eq=False)
class _ScanSensor(_Sensor):
    """A 2-D laser scanner: /scan."""

    scanner: Scanner
    topics: ClassVar[_TopicList] = ((SCAN_TOPIC, "sensor_msgs/msg/LaserScan"),)

    def truth_mount(self) -> dict[str, Any]:
        """The scanner, for the truth file."""
        return {"scanner": self.scanner.to_json()}

    def static_tf(self, sink: BagSink, stamp_ns: int) -> Any:
        """base_link → laser."""
        return _laser_static_tf(sink, stamp_ns, self.scanner)

    def write_frame(self, sink: BagSink, out: _Outputs, stamp_ns: int, pose: _Pose) -> set[int]:
        """One LaserScan."""
        ranges, hit_wall = render_scan(self.plan, *pose, self.scanner, self.rng)
        scan = _laser_scan(sink, stamp_ns, ranges, self.scanner, self.rate_hz)
        sink.write(out[0], stamp_ns, scan)
        return scan_walls_seen(hit_wall, ranges)


@dataclass(frozen=True, eq=False)
class _CameraSensor(_Sensor, ABC):
    """A depth camera: its mount and its rendering, whichever way it publishes a depth image."""

    camera: Camera

    def truth_mount(self) -> dict[str, Any]:
        """The camera, for the truth file."""
        return {"camera": self.camera.to_json()}

    def static_tf(self, sink: BagSink, stamp_ns: int) -> Any:
        """base_link → camera_link → camera_optical_frame."""
        return _camera_static_tf(sink, stamp_ns, self.camera)

    def write_frame(self, sink: BagSink, out: _Outputs, stamp_ns: int, pose: _Pose) -> set[int]:
        """One depth image, published the subclass's way."""
        depth, hit_wall = render_depth(self.plan, *pose, self.camera, self.rng)
        self.publish(sink, out, stamp_ns, depth)
        return walls_seen(hit_wall, depth, self.camera)

    @abstractmethod
    def publish(self, sink: BagSink, out: _Outputs, stamp_ns: int, depth: np.ndarray) -> None:
        """Write one depth image (metres, NaN for no return) to the camera's topics."""


@dataclass(frozen=True, eq=False)
class _CloudSensor(_CameraSensor):
    """A depth camera publishing organized point clouds: /camera/depth/points."""

    topics: ClassVar[_TopicList] = ((POINTS_TOPIC, "sensor_msgs/msg/PointCloud2"),)

    def publish(self, sink: BagSink, out: _Outputs, stamp_ns: int, depth: np.ndarray) -> None:
        """One PointCloud2."""
        sink.write(out[0], stamp_ns, _point_cloud(sink, stamp_ns, depth, self.camera))


@dataclass(frozen=True, eq=False)
class _ImageSensor(_CameraSensor):
    """A depth camera publishing images (``kind`` says 16UC1 or 32FC1) and their camera info."""

    topics: ClassVar[_TopicList] = (
        (IMAGE_TOPIC, "sensor_msgs/msg/Image"),
        (CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo"),
    )

    def publish(self, sink: BagSink, out: _Outputs, stamp_ns: int, depth: np.ndarray) -> None:
        """One Image and its CameraInfo."""
        image_conn, info_conn = out
        image = depth_image(sink, stamp_ns, depth, self.camera, self.kind)
        sink.write(image_conn, stamp_ns, image)
        sink.write(info_conn, stamp_ns, camera_info(sink, stamp_ns, self.camera))


def _sensor_for(
    kind: SensorKind,
    *,
    plan: FloorPlan,
    rate_hz: float,
    rng: np.random.Generator,
    camera: Camera | None,
    scanner: Scanner | None,
) -> _Sensor:
    """The sensor of ``kind``, with the default camera or scanner if none is given."""
    if kind == "laserscan":
        scanner = Scanner() if scanner is None else scanner
        return _ScanSensor(kind=kind, plan=plan, rate_hz=rate_hz, rng=rng, scanner=scanner)
    camera = Camera() if camera is None else camera
    sensor = _CloudSensor if kind == "pointcloud" else _ImageSensor
    return sensor(kind=kind, plan=plan, rate_hz=rate_hz, rng=rng, camera=camera)


@dataclass(frozen=True)
class _Topics:
    """The connections of a scene bag; ``sensor`` are the sensor's own, in its order."""

    tf_static: Connection
    tf: Connection
    odom: Connection
    ground_truth: Connection
    sensor: _Outputs
    amcl: Connection


def _open_topics(sink: BagSink, sensor_topics: _TopicList) -> _Topics:
    """Every topic of a scene bag, opened in the order (the arguments') that gives each its id."""
    return _Topics(
        tf_static=sink.topic(TF_STATIC_TOPIC, "tf2_msgs/msg/TFMessage", latched=True),
        tf=sink.topic(TF_TOPIC, "tf2_msgs/msg/TFMessage"),
        odom=sink.topic(ODOM_TOPIC, "nav_msgs/msg/Odometry"),
        ground_truth=sink.topic(GROUND_TRUTH_TOPIC, "geometry_msgs/msg/PoseStamped"),
        sensor=tuple(sink.topic(name, msgtype) for name, msgtype in sensor_topics),
        # Opened last so that the other topics keep the connection ids they always had.
        amcl=sink.topic(AMCL_POSE_TOPIC, "geometry_msgs/msg/PoseWithCovarianceStamped"),
    )


def _write_tf(sink: BagSink, tf: Connection, drive: _Drive, k: int) -> None:
    """Sample ``k``'s odom → base_link, and the map → odom that makes the chain the bag's pose.

    map → odom is written every ``map_odom_every`` samples and at the last one.
    """
    stamp_ns = drive.stamps_ns[k]
    odom_pose = se2.matrix(drive.odom.pose_at(k))
    if k % drive.map_odom_every == 0 or k == len(drive.stamps_ns) - 1:
        map_odom = se2.matrix(drive.posed.pose_at(k)) @ np.linalg.inv(odom_pose)
        msg = _planar_transform(sink, stamp_ns, MAP_FRAME, ODOM_FRAME, map_odom)
        sink.write(tf, stamp_ns, tf_message(sink, msg))
    msg = _planar_transform(sink, stamp_ns, ODOM_FRAME, BASE_FRAME, odom_pose)
    sink.write(tf, stamp_ns, tf_message(sink, msg))


def _write_poses(sink: BagSink, topics: _Topics, drive: _Drive, k: int) -> None:
    """Sensor frame ``k``'s /odom, /ground_truth and /amcl_pose."""
    stamp_ns = drive.stamps_ns[k]
    odometry = _odometry(sink, stamp_ns, drive.odom.pose_at(k), drive.twist[k])
    sink.write(topics.odom, stamp_ns, odometry)
    given = drive.posed.pose_at(k)
    sink.write(topics.ground_truth, stamp_ns, _ground_truth(sink, stamp_ns, given))
    sink.write(topics.amcl, stamp_ns, _amcl_pose(sink, stamp_ns, given))


def _write_frames(sink: BagSink, drive: _Drive, sensor: _Sensor) -> dict[int, int]:
    """The whole drive: the mount, every sample's tf and every sensor frame's poses and data.

    Returns:
        Per wall id, the number of frames in which the detector could see it.
    """
    topics = _open_topics(sink, sensor.topics)
    first_ns = drive.stamps_ns[0]
    sink.write(topics.tf_static, first_ns, sensor.static_tf(sink, first_ns))
    seen_counts = {w.id: 0 for w in sensor.plan.walls}
    for k, stamp_ns in enumerate(drive.stamps_ns):
        _write_tf(sink, topics.tf, drive, k)
        if k % 2:
            continue
        _write_poses(sink, topics, drive, k)
        for wall_id in sensor.write_frame(sink, topics.sensor, stamp_ns, drive.fine.pose_at(k)):
            seen_counts[wall_id] += 1
    return seen_counts


def _write_truth(
    path: Path,
    *,
    seed: int,
    fmt: BagFormat,
    sensor: _Sensor,
    drive: _Drive,
    seen_counts: dict[int, int],
    reverse: bool,
) -> SceneInfo:
    """``<path>.truth.json`` beside the bag, and what was written."""
    truth = drive.fine.sliced(slice(None, None, 2))
    truth_path = truth_path_for(path)
    truth_path.write_text(
        json.dumps(
            {
                "seed": seed,
                "format": fmt,
                "sensor": sensor.kind,
                "rate_hz": sensor.rate_hz,
                "n_frames": len(truth),
                **sensor.truth_mount(),
                "plan": sensor.plan.to_json(),
                "trajectory": truth.to_json(),
                "stamps_ns": drive.stamps_ns[::2],
                "seen_counts": {str(k): v for k, v in seen_counts.items()},
                "reverse": reverse,
                "map_in_world": list(drive.map_in_world),
            }
        )
    )
    return SceneInfo(
        path=path,
        truth_path=truth_path,
        n_frames=len(truth),
        plan=sensor.plan,
        trajectory=truth,
        seen_counts=seen_counts,
        map_in_world=drive.map_in_world,
    )


def write_scene_bag(
    path: str | Path,
    *,
    seed: int,
    n_frames: int,
    fmt: BagFormat,
    sensor: SensorKind,
    camera: Camera | None = None,
    scanner: Scanner | None = None,
    plan: FloorPlan | None = None,
    rate_hz: float = 15.0,
    compress: bool = False,
    odometry_drift: tuple[float, float] = (0.02, 1.0),
    faults: PoseFaults | None = None,
    reverse: bool = False,
    own_frame: bool = False,
) -> SceneInfo:
    """Drive through a scene and record it as a bag, plus ``<path>.truth.json``.

    The bag's topics are in the module's docstring.

    Args:
        path: Bag to create: a file for ROS 1, a folder for ROS 2; must not exist.
        seed: Seed of everything: the plan (unless ``plan`` is given), the trajectory, the
            odometry drift and the sensor noise.
        n_frames: Sensor frames to write; fewer if the route ends first.
        fmt: Bag format.
        sensor: What the sensor publishes: a depth camera's cloud or image, or a scan.
        camera: Depth camera and mount, but for ``laserscan``; 160 x 120 Kinect-like if None.
        scanner: Laser scanner and mount, only for ``laserscan``; :class:`Scanner` if None.
        plan: Scene to drive through (it must have a route); ``generate_floorplan(seed)`` if None.
        rate_hz: Sensor frame rate.
        compress: LZ4 chunk compression (ROS 1 only), for bags that ship in a repository.
        odometry_drift: /odom's error per metre: of position (0.02 = 2 %), of heading (degrees).
        faults: How every pose source of the bag errs (``pose_faults``); the faulty poses also
            go to ``<path>.poses.tum``, and the truth file keeps the true trajectory.
        reverse: Drive the plan's route from its end to its start: another robot's drive.
        own_frame: Every pose of the bag in a map frame at the robot's true first pose, as a
            fleet robot's own map; the truth stays in the plan's frame, with ``map_in_world``.

    Returns:
        What was written, including the per-wall seen counts.

    Raises:
        ValueError: If ``n_frames`` is not positive.
    """
    path = Path(path)
    plan = generate_floorplan(seed) if plan is None else plan
    traj_seed, odom_seed, noise_seed = sub_seeds(seed, 3)
    fine = _true_drive(plan, traj_seed, n_frames=n_frames, rate_hz=rate_hz, reverse=reverse)
    drive = _as_recorded(fine, odom_seed, drift=odometry_drift, faults=faults, own_frame=own_frame)
    if drive.faulty:
        write_tum(drive.posed, tum_path_for(path))
    rng = np.random.default_rng(noise_seed)
    eye = _sensor_for(sensor, plan=plan, rate_hz=rate_hz, rng=rng, camera=camera, scanner=scanner)
    with BagSink(path, fmt, compress=compress) as sink:
        seen_counts = _write_frames(sink, drive, eye)
    return _write_truth(
        path, seed=seed, fmt=fmt, sensor=eye, drive=drive, seen_counts=seen_counts, reverse=reverse
    )


def load_truth(truth_path: str | Path) -> tuple[FloorPlan, Trajectory, dict[int, int]]:
    """Plan, true trajectory at the sensor stamps and per-wall seen counts of a scene."""
    data = json.loads(Path(truth_path).read_text())
    seen = {int(k): int(v) for k, v in data["seen_counts"].items()}
    return FloorPlan.from_json(data["plan"]), Trajectory.from_json(data["trajectory"]), seen


def load_map_in_world(truth_path: str | Path) -> tuple[float, float, float]:
    """Where a scene bag's map frame lies in its plan's frame: ``(x, y, yaw)``.

    The transform T with ``world_point = T * map_point``: a map made from the bag, moved by it,
    can be scored against the plan. The identity for bags whose poses are in the plan's frame,
    which older truth files (without the key) all are.
    """
    data = json.loads(Path(truth_path).read_text())
    x, y, yaw = data.get("map_in_world", (0.0, 0.0, 0.0))
    return float(x), float(y), float(yaw)
