"""A test robot: a ROS 2 bag's messages on zenoh-bridge-ros2dds's keys, as a live robot sends them.

Each message's own CDR bytes go on the key of its topic (``/T`` -> ``NAMESPACE/T``), in the
bag's order and at its pace (``SPEED`` times real time); ``tf_static`` is answered to queries,
as the bridge answers from its cache for a transient-local topic.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import zenoh
from conftest import run_wallmap
from rosbags.rosbag2 import Reader

SPEED = 2.0  # the robot's pace: twice real time, as the acceptance plays it
SENSORS = {
    "depth16": "camera/depth/image_raw:sensor_msgs/msg/Image",
    "pointcloud": "camera/depth/points:sensor_msgs/msg/PointCloud2",
    "laserscan": "scan:sensor_msgs/msg/LaserScan",
}


SENSOR_TOPICS = {f"/{spec.split(':')[0]}" for spec in SENSORS.values()}


class Robot:
    """A bag's messages on the bridge's keys, at ``SPEED`` times their recorded pace."""

    def __init__(self, session: zenoh.Session, bag: Path, namespace: str) -> None:
        self.session, self.bag, self.namespace = session, bag, namespace
        self.sent: dict[str, int] = {}
        self._static: bytes | None = None
        self._cache = session.declare_queryable(self.key("tf_static"), self._answer)

    def key(self, topic: str) -> str:
        topic = topic.strip("/")
        return f"{self.namespace}/{topic}" if self.namespace else topic

    def _answer(self, query: zenoh.Query) -> None:
        if self._static is not None:  # the bridge's cache of a transient-local topic
            query.reply(query.key_expr, self._static)

    def play(self, skip: tuple[str, ...] = (), quiet: tuple[float, float] | None = None) -> None:
        """Every message but those of ``skip`` topics, in bag order, paced.

        ``quiet``: the sensor stays silent over this stretch (s from the start, the bag's time),
        as a camera that stalls; the rest of the robot goes on.
        """
        with Reader(self.bag) as reader:
            start_wall, start_bag = time.monotonic(), reader.start_time
            for connection, stamp, raw in reader.messages():
                if connection.topic in skip:
                    continue
                since = (stamp - start_bag) * 1e-9
                if quiet and connection.topic in SENSOR_TOPICS and quiet[0] <= since < quiet[1]:
                    continue
                if connection.topic == "/tf_static":
                    self._static = bytes(raw)
                due = start_wall + (stamp - start_bag) * 1e-9 / SPEED
                time.sleep(max(0.0, due - time.monotonic()))
                self.session.put(self.key(connection.topic), bytes(raw))
                self.sent[connection.topic] = self.sent.get(connection.topic, 0) + 1

    def close(self) -> None:
        self._cache.undeclare()


def client(endpoint: str) -> zenoh.Session:
    """A Zenoh client session on ``endpoint`` (multicast off): the robot's bridge."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", f'["{endpoint}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def mapped(query: Callable[[], dict], sent: int, share: float = 0.95) -> dict:
    """The map reply once ``share`` of the ``sent`` frames are integrated (20 s at most), checked.

    The last frames are still on their way through the detector and the mapper when the robot
    is done; a bridge may drop a few large ones, as a real one does.
    """
    deadline = time.monotonic() + 20
    reply = query()
    while reply["frames"] < share * sent and time.monotonic() < deadline:
        time.sleep(0.5)
        reply = query()
    assert reply["frames"] >= share * sent, f"{reply['frames']} of {sent} frames integrated"
    return reply


def play_to_the_source(endpoint: str, prefix_args: tuple[str, ...], bag: Path, namespace: str,
                       log: Path) -> Robot:  # fmt: skip
    """Once `wallmap ros2` is live on ``endpoint`` (60 s at most; ``log`` says why not), the bag
    played to it; the robot, with what it sent."""
    deadline = time.monotonic() + 60
    status = ("status", "--json", "--connect", endpoint, *prefix_args)
    while '"ros2"' not in run_wallmap(*status, expect=None).stdout:
        assert time.monotonic() < deadline, log.read_text()
        time.sleep(0.3)
    with client(endpoint) as session:
        robot = Robot(session, bag, namespace)
        try:
            robot.play()
        finally:
            robot.close()
    return robot
