"""A test robot: a ROS 2 bag's messages on Zenoh, as a live robot's bridge or rmw_zenoh sends them.

Each message's own CDR bytes go on the key of its topic, in the bag's order and at its pace
(``SPEED`` times real time):
- ``bridge`` (zenoh-bridge-ros2dds before 1.6): ``/T`` -> ``NAMESPACE/T``; ``tf_static`` answered
  to queries on its key, from the bridge's cache of a transient-local topic; each topic's route
  listed in the bridge's admin space (``@/<id>/ros2/route/topic/pub/<key>``, its JSON).
- ``bridge-advanced`` (1.6 and later): the same keys, ``tf_static`` in an advanced publisher's
  cache with publisher detection, as the bridge declares it.
- ``rmw_zenoh``: ``DOMAIN/NAMESPACE/T/TYPE/HASH`` with rmw_zenoh's attachment (sequence number,
  source time, publisher id), ``tf_static`` in an advanced publisher's cache, and each
  publisher's liveliness token under ``@ros2_lv``.
"""

from __future__ import annotations

import json
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh
from conftest import run_wallmap
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from zenoh import ext

from wallmap.services.ros2_source.settings import dds_type_name

SPEED = 2.0  # the robot's pace: twice real time, as the acceptance plays it
SENSORS = {
    "depth16": "camera/depth/image_raw:sensor_msgs/msg/Image",
    "pointcloud": "camera/depth/points:sensor_msgs/msg/PointCloud2",
    "laserscan": "scan:sensor_msgs/msg/LaserScan",
}


SENSOR_TOPICS = {f"/{spec.split(':')[0]}" for spec in SENSORS.values()}


DOMAIN = 3  # the rmw_zenoh robot's ROS domain
HASHES = get_typestore(Stores.ROS2_HUMBLE)


class Robot:
    """A bag's messages as ``naming`` puts them on Zenoh, at ``SPEED`` times their recorded pace.

    Announced from the start: the bridge's routes, or rmw_zenoh's liveliness tokens.
    """

    def __init__(
        self,
        session: zenoh.Session,
        bag: Path,
        namespace: str,
        naming: str = "bridge",
        renamed: dict[str, str] | None = None,
    ) -> None:
        """``renamed``: topics the robot publishes under another name (old -> new)."""
        self.session, self.bag, self.namespace, self.naming = session, bag, namespace, naming
        self.renamed = renamed or {}
        self.sent: dict[str, int] = {}
        self._hold: tuple[str, int] | None = None  # (topic, count): stop once it sent so many
        self._going_on = threading.Event()
        self._static: bytes | None = None
        self._seq = 0
        with Reader(bag) as reader:
            self.types = {c.topic: c.msgtype for c in reader.connections}
        self._declared: list = []
        if naming != "rmw_zenoh":  # either bridge: its admin space
            self._declared.append(
                session.declare_queryable(
                    f"@/{session.info.zid()}/ros2/route/topic/pub/**", self._routes
                )
            )
        if naming == "bridge":
            self._declared.append(session.declare_queryable(self.key("/tf_static"), self._answer))
        else:
            self._static_publisher = ext.declare_advanced_publisher(
                session,
                self.key("/tf_static"),
                cache=ext.CacheConfig(max_samples=1),
                sample_miss_detection=ext.MissDetectionConfig(sporadic_heartbeat=0.5),
                publisher_detection=True,
            )
            self._declared.append(self._static_publisher)
        if naming == "rmw_zenoh":
            self._declared += [
                session.liveliness().declare_token(self._token(topic, n))
                for n, topic in enumerate(self.types)
            ]

    def key(self, topic: str) -> str:
        name = f"{self.namespace}/{self.renamed.get(topic, topic).strip('/')}".strip("/")
        if self.naming != "rmw_zenoh":
            return name
        msgtype = self.types[topic]
        return f"{DOMAIN}/{name}/{dds_type_name(msgtype)}/{HASHES.hash_rihs01(msgtype)}"

    def _token(self, topic: str, entity: int) -> str:
        """rmw_zenoh's liveliness token of a publisher (Jazzy's layout)."""
        name = f"/{self.namespace}/{topic.strip('/')}".replace("//", "/").replace("/", "%")
        msgtype = self.types[topic]
        return (
            f"@ros2_lv/{DOMAIN}/{self.session.info.zid()}/0/{10 + entity}/MP/%/"
            f"{('%' + self.namespace) if self.namespace else '%'}/robot_node/{name}/"
            f"{dds_type_name(msgtype)}/{HASHES.hash_rihs01(msgtype)}/::,10:,:,:,,"
        )

    def _answer(self, query: zenoh.Query) -> None:
        if self._static is not None:  # the bridge's cache of a transient-local topic
            query.reply(query.key_expr, self._static)

    def _routes(self, query: zenoh.Query) -> None:
        """The bridge's admin space: a route for each of the robot's topics."""
        for topic, msgtype in self.types.items():
            key = self.key(topic)
            route = {
                "ros2_name": topic,
                "ros2_type": msgtype,
                "zenoh_key_expr": key,
                "publication_cache_size": 0,
                "dds_reader": "",
                "priority": 5,
                "remote_routes": [],
                "local_nodes": ["/robot_node"],
            }
            reply_key = f"@/{self.session.info.zid()}/ros2/route/topic/pub/{key}"
            if zenoh.KeyExpr(reply_key).intersects(query.key_expr):
                query.reply(reply_key, json.dumps(route))

    def send_static_first(self) -> None:
        """The bag's static transforms now, as a robot sends them long before anyone listens."""
        with Reader(self.bag) as reader:
            connections = [c for c in reader.connections if c.topic == "/tf_static"]
            for connection, _, raw in reader.messages(connections=connections):
                self._put(connection.topic, bytes(raw))

    def _put(self, topic: str, raw: bytes) -> None:
        if topic == "/tf_static":
            self._static = raw
            if self.naming != "bridge":
                self._static_publisher.put(raw)
                return
        if self.naming == "rmw_zenoh":  # sequence number, source time (ns), publisher id
            self._seq += 1
            attachment = struct.pack("<qqB16s", self._seq, time.time_ns(), 16, bytes(16))
            self.session.put(self.key(topic), raw, attachment=attachment)
        else:
            self.session.put(self.key(topic), raw)

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
                start_wall += self._held()
                due = start_wall + (stamp - start_bag) * 1e-9 / SPEED
                time.sleep(max(0.0, due - time.monotonic()))
                self._put(connection.topic, bytes(raw))
                self.sent[connection.topic] = self.sent.get(connection.topic, 0) + 1

    def hold_after(self, topic: str, more: int) -> None:
        """Stop sending anything once ``more`` more ``topic`` messages are out, until ``go_on``."""
        self._going_on.clear()
        self._hold = (topic, self.sent.get(topic, 0) + more)

    def go_on(self) -> None:
        self._hold = None
        self._going_on.set()

    def _held(self) -> float:
        """Seconds the robot stood held here (0 if it was not): its pace resumes after them."""
        hold = self._hold
        if hold is None or self.sent.get(hold[0], 0) < hold[1]:
            return 0.0
        since = time.monotonic()
        self._going_on.wait()
        return time.monotonic() - since

    def close(self) -> None:
        for declared in self._declared:
            declared.undeclare()


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


def play_to_the_source(
    endpoint: str, prefix_args: tuple[str, ...], bag: Path, namespace: str, log: Path
) -> Robot:
    """A robot on the bridge's keys, announcing its topics as soon as the router on ``endpoint``
    is up; once `wallmap ros2` is live there (60 s at most; ``log`` says why not), the bag
    played to it. The robot, with what it sent."""
    deadline = time.monotonic() + 60
    while True:
        try:
            session = client(endpoint)
            break
        except zenoh.ZError:
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.3)
    with session:
        robot = Robot(session, bag, namespace)
        try:
            status = ("status", "--json", "--connect", endpoint, *prefix_args)
            while '"ros2"' not in run_wallmap(*status, expect=None).stdout:
                assert time.monotonic() < deadline, log.read_text()
                time.sleep(0.3)
            robot.play()
        finally:
            robot.close()
    return robot
