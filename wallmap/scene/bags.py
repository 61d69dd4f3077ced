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
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

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

    Topics: /tf_static (base_link → camera_link → camera_optical_frame for the camera,
    base_link → laser for the scanner), /tf (odom → base_link at the sensor stamps and
    midway between them, map → odom at 2/3 of the sensor rate), /odom (drifting odometry at
    sensor stamps), /ground_truth (true pose in map), /amcl_pose (the true pose again, with
    a 2 cm / 1 degree covariance, as from a localiser), and the sensor data: either
    /camera/depth/points (organized PointCloud2, fields x, y, z, rgb, point_step 32, NaN for
    no return), /camera/depth/image_raw (16UC1 millimetres with 0 for no return, or 32FC1
    metres with NaN) with /camera/depth/camera_info, or /scan (LaserScan in frame laser,
    +inf for no return). Header stamps and bag times are the trajectory stamps.
    ``map → odom ∘ odom → base_link``, interpolated at a sensor stamp, is the true pose to
    well under 1 mm.

    Args:
        path: Bag to create: a file for ROS 1, a folder for ROS 2; must not exist.
        seed: Seed of everything: the plan (``generate_floorplan(seed)`` unless ``plan``
            is given), the trajectory, the odometry drift and the sensor noise.
        n_frames: Sensor frames to write; fewer if the route ends first.
        fmt: Bag format.
        sensor: What the sensor publishes: a depth camera's cloud or image, or a scan.
        camera: Depth camera and mount (not used for ``laserscan``); the default is a
            160 x 120 Kinect-like camera.
        scanner: Laser scanner and mount (used only for ``laserscan``); default
            :class:`Scanner`.
        plan: Scene to drive through (must have a route); generated if None.
        rate_hz: Sensor frame rate.
        compress: LZ4 chunk compression (ROS 1 only), for bags that ship in a repository.
        odometry_drift: How /odom drifts: its position error per metre (0.02 = 2 %) and its
            heading error in degrees per metre (``drifting_odometry``).
        faults: How every pose source of the bag errs (``pose_faults``): tf ``map -> odom`` is
            then written at every odom -> base_link stamp so that ``map -> base_link`` is the
            faulty pose, /odom, /ground_truth and /amcl_pose carry the faults too, and the
            faulty poses are also written as a TUM file, ``<path>.poses.tum``. The truth file
            keeps the true trajectory.
        reverse: Drive the plan's route the other way, from its last waypoint to its first
            (``generate_trajectory``): another robot's drive through the same building.
        own_frame: Give every pose of the bag (tf ``map -> odom`` and ``odom -> base_link``,
            /odom, /ground_truth, /amcl_pose, the TUM file) in a map frame at the robot's true
            first pose, as a robot of a fleet has its own map; the first ground-truth pose is
            then (0, 0, 0). The sensor data are the same, and the truth file keeps the plan and
            the trajectory in the plan's frame and says where the map frame lies in it
            (``map_in_world``, read by :func:`load_map_in_world`): score a map of the bag
            after moving it by that.

    Returns:
        What was written, including the per-wall seen counts.

    Raises:
        ValueError: If ``n_frames`` is not positive.
    """
    if n_frames < 1:
        raise ValueError("n_frames must be positive")
    path = Path(path)
    laser = sensor == "laserscan"
    camera = Camera() if camera is None else camera
    scanner = Scanner() if scanner is None else scanner
    plan = generate_floorplan(seed) if plan is None else plan
    traj_seed, odom_seed, noise_seed = sub_seeds(seed, 3)

    # Sampled at twice the sensor rate: even samples are sensor frames, odd ones are the
    # extra odom → base_link transforms between them.
    fine = generate_trajectory(plan, traj_seed, rate_hz=2 * rate_hz, reverse=reverse)
    n_frames = min(n_frames, (len(fine) + 1) // 2)
    fine = fine.sliced(slice(0, 2 * n_frames - 1))  # true poses in the plan's frame
    truth = fine.sliced(slice(None, None, 2))
    map_in_world = fine.pose_at(0) if own_frame else (0.0, 0.0, 0.0)
    # What the bag says: the truth, or the truth as a faulty source has it; in the bag's map.
    posed, odom = _pose_sources(fine, odom_seed, odometry_drift, faults, map_in_world)
    faulty = faults is not None and faults.any
    if faulty:
        write_tum(posed, tum_path_for(path))
    every_map_odom = 1 if faulty else _MAP_ODOM_EVERY
    twist = _body_twist(odom)
    stamps_ns = [stamp_to_ns(s) for s in fine.stamps]
    rng = np.random.default_rng(noise_seed)
    seen_counts = {w.id: 0 for w in plan.walls}

    with BagSink(path, fmt, compress=compress) as sink:
        tf_static = sink.topic(TF_STATIC_TOPIC, "tf2_msgs/msg/TFMessage", latched=True)
        tf = sink.topic(TF_TOPIC, "tf2_msgs/msg/TFMessage")
        odom_conn = sink.topic(ODOM_TOPIC, "nav_msgs/msg/Odometry")
        truth_conn = sink.topic(GROUND_TRUTH_TOPIC, "geometry_msgs/msg/PoseStamped")
        if laser:
            sensor_conn = sink.topic(SCAN_TOPIC, "sensor_msgs/msg/LaserScan")
        elif sensor == "pointcloud":
            sensor_conn = sink.topic(POINTS_TOPIC, "sensor_msgs/msg/PointCloud2")
        else:
            sensor_conn = sink.topic(IMAGE_TOPIC, "sensor_msgs/msg/Image")
            info_conn = sink.topic(CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo")
        # Opened last so that the other topics keep the connection ids they always had.
        amcl_conn = sink.topic(AMCL_POSE_TOPIC, "geometry_msgs/msg/PoseWithCovarianceStamped")

        if laser:
            static = _laser_static_tf(sink, stamps_ns[0], scanner)
        else:
            static = _camera_static_tf(sink, stamps_ns[0], camera)
        sink.write(tf_static, stamps_ns[0], static)
        for k, stamp_ns in enumerate(stamps_ns):
            odom_pose = se2.matrix(odom.pose_at(k))
            if k % every_map_odom == 0 or k == len(stamps_ns) - 1:
                map_odom = se2.matrix(posed.pose_at(k)) @ np.linalg.inv(odom_pose)
                msg = _planar_transform(sink, stamp_ns, MAP_FRAME, ODOM_FRAME, map_odom)
                sink.write(tf, stamp_ns, tf_message(sink, msg))
            msg = _planar_transform(sink, stamp_ns, ODOM_FRAME, BASE_FRAME, odom_pose)
            sink.write(tf, stamp_ns, tf_message(sink, msg))
            if k % 2:
                continue

            pose, given = fine.pose_at(k), posed.pose_at(k)
            sink.write(odom_conn, stamp_ns, _odometry(sink, stamp_ns, odom.pose_at(k), twist[k]))
            sink.write(
                truth_conn,
                stamp_ns,
                sink.types["geometry_msgs/msg/PoseStamped"](
                    header=sink.header(GROUND_TRUTH_TOPIC, stamp_ns, MAP_FRAME),
                    pose=_pose(sink, *given),
                ),
            )
            sink.write(amcl_conn, stamp_ns, _amcl_pose(sink, stamp_ns, given))
            if laser:
                ranges, hit_wall = render_scan(plan, *pose, scanner, rng)
                seen = scan_walls_seen(hit_wall, ranges)
                scan = _laser_scan(sink, stamp_ns, ranges, scanner, rate_hz)
                sink.write(sensor_conn, stamp_ns, scan)
            else:
                depth, hit_wall = render_depth(plan, *pose, camera, rng)
                seen = walls_seen(hit_wall, depth, camera)
                if sensor == "pointcloud":
                    cloud = _point_cloud(sink, stamp_ns, depth, camera)
                    sink.write(sensor_conn, stamp_ns, cloud)
                else:
                    image = depth_image(sink, stamp_ns, depth, camera, sensor)
                    sink.write(sensor_conn, stamp_ns, image)
                    sink.write(info_conn, stamp_ns, camera_info(sink, stamp_ns, camera))
            for wall_id in seen:
                seen_counts[wall_id] += 1

    mount = {"scanner": scanner.to_json()} if laser else {"camera": camera.to_json()}
    truth_path = truth_path_for(path)
    truth_path.write_text(
        json.dumps(
            {
                "seed": seed,
                "format": fmt,
                "sensor": sensor,
                "rate_hz": rate_hz,
                "n_frames": n_frames,
                **mount,
                "plan": plan.to_json(),
                "trajectory": truth.to_json(),
                "stamps_ns": stamps_ns[::2],
                "seen_counts": {str(k): v for k, v in seen_counts.items()},
                "reverse": reverse,
                "map_in_world": list(map_in_world),
            }
        )
    )
    return SceneInfo(path, truth_path, n_frames, plan, truth, seen_counts, map_in_world)


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
