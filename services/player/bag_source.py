"""Read a ROS 1 or ROS 2 bag into sensor frames and robot poses for the player to publish.

Opening a bag does everything that can fail up front (format, sensor topic choice, pose source,
tf mounting), so a user sees one clear error before any frame is published. ``frames()`` then
streams the sensor topic in bag order, decoding each message into an organized xyz grid with its
mounting transform and the robot pose interpolated at the message's stamp.
"""

import dataclasses
import math
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection
from rosbags.typesys import Stores, get_typestore

from wallmap.common.messages import Pose
from wallmap.common.ros_poses import (
    DEFAULT_CHILD,
    header_stamp,
    pose_from_matrix,
    pose_from_message,
)
from wallmap.common.scan_row import RowSelection
from wallmap.common.tf_buffer import TfBuffer, TfError, normalize_frame
from wallmap.services.player.depth import SUPPORTED_ENCODINGS, depth_image_to_xyz
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.frames import ClosingSource, SensorFrame, hand_out
from wallmap.services.player.laserscan import laserscan_to_xyz
from wallmap.services.player.mapped_bag import mapped_messages
from wallmap.services.player.placement import (
    SURVEY_FRAMES,
    LevelMode,
    Placement,
    Sample,
    survey,
    unlevelled,
)
from wallmap.services.player.pointcloud import invalid_to_nan, pointcloud2_xyz
from wallmap.services.player.pose_sources import (
    PoseSourceSpec,
    PoseTrack,
    load_tum,
    parse_pose_source,
    resolve_pose_topic,
)

__all__ = ["BagSource", "SensorFrame"]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
LASERSCAN = "sensor_msgs/msg/LaserScan"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
# tf2's message, and tf1's older one with the same layout (both renamed to ROS 2 style).
TF_TYPES = frozenset({"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"})
TF_TOPICS = {"tf": False, "tf_static": True}  # normalised topic name -> static
FIXED_FRAMES = ("map", "odom", "world")  # REP-105's fixed frames, most global first
# How far (s) a sensor stamp may lie outside the pose data and still get the end pose.
POSE_TOLERANCE = 0.05
SUPPORTED_SENSORS = (
    f"organized {POINTCLOUD2}, {IMAGE} depth ({'/'.join(SUPPORTED_ENCODINGS)}) with a "
    f"{CAMERA_INFO} topic in the same namespace, {LASERSCAN}"
)
BAG_FORMS = "a ROS 1 .bag file, a ROS 2 bag folder with metadata.yaml, or a ROS 2 .mcap file"

Decoder = Callable[[Any, slice], np.ndarray]  # a message and the rows to decode


def _one_line(err: BaseException) -> str:
    """A library error as one readable line (some rosbags errors have no text)."""
    text = " ".join(str(err).split())
    return text or type(err).__name__


def _unreadable(path: Path, err: BaseException) -> PlayerError:
    """The error for a bag rosbags fails on, with its reason kept as one line.

    Old or interrupted ROS 1 recorders leave bags whose index does not match their chunks (e.g.
    the 2010 demo bag of laser_scan_matcher); ROS 1's own tools repair those, so say how.
    """
    repair = ""
    if path.suffix == ".bag":
        repair = (
            f"; ROS 1 can often repair it: `rosbag reindex {path}` rebuilds a broken index, then "
            f"`rosbag fix {path} fixed.bag` updates old message definitions (e.g. roslib/Header)"
        )
    return PlayerError(
        f"cannot read bag {path}; it looks damaged or was written by an unsupported recorder "
        f"({_one_line(err)}){repair}"
    )


def _check_path(path: Path) -> None:
    """Reject paths rosbags cannot read with a message saying why, before rosbags sees them."""
    if not path.exists():
        raise PlayerError(f"bag not found: {path}")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise PlayerError(f"{path} is a folder without metadata.yaml; expected {BAG_FORMS}")
        return
    try:
        with path.open("rb") as file:
            magic = file.read(16)
    except OSError as err:
        raise PlayerError(f"cannot read bag {path}: {_one_line(err)}") from err
    if magic.startswith(b"#ROSRECORD"):
        raise PlayerError(
            f"{path} is an old '#ROSRECORD V1.x' bag, which cannot be read; convert it to "
            f"format 2.0 with ROS 1's `rosbag fix` first"
        )
    # rosbags picks the format from the file name, so the suffix has to match the contents.
    formats = {b"#ROSBAG V2.0": ".bag", b"\x89MCAP": ".mcap", b"SQLite format 3\x00": ".db3"}
    for prefix, suffix in formats.items():
        if magic.startswith(prefix):
            if path.suffix != suffix:
                raise PlayerError(f"{path} holds a {suffix} bag; rename it to end in {suffix}")
            return
    if magic.startswith(b"#ROSBAG"):
        version = magic.split(b"\n", 1)[0].decode("ascii", "replace")
        raise PlayerError(f"{path} is a {version!r} bag; only ROS 1 bag format 2.0 is supported")
    raise PlayerError(f"{path} is not a ROS bag; expected {BAG_FORMS}")


def _open_reader(path: Path) -> AnyReader:
    """Open a bag with rosbags, turning every failure into a one-line PlayerError."""
    _check_path(path)
    # The default typestore only serves ROS 2 bags recorded without type definitions.
    reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    try:
        reader.open()
    except Exception as err:  # a damaged bag fails in many ways (even AssertionError)
        raise _unreadable(path, err) from err
    return reader


def _namespace(topic: str) -> str:
    """Topic namespace without leading '/': '/camera/depth/image_raw' -> 'camera/depth'."""
    return topic.lstrip("/").rpartition("/")[0]


class BagSource(ClosingSource):
    """Sensor frames and robot poses from one bag, checked and ready when constructed.

    Attributes:
        path: The bag.
        sensor_topic: Sensor topic as spelled in the bag.
        sensor_type: Its message type, e.g. ``sensor_msgs/msg/PointCloud2``.
        pose_spec: The parsed pose source.
        base_frame: Robot frame that poses describe and ``T_base_sensor`` maps into.
        warnings: Assumptions made while opening (e.g. an identity sensor mounting) for the CLI
            to log.
        placement: How frames are placed: the levelled fixed frame, the band the sensor sees.
    """

    def __init__(
        self,
        path: Path,
        *,
        sensor_topic: str | None = None,
        pose_source: str = "tf",
        base_frame: str | None = None,
        topics: Iterable[str] | None = None,
        level: LevelMode = "auto",
        floor_z: float | None = None,
    ) -> None:
        """Open the bag and resolve the sensor topic, pose source and sensor mounting.

        Args:
            path: ROS 1 .bag file, ROS 2 bag folder, or ROS 2 .mcap file.
            sensor_topic: Sensor topic (leading '/' optional); None detects the only candidate.
            pose_source: A ``--pose-source`` spec (see ``parse_pose_source``).
            base_frame: Robot frame; defaults to the pose source's child frame (``base_link``
                for tf, pose, tum and none; the odometry's child frame for odom).
            topics: Read only these topics (leading '/' optional), as ``ros2 bag play --topics``:
                the sensor topic, tf and pose topics are looked for among them.
            level: ``auto`` levels a fixed frame that is not level, from the depth data;
                ``none`` takes it as it is.
            floor_z: The floor's height in the fixed frame, instead of the one found.

        Raises:
            PlayerError: Unreadable bag, no usable (or an ambiguous) sensor topic, a bad pose
                source, or no tf chain from the sensor to the base frame when one is required.
        """
        self.path = Path(path)
        self.pose_spec: PoseSourceSpec = parse_pose_source(pose_source)
        self.warnings: list[str] = []
        self._reader = _open_reader(self.path)
        try:
            self._setup(sensor_topic, base_frame, topics)
            self.placement = self._survey(level, floor_z)
        except BaseException:
            self._reader.close()
            raise

    def _setup(
        self, sensor_topic: str | None, base_frame: str | None, topics: Iterable[str] | None
    ) -> None:
        """Resolve everything ``frames()`` needs; split from __init__ so failures close the bag."""
        self._topics = {
            name: info for name, info in self._reader.topics.items() if info.msgtype is not None
        }
        if topics is not None:
            wanted = {t.lstrip("/") for t in topics}
            unknown = wanted - {name.lstrip("/") for name in self._topics}
            if unknown:
                raise PlayerError(
                    f"--topics names {', '.join(sorted(unknown))}, not in {self.path} "
                    f"(topics: {self._listing()})"
                )
            self._topics = {n: i for n, i in self._topics.items() if n.lstrip("/") in wanted}
        self._first: dict[str, Any] = {}
        self.sensor_topic = self._resolve_sensor(sensor_topic)
        self.sensor_type: str = self._topics[self.sensor_topic].msgtype or ""
        self._tf = TfBuffer()
        self._track: PoseTrack | None = None
        # Poses from pose/tum sources (and odometry without a child frame) describe the base.
        camera_info = self._load_first_pass(
            normalize_frame(base_frame) if base_frame else DEFAULT_CHILD
        )
        self._decode = self._decoder(camera_info)
        if base_frame is None:
            self._find_moving_frame()

        track = self._track
        self._compose_track = False
        if base_frame is not None:
            self.base_frame = normalize_frame(base_frame)
        elif self.pose_spec.kind == "tf":
            self.base_frame = self.pose_spec.child
        else:
            self.base_frame = track.child if track is not None else DEFAULT_CHILD
        if self.pose_spec.kind == "tf" and not self._tf.has_path(
            self.pose_spec.parent, self.base_frame
        ):
            reason = (
                self._tf.no_path_message(self.pose_spec.parent, self.base_frame)
                if self._tf
                else "the bag has no /tf or /tf_static"
            )
            raise PlayerError(
                f"pose source tf:{self.pose_spec.parent}>{self.base_frame}: {reason}; choose "
                f"another --pose-source (odom, pose, tum:FILE or none)"
            )
        if track is not None and track.child != self.base_frame:
            # Odometry names its own child frame; bridge it to the chosen base frame via tf.
            if self._tf.has_path(track.child, self.base_frame):
                self._compose_track = True
            else:
                self.warnings.append(
                    f"no tf between the pose source's frame {track.child!r} and base frame "
                    f"{self.base_frame!r}: its poses are used as {self.base_frame!r} poses"
                )
                self._track = dataclasses.replace(track, child=self.base_frame)

        # Decide the sensor mounting now so a missing tf link fails before any frame is sent.
        frame_id = normalize_frame(self._first_message(self.sensor_topic).header.frame_id)
        self._mounts: dict[str, np.ndarray | None] = {frame_id: self._mount_policy(frame_id)}
        self._first.clear()  # detection's first messages (whole clouds) are not needed again

    # --- sensor topic -------------------------------------------------------------------------

    def _find_topic(self, name: str) -> str | None:
        """The bag's spelling of a topic, matching with or without the leading '/'."""
        wanted = name.lstrip("/")
        return next((t for t in self._topics if t.lstrip("/") == wanted), None)

    def _listing(self) -> str:
        return ", ".join(f"{n} ({i.msgtype})" for n, i in sorted(self._topics.items())) or "none"

    def _first_message(self, topic: str) -> Any:
        """Deserialize a topic's first message (cached); None if it has none."""
        if topic not in self._first:
            stream = self._messages(self._topics[topic].connections)
            item = next(stream, None)
            stream.close()
            self._first[topic] = None if item is None else item[2]
        return self._first[topic]

    def _camera_info_topic(self, image_topic: str) -> str | None:
        """The CameraInfo topic beside a depth image topic (same namespace), if any."""
        namespace = _namespace(image_topic)
        return next(
            (
                name
                for name, info in sorted(self._topics.items())
                if info.msgtype == CAMERA_INFO and _namespace(name) == namespace
            ),
            None,
        )

    def _rejection(self, topic: str) -> str | None:
        """Why a topic cannot be the sensor, or None if it can."""
        msgtype = self._topics[topic].msgtype
        if msgtype not in {POINTCLOUD2, IMAGE, LASERSCAN}:
            return f"{msgtype} is not a supported sensor type"
        first = self._first_message(topic)
        if first is None:
            return "it has no messages"
        if msgtype == POINTCLOUD2 and first.height <= 1:
            return (
                f"it is an unorganized PointCloud2 (height {first.height}, width {first.width}); "
                f"the detector needs organized rows"
            )
        if msgtype == IMAGE:
            if first.encoding not in SUPPORTED_ENCODINGS:
                return (
                    f"its encoding {first.encoding!r} is not a depth encoding "
                    f"({'/'.join(SUPPORTED_ENCODINGS)})"
                )
            if self._camera_info_topic(topic) is None:
                return f"no {CAMERA_INFO} topic in its namespace '/{_namespace(topic)}'"
        return None

    def _resolve_sensor(self, requested: str | None) -> str:
        """Pick the sensor topic: the requested one if usable, else the only candidate."""
        if requested is not None:
            topic = self._find_topic(requested)
            if topic is None:
                raise PlayerError(
                    f"sensor topic {requested!r} is not in {self.path} (topics: {self._listing()})"
                )
            if (reason := self._rejection(topic)) is not None:
                raise PlayerError(f"sensor topic {topic!r} cannot be used: {reason}")
            return topic
        sensor_types = {POINTCLOUD2, IMAGE, LASERSCAN}
        considered = [n for n, i in sorted(self._topics.items()) if i.msgtype in sensor_types]
        reasons = {topic: self._rejection(topic) for topic in considered}
        candidates = [topic for topic, reason in reasons.items() if reason is None]
        if len(candidates) == 1:
            return candidates[0]
        if candidates:
            listed = ", ".join(f"{t} ({self._topics[t].msgtype})" for t in candidates)
            raise PlayerError(
                f"several sensor topics in {self.path}: {listed}; choose one with --sensor-topic"
            )
        rejected = "".join(f"; {t} rejected: {r}" for t, r in reasons.items())
        raise PlayerError(
            f"no usable sensor topic in {self.path} (supported: {SUPPORTED_SENSORS}){rejected}; "
            f"bag topics: {self._listing()}"
        )

    def _decoder(self, camera_info: Any) -> Decoder:
        """The function turning one sensor message into an (h, w, 3) grid.

        A cloud's grid is a view over the message with non-finite points left as they are, so a
        scan row is picked without copying the cloud; ``frames`` cleans what it hands out.
        """
        if self.sensor_type == POINTCLOUD2:
            return pointcloud2_xyz
        if self.sensor_type == LASERSCAN:
            return lambda scan, _rows: laserscan_to_xyz(scan)
        return lambda image, rows: depth_image_to_xyz(image, camera_info, rows)

    def _find_moving_frame(self) -> None:
        """Without ``base_link`` in tf, the plain ``tf`` source follows the chain to the sensor.

        A handheld camera, a SLAM or a reconstruction system publishes ``map -> camera_link``
        (6-DoF) and no robot frame: the poses are then those of the frame that carries the
        sensor (``TfBuffer.moving_frame``), from the first fixed frame of REP-105 that has one.
        """
        spec = self.pose_spec
        if spec.kind != "tf" or spec.named or self._tf.has_path(spec.parent, spec.child):
            return
        sensor_frame = normalize_frame(self._first_message(self.sensor_topic).header.frame_id)
        for fixed in FIXED_FRAMES:
            moving = self._tf.moving_frame(fixed, sensor_frame) if sensor_frame else None
            if moving is not None:
                self.pose_spec = dataclasses.replace(spec, parent=fixed, child=moving)
                self.warnings.append(
                    f"no tf {spec.parent} -> {spec.child}: the poses are those of {moving!r} in "
                    f"{fixed!r}, the chain to the sensor's frame {sensor_frame!r} "
                    f"(--pose-source tf:{fixed}>{moving}; name other frames the same way)"
                )
                return

    # --- first pass: tf, poses, camera info ---------------------------------------------------

    def _load_first_pass(self, child: str) -> Any:
        """Read tf, the pose topic and the first CameraInfo in one pass; return the CameraInfo.

        Args:
            child: Robot frame of poses whose source does not name one.
        """
        spec = self.pose_spec
        pose_topic = None
        if spec.kind in {"odom", "pose"}:
            pose_topic = resolve_pose_topic(
                spec, {name: info.msgtype or "" for name, info in self._topics.items()}
            )
        info_topic = (
            self._camera_info_topic(self.sensor_topic) if self.sensor_type == IMAGE else None
        )
        tf_topics = {
            name: TF_TOPICS[name.lstrip("/")]
            for name, info in self._topics.items()
            if name.lstrip("/") in TF_TOPICS and info.msgtype in TF_TYPES
        }
        wanted = [*tf_topics, *filter(None, (pose_topic, info_topic))]
        connections = [c for name in wanted for c in self._topics[name].connections]

        camera_info = None
        poses: list[Pose] = []
        invalid: list[str] = []
        for connection, receive_ns, msg in self._messages(connections):
            topic = connection.topic
            if topic in tf_topics:
                invalid += self._tf.add_message(msg, static=tf_topics[topic])[1]
            elif topic == pose_topic:
                poses.append(pose_from_message(msg, receive_ns, child))
            elif camera_info is None:
                camera_info = msg
        if invalid:
            self.warnings.append(f"ignored {len(invalid)} invalid tf transforms, e.g. {invalid[0]}")
        if spec.path is not None:
            self._track = load_tum(spec.path, child=child)
        elif pose_topic is not None:
            if not poses:
                raise PlayerError(f"pose source {spec}: topic {pose_topic!r} has no messages")
            self._track = PoseTrack.from_poses(poses)
        if info_topic is not None and camera_info is None:
            raise PlayerError(f"camera info topic {info_topic!r} has no messages")
        return camera_info

    # --- per frame ----------------------------------------------------------------------------

    def _mount(self, frame_id: str, stamp: float) -> np.ndarray:
        """T_base_sensor for a sensor frame, deciding once per frame name how to obtain it."""
        if frame_id not in self._mounts:
            self._mounts[frame_id] = self._mount_policy(frame_id)
        fixed = self._mounts[frame_id]
        if fixed is not None:
            return fixed.copy()
        # Mounting chains are rigid in practice even when published on /tf, so clamp to the
        # nearest sample rather than fail at the ends of the recording.
        return self._tf.lookup(self.base_frame, frame_id, stamp, tolerance=math.inf)

    def _mount_policy(self, frame_id: str) -> np.ndarray | None:
        """Identity when no tf is needed or none can exist; None to look the mount up in tf."""
        if frame_id == self.base_frame:
            return np.eye(4)
        if not frame_id:
            self.warnings.append(
                f"sensor messages on {self.sensor_topic} have no frame_id; assuming they are in "
                f"base frame {self.base_frame!r}"
            )
            return np.eye(4)
        if self._tf.has_path(self.base_frame, frame_id):
            return None
        if self.pose_spec.kind == "none" or not self._tf:
            why = "the bag has no tf" if not self._tf else "pose source is none"
            self.warnings.append(
                f"no tf from sensor frame {frame_id!r} to base frame {self.base_frame!r} "
                f"({why}): using an identity sensor mounting"
            )
            return np.eye(4)
        raise PlayerError(
            f"no tf chain from sensor frame {frame_id!r} to base frame {self.base_frame!r}: "
            f"{self._tf.no_path_message(self.base_frame, frame_id)}"
        )

    def _survey(self, level: LevelMode, floor_z: float | None) -> Placement:
        """Level the fixed frame and find the band from frames spread over the bag."""
        if self.pose_spec.kind == "none":
            return unlevelled(self.base_frame)
        samples = [] if self.sensor_type == LASERSCAN else list(self._samples())
        return survey(samples, self.base_frame, mode=level, floor_z=floor_z)

    def _samples(self) -> Iterator[Sample]:
        """Up to SURVEY_FRAMES whole frames spread over the bag, with their poses."""
        connections = self._topics[self.sensor_topic].connections
        begin, length = self._reader.start_time, max(self._reader.duration, 1)
        step = length // SURVEY_FRAMES + 1
        for start in range(begin, begin + length, step):
            messages = self._messages(connections, mapped=True, start=start, stop=start + step)
            item = next(messages, None)
            messages.close()
            if item is None:
                continue
            _, receive_ns, msg = item
            stamp = header_stamp(msg.header, receive_ns)
            pose = self._pose_at(stamp)
            if pose is None:
                continue
            frame_id = normalize_frame(msg.header.frame_id)
            mount = self._mount(frame_id, stamp)
            points = invalid_to_nan(np.array(self._decode(msg, slice(None)), dtype=np.float32))
            yield Sample(points, pose.matrix @ mount, frame_id or self.base_frame)

    def _pose_at(self, stamp: float) -> Pose | None:
        """The base frame's 6-DoF pose at a stamp, or None where the source does not cover it."""
        spec = self.pose_spec
        if spec.kind == "tf":
            try:
                matrix = self._tf.lookup(
                    spec.parent, self.base_frame, stamp, tolerance=POSE_TOLERANCE
                )
            except TfError:
                return None
            return pose_from_matrix(matrix, stamp, spec.parent, self.base_frame)
        if self._track is None:
            return None
        pose = self._track.at(stamp, tolerance=POSE_TOLERANCE)
        if pose is None or not self._compose_track:
            return pose
        child_base = self._tf.lookup(pose.child, self.base_frame, stamp, tolerance=math.inf)
        moved = pose_from_matrix(pose.matrix @ child_base, stamp, pose.frame, self.base_frame)
        return dataclasses.replace(moved, cov=pose.cov)

    def _messages(
        self,
        connections: Iterable[Connection],
        *,
        mapped: bool = False,
        start: int | None = None,
        stop: int | None = None,
    ) -> Iterator[tuple[Connection, int, Any]]:
        """Deserialized messages of some connections in bag order; errors become PlayerError.

        With ``mapped``, messages of an uncompressed ROS 1 bag are views over the mapped file
        (see ``mapped_bag``): for large clouds of which only some rows are read. ``start`` and
        ``stop`` (bag time, ns) keep the messages received in ``[start, stop)``.
        """
        connections = list(connections)
        if not connections:
            return
        try:
            raws = mapped_messages(self._reader, connections, start, stop) if mapped else None
            if raws is None:
                raws = self._reader.messages(connections=connections, start=start, stop=stop)
            for connection, receive_ns, raw in raws:
                yield connection, receive_ns, self._reader.deserialize(raw, connection.msgtype)
        except Exception as err:  # damaged chunks surface as assorted library errors
            raise _unreadable(self.path, err) from err

    def frames(
        self,
        rows: RowSelection | None = None,
        start: float | None = None,
        stop: float | None = None,
    ) -> Iterator[tuple[SensorFrame, Pose | None]]:
        """Yield every sensor message as (SensorFrame, pose at its stamp or None), in bag order.

        Args:
            rows: Hand out only what this selection picks (``pick_points``: the band's stack
                of points, or one row), reading only the image rows it searches
                (``rows_to_search``): decoding whole clouds is most of a player's time. The band
                is the selection's, or the one the sensor sees (``placement.band``). None hands
                out every row.
            start: Seconds from the bag's start: the first message received then or later.
            stop: Seconds from the bag's start: messages received before it only.

        Raises:
            PlayerError: A message cannot be read or decoded (its index is named).
        """
        connections = self._topics[self.sensor_topic].connections
        begin = self._reader.start_time
        window = {
            "start": None if start is None else begin + round(start * 1e9),
            "stop": None if stop is None else begin + round(stop * 1e9),
        }
        messages = self._messages(connections, mapped=True, **window)
        for index, (_, receive_ns, msg) in enumerate(messages):
            stamp = header_stamp(msg.header, receive_ns)
            frame_id = normalize_frame(msg.header.frame_id)
            try:
                pose, mount = self.placement.place(
                    self._pose_at(stamp), self._mount(frame_id, stamp)
                )
                points, stacked = hand_out(  # a LaserScan has no height: it is one row
                    lambda rows_read, m=msg: self._decode(m, rows_read),
                    getattr(msg, "height", 1), rows, mount, self.placement.band,
                )  # fmt: skip
                if points.base is not None or points.dtype != np.float32:  # not ours to change
                    points = np.array(points, dtype=np.float32)
                points = invalid_to_nan(points)
            except PlayerError as err:
                raise PlayerError(f"{self.sensor_topic} message {index}: {err}") from err
            bag_time = (receive_ns - begin) * 1e-9
            yield SensorFrame(stamp, frame_id, points, mount, bag_time, stacked), pose

    # --- bookkeeping --------------------------------------------------------------------------

    @property
    def frame_count(self) -> int:
        """Number of sensor messages, for progress reporting."""
        return sum(c.msgcount for c in self._topics[self.sensor_topic].connections)

    def __len__(self) -> int:
        """Number of sensor messages (``frame_count``)."""
        return self.frame_count

    @property
    def duration(self) -> float:
        """Time between the bag's first and last message, seconds."""
        return self._reader.duration * 1e-9

    def close(self) -> None:
        """Close the bag; safe to call twice."""
        if self._reader.stack is not None:
            self._reader.close()
