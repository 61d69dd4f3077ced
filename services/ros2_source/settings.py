"""What ``wallmap ros2`` subscribes to, and how it names the robot's topics on Zenoh."""

from __future__ import annotations

import math
from dataclasses import dataclass

from wallmap.common.config_file import require
from wallmap.services.player.bag_contents import IMAGE, LASERSCAN, POINTCLOUD2
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.pose_sources import PoseSourceSpec, parse_pose_source

LIVE_TYPES = (IMAGE, POINTCLOUD2, LASERSCAN)
POSE_DEFAULT_TOPICS = {"odom": "odom", "pose": "pose"}
MAX_DOMAIN = 232  # the highest ROS domain id (ROS 2's domain-id documentation)


@dataclass(frozen=True)
class Ros2Settings:
    """A live ROS 2 robot, bridged to Zenoh by zenoh-bridge-ros2dds or speaking rmw_zenoh.

    Attributes:
        namespace: The bridge's ``--namespace`` (its keys are ``NAMESPACE/TOPIC``), or with
            rmw_zenoh the robot's ROS namespace; empty: none.
        sensor: ``TOPIC:TYPE`` of the sensor, TYPE one of sensor_msgs/msg/Image (16UC1,
            32FC1), sensor_msgs/msg/PointCloud2 or sensor_msgs/msg/LaserScan; None (or empty,
            as a compose file's unset variable gives it): the one sensor topic the bridge (or
            rmw_zenoh) announces.
        camera_info: A depth image's CameraInfo topic (not set: ``camera_info`` beside the
            image's topic, as ROS drivers name it).
        pose_source: tf | tf:PARENT>CHILD | odom[:TOPIC] | pose[:TOPIC] | none.
        tf_wait: Seconds of the robot's time a sensor message waits for its tf, then is dropped.
        whole_clouds: Send whole clouds, not only the rows the detector asks for.
        rmw_zenoh: The ROS domain id of a robot speaking rmw_zenoh (keys
            ``DOMAIN/TOPIC/TYPE/HASH``); None: zenoh-bridge-ros2dds's keys.
        discover_wait: Seconds to wait for the robot's topics to be announced (no ``sensor``).
    """

    namespace: str = ""
    sensor: str | None = None
    camera_info: str | None = None
    pose_source: str = "tf"
    tf_wait: float = 1.0
    whole_clouds: bool = False
    rmw_zenoh: int | None = None
    discover_wait: float = 10.0

    def __post_init__(self) -> None:
        if not self.sensor:
            object.__setattr__(self, "sensor", None)
        require(0 < self.tf_wait < math.inf, "tf_wait", "a positive number", self.tf_wait)
        require(
            0 < self.discover_wait < math.inf,
            "discover_wait",
            "a positive number",
            self.discover_wait,
        )
        require(
            self.rmw_zenoh is None or 0 <= self.rmw_zenoh <= MAX_DOMAIN,
            "rmw_zenoh",
            f"a ROS domain id, 0-{MAX_DOMAIN}",
            self.rmw_zenoh,
        )
        if self.sensor is not None:
            self.sensor_topic_type()  # raises on a bad value
        self.pose_spec()

    def sensor_topic_type(self) -> tuple[str, str]:
        """The sensor's topic (no leading slash) and message type; PlayerError if unusable."""
        topic, _, msgtype = (self.sensor or "").rpartition(":")
        topic = topic.strip("/")
        if not topic or msgtype not in LIVE_TYPES:
            raise PlayerError(
                f"--sensor must be TOPIC:TYPE with TYPE one of "
                f"{', '.join(LIVE_TYPES)}; got {self.sensor!r}"
            )
        return topic, msgtype

    def pose_spec(self) -> PoseSourceSpec:
        """The parsed pose source; PlayerError for a bad one (``tum:`` has no live form)."""
        spec = parse_pose_source(self.pose_source)
        if spec.kind == "tum":
            msg = "--pose-source tum:FILE is for recordings; live: tf, odom, pose, none"
            raise PlayerError(msg)
        return spec

    def camera_info_topic(self) -> str:
        """A depth image's CameraInfo topic."""
        if self.camera_info:
            return self.camera_info.strip("/")
        topic, _ = self.sensor_topic_type()
        return f"{topic.rpartition('/')[0]}/camera_info".strip("/")

    def pose_topic(self) -> str | None:
        """The topic of an ``odom``/``pose`` source."""
        spec = self.pose_spec()
        if spec.kind not in POSE_DEFAULT_TOPICS:
            return None
        return (spec.topic or POSE_DEFAULT_TOPICS[spec.kind]).strip("/")

    def key(self, topic: str, msgtype: str | None = None) -> str:
        """The Zenoh key of a topic's messages.

        The bridge's: ``/T`` is ``T``, under the namespace. rmw_zenoh's:
        ``DOMAIN/T/TYPE/HASH``, the type as DDS names it, the hash any (Humble has none, later
        distributions their own); a type not known (a ``pose`` topic's) is any.
        """
        topic = topic.strip("/")
        namespace = self.namespace.strip("/")
        name = f"{namespace}/{topic}" if namespace else topic
        if self.rmw_zenoh is None:
            return name
        return f"{self.rmw_zenoh}/{name}/{dds_type_name(msgtype) if msgtype else '*'}/*"


def dds_type_name(msgtype: str) -> str:
    """``pkg/msg/Name`` as DDS (and rmw_zenoh's keys) name it: ``pkg::msg::dds_::Name_``."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str | None:
    """The inverse of ``dds_type_name``; None for a name not of that form."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        return None
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
