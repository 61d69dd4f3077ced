"""What a bag holds, read once: its topics, its tf tree, its poses and its first messages.

The player's choices (which sensor topic, which pose source, how the sensor is mounted: see
``choices`` and ``pose_choice``) and ``wallmap doctor``'s account of a bag are made from the
same `BagContents`, so the two cannot disagree. Reading them costs one pass over the small
topics (tf, odometry, poses) and a peek at the first message of each sensor and camera-info
topic; the big sensor topics are read later, frame by frame.
"""

from collections import Counter
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wallmap.common.messages import Pose
from wallmap.common.ros_poses import ODOMETRY_TYPE, POSE_TYPES, header_stamp, pose_from_message
from wallmap.common.tf_buffer import TfBuffer, TfError, normalize_frame
from wallmap.services.player.bag_file import BagFile, Topic

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
LASERSCAN = "sensor_msgs/msg/LaserScan"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
SENSOR_TYPES = frozenset({POINTCLOUD2, IMAGE, LASERSCAN})
# tf2's message, and tf1's older one with the same layout (both renamed to ROS 2 style).
TF_TYPES = frozenset({"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"})
TF_TOPICS = {"tf": False, "tf_static": True}  # normalised topic name -> static
POSE_TOPIC_TYPES = frozenset({ODOMETRY_TYPE, *POSE_TYPES})


@dataclass
class Stamps:
    """Header stamps (as the player reads them), receive times and frames of a topic, in order.

    Attributes:
        stamps: Header stamps, s (the receive time where a header stamp is zero).
        receive: Receive times, s.
        zero: How many header stamps are zero.
        frame_ids: Header frame names (without a leading '/') and how many messages use each.
    """

    stamps: list[float] = field(default_factory=list)
    receive: list[float] = field(default_factory=list)
    zero: int = 0
    frame_ids: Counter[str] = field(default_factory=Counter)

    def add(self, header: Any, receive_ns: int) -> None:
        """Count one message's header, received at ``receive_ns``."""
        self.zero += header.stamp.sec == 0 and header.stamp.nanosec == 0
        self.stamps.append(header_stamp(header, receive_ns))
        self.receive.append(receive_ns * 1e-9)
        self.frame_ids[normalize_frame(header.frame_id)] += 1


@dataclass
class TfLink:
    """One tf link as published: static or not (its first sample decides, as in TfBuffer).

    Attributes:
        parent: Parent frame, without a leading '/'.
        child: Child frame.
        static: Published on /tf_static.
        stamps: Stamps of every sample accepted, in bag order, s.
    """

    parent: str
    child: str
    static: bool
    stamps: list[float] = field(default_factory=list)


@dataclass
class BagContents:
    """Everything the player decides a bag by, and the doctor reports on.

    Attributes:
        path: The bag.
        topics: The topics considered (all, or those ``--topics`` names), by name.
        start_ns: Receive time of the bag's first message, ns.
        duration_ns: From the bag's first message to its last, ns.
        message_count: Messages in the bag.
        tf: Every transform of /tf and /tf_static that tf2 would accept.
        tf_links: The same, link by link, with the stamps of their samples.
        tf_refused: Why each transform tf2 would refuse was refused.
        firsts: The first message of every sensor and CameraInfo topic (None: no messages).
        poses: The poses of the odometry and pose topics read; a pose's child is '' when its
            message names none (only Odometry does): the pose source's choice names it.
        pose_stamps: The stamps of the same topics.
    """

    path: Path
    topics: dict[str, Topic]
    start_ns: int
    duration_ns: int
    message_count: int
    tf: TfBuffer = field(default_factory=TfBuffer)
    tf_links: dict[tuple[str, str], TfLink] = field(default_factory=dict)
    tf_refused: list[str] = field(default_factory=list)
    firsts: dict[str, Any] = field(default_factory=dict)
    poses: dict[str, list[Pose]] = field(default_factory=dict)
    pose_stamps: dict[str, Stamps] = field(default_factory=dict)

    def find(self, name: str) -> str | None:
        """The bag's spelling of a topic, matching with or without the leading '/'."""
        wanted = name.lstrip("/")
        return next((t for t in self.topics if t.lstrip("/") == wanted), None)

    def types(self) -> dict[str, str]:
        """Every topic's message type, by name."""
        return {name: topic.msgtype for name, topic in self.topics.items()}

    def listing(self) -> str:
        """The topics and their types, for messages that must show what the bag holds."""
        return topic_listing(self.topics)

    def add_tf(self, msg: Any, *, static: bool) -> None:
        """Add a TFMessage's transforms, noting the links and what tf2 would refuse."""
        for transform in msg.transforms:
            parent = normalize_frame(transform.header.frame_id)
            child = normalize_frame(transform.child_frame_id)
            stamp = transform.header.stamp.sec + transform.header.stamp.nanosec * 1e-9
            t, q = transform.transform.translation, transform.transform.rotation
            try:
                self.tf.add_transform(
                    parent, child, stamp, (t.x, t.y, t.z), (q.x, q.y, q.z, q.w), static=static
                )
            except TfError as err:
                self.tf_refused.append(str(err))
                continue
            link = self.tf_links.setdefault((parent, child), TfLink(parent, child, static))
            link.stamps.append(stamp)


def topic_listing(topics: Mapping[str, Topic]) -> str:
    """``name (type)`` of each topic, sorted, or ``none``."""
    return ", ".join(f"{n} ({t.msgtype})" for n, t in sorted(topics.items())) or "none"


def read_contents(
    bag: BagFile,
    topics: dict[str, Topic] | None = None,
    pose_topics: Collection[str] | None = None,
) -> BagContents:
    """Read what the choices about a bag need: tf, poses, the first sensor and camera messages.

    Through the mapped file where it can be (``BagFile.messages``): rosbags reads every chunk
    that holds a tf message whole, and in a camera's bag those chunks are the clouds, so the
    first pass over a 2.9 GB bag of 640x480 clouds read all of it (2.1-2.5 s, now 0.95 s).

    Args:
        bag: The open bag.
        topics: The topics to consider (``--topics``); None for all of them.
        pose_topics: The odometry and pose topics to read; None for all of them (the doctor
            weighs every one, the player reads the one its pose source names).

    Raises:
        PlayerError: A damaged chunk.
    """
    considered = bag.topics if topics is None else topics
    contents = BagContents(bag.path, considered, bag.start_ns, bag.duration_ns, bag.message_count)
    for name, topic in sorted(considered.items()):
        if topic.msgtype in SENSOR_TYPES or topic.msgtype == CAMERA_INFO:
            first = bag.first(topic, mapped=True)
            contents.firsts[name] = None if first is None else first[1]
    tf_topics = {
        name: TF_TOPICS[name.lstrip("/")]
        for name, topic in considered.items()
        if name.lstrip("/") in TF_TOPICS and topic.msgtype in TF_TYPES
    }
    if pose_topics is None:
        pose_topics = [n for n, t in considered.items() if t.msgtype in POSE_TOPIC_TYPES]
    for name in sorted(pose_topics):
        contents.poses[name], contents.pose_stamps[name] = [], Stamps()
    wanted = [considered[name] for name in [*tf_topics, *sorted(pose_topics)]]
    for name, receive_ns, msg in bag.messages(wanted, mapped=True):
        if name in tf_topics:
            contents.add_tf(msg, static=tf_topics[name])
        else:
            contents.pose_stamps[name].add(msg.header, receive_ns)
            contents.poses[name].append(pose_from_message(msg, receive_ns, child=""))
    return contents


def read_stamps(bag: BagFile, topic: Topic) -> Stamps:
    """The stamps and frame names of every message of a topic (the doctor's look at a sensor).

    Raises:
        PlayerError: A damaged chunk.
    """
    stamps = Stamps()
    for receive_ns, msg, _ in bag.sensor_messages(topic):  # their heads: an LZ4 bag's alone
        stamps.add(msg.header, receive_ns)
    return stamps
