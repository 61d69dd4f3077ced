"""The live ROS 2 source: a robot's topics as CDR on Zenoh in, the player's frames and poses out.

zenoh-bridge-ros2dds puts each ROS 2 topic ``/T`` on the key ``T`` (under its ``--namespace``),
rmw_zenoh on ``DOMAIN/T/TYPE/HASH``, the messages as CDR bytes either way. ``tf_static`` is
transient local: bridges before 1.6 answer a query on its key from their cache, later bridges
and rmw_zenoh keep it in an advanced publisher's cache, which an advanced subscriber's history
reaches; the source does both. Without ``--sensor``, the sensor topic is the one the bridge or
rmw_zenoh announces (``discovery``). The samples go from the
subscribers' callbacks into one queue and are decoded, placed (``live.LiveFrames``) and
published by the service's own thread, on the keys and in the payloads the player uses: the
detector and the mapper cannot tell a live robot from a bag played in real time.
"""

from __future__ import annotations

import queue
import threading
import time
import uuid
from dataclasses import dataclass, replace
from typing import Any

import zenoh
from zenoh import ext

from wallmap.common.codec import MessageError
from wallmap.common.delivery import declare_history_publisher
from wallmap.common.link_settings import MAX_RATE, HistorySettings, ZenohSettings
from wallmap.common.messages import Pose, pack
from wallmap.common.ros2_types import deserialize_cdr
from wallmap.common.ros_poses import ODOMETRY_TYPE, POSE_TYPES
from wallmap.common.runtime import Presence, Stats, exempt_startup_objects, setup_logging
from wallmap.common.transport import Keys, open_session
from wallmap.services.detector_rows import ask_rows
from wallmap.services.mapper.pose_input import TF_TYPE
from wallmap.services.player.bag_contents import CAMERA_INFO, IMAGE, LASERSCAN
from wallmap.services.player.frames import SensorFrame
from wallmap.services.ros2_source.discovery import discover_sensor
from wallmap.services.ros2_source.live import LiveFrames
from wallmap.services.ros2_source.settings import Ros2Settings
from wallmap.services.ros2_source.topic_watch import TopicWatch

QUEUE_DEPTH = 512  # samples waiting for the service's thread; beyond, the newest are dropped
POSE_RATE = 200.0  # poses a second the history is sized for
QUIET = 1.0  # s without a sample: the frames held for the survey go out


@dataclass(frozen=True)
class _Sample:
    kind: str  # sensor, camera_info, tf, tf_static, pose
    payload: bytes


class _Intake:
    """The subscribers' callbacks: each sample into the queue, nothing else (never blocks)."""

    def __init__(self, stats: Stats) -> None:
        self.queue: queue.Queue[_Sample] = queue.Queue(maxsize=QUEUE_DEPTH)
        self._stats = stats

    def handler(self, kind: str) -> Any:
        def put(sample: zenoh.Sample) -> None:
            try:
                self.queue.put_nowait(_Sample(kind, sample.payload.to_bytes()))
            except queue.Full:
                self._stats.add("queue_full")

        return put


def _subscriptions(ros2: Ros2Settings) -> dict[str, tuple[str, str]]:
    """Sample kind -> (Zenoh key, message type) of everything the source listens to."""
    topic, msgtype = ros2.sensor_topic_type()
    found = {"sensor": (topic, msgtype), "tf": ("tf", TF_TYPE), "tf_static": ("tf_static", TF_TYPE)}
    if msgtype == IMAGE:
        found["camera_info"] = (ros2.camera_info_topic(), CAMERA_INFO)
    if (pose_topic := ros2.pose_topic()) is not None:
        kind = ros2.pose_spec().kind
        found["pose"] = (pose_topic, ODOMETRY_TYPE if kind == "odom" else "")
    return {
        kind: (ros2.key(topic, msgtype or None), msgtype)
        for kind, (topic, msgtype) in found.items()
    }


def _subscribe(session: zenoh.Session, kind: str, key: str, intake: _Intake) -> Any:
    """A subscriber; ``tf_static``'s with the history of advanced publishers' caches."""
    if kind != "tf_static":
        return session.declare_subscriber(key, intake.handler(kind))
    history = ext.HistoryConfig(detect_late_publishers=True)
    return ext.declare_advanced_subscriber(session, key, intake.handler(kind), history=history)


def run(
    settings: ZenohSettings,
    ros2: Ros2Settings,
    stop: threading.Event,
    history: HistorySettings | None,
) -> Stats:
    """Until ``stop`` is set; returns the counters. PlayerError says what is wrong with a flag."""
    log = setup_logging("ros2")
    keys, stats, run_id = Keys(settings.prefix), Stats(log), uuid.uuid4().hex[:12]
    spec = ros2.pose_spec()
    log.info("connecting to %s (prefix %r)", ", ".join(settings.connect), settings.prefix)
    with open_session(settings, count=stats.add, stop=stop) as session:
        if ros2.sensor is None:
            ros2 = replace(ros2, sensor=discover_sensor(session, ros2, stop))
            log.info("the sensor topic, as announced: %s", ros2.sensor)
        subscriptions = _subscriptions(ros2)
        _, msgtype = ros2.sensor_topic_type()
        rows = None if ros2.whole_clouds or msgtype == LASERSCAN else ask_rows(session, keys)
        live = LiveFrames(
            msgtype,
            spec,
            spec.child,
            ros2.tf_wait,
            rows,
            lambda counter, line: stats.note(counter, counter, line),
        )
        intake = _Intake(stats)
        watch = TopicWatch({kind: key for kind, (key, _) in subscriptions.items()})
        subscribers = [
            _subscribe(session, kind, key, intake) for kind, (key, _) in subscriptions.items()
        ]
        outlet = _Outlet(session, keys, history or HistorySettings(), run_id, msgtype)
        presence = Presence(
            session, keys, "ros2", stats, lambda: {"run": run_id, **watch.report(time.monotonic())}
        )
        worker = threading.Thread(
            target=_work, args=(intake, live, subscriptions, outlet, stats, watch, stop)
        )
        worker.start()  # before the query: the queue it drains may fill meanwhile
        # an old bridge's cache (later ones and rmw_zenoh's: the advanced subscriber's history)
        for reply in session.get(subscriptions["tf_static"][0], timeout=2.0):
            if reply.ok is not None:
                intake.handler("tf_static")(reply.ok)
        exempt_startup_objects()
        log.info(
            "ready: %s -> %s, %s (poses from %s)",
            ", ".join(key for key, _ in subscriptions.values()),
            keys.frames,
            keys.pose,
            spec,
        )
        stop.wait()
        worker.join()
        log.info("stopping: %s", stats.snapshot())
        presence.undeclare()
        for subscriber in subscribers:
            subscriber.undeclare()
    return stats


def _work(
    intake: _Intake,
    live: LiveFrames,
    subscriptions: dict[str, tuple[str, str]],
    outlet: _Outlet,
    stats: Stats,
    watch: TopicWatch,
    stop: threading.Event,
) -> None:
    """Decode, place and publish, in the order the samples came, until ``stop``.

    Frames held for the survey go out once the robot has been quiet ``QUIET`` seconds, and when
    the source stops: a robot that sends a few frames and pauses has them mapped.
    """
    heard = time.monotonic()
    while not stop.is_set():
        try:
            sample = intake.queue.get(timeout=0.1)
        except queue.Empty:
            if time.monotonic() - heard > QUIET:
                _send(outlet, live, live.end_survey(), stats)
            continue
        heard = time.monotonic()
        watch.heard(sample.kind, heard)
        key, msgtype = subscriptions[sample.kind]
        try:
            msg = deserialize_cdr(sample.payload, msgtype) if msgtype else _pose(sample.payload)
        except MessageError as err:
            stats.refuse(key, str(err))
            continue
        if sample.kind in ("tf", "tf_static"):
            live.add_tf(msg, static=sample.kind == "tf_static")
        elif sample.kind == "camera_info":
            live.add_camera_info(msg)
        elif sample.kind == "pose":
            live.add_pose(msg)
        else:
            live.add_sensor(msg)
        _send(outlet, live, live.ready(), stats)
    _send(outlet, live, live.end_survey(), stats)


def _send(outlet: _Outlet, live: LiveFrames, frames: list[Any], stats: Stats) -> None:
    """The poses ready, then the frames they place."""
    outlet.poses(live.take_poses())
    for frame in frames:
        outlet.frame(frame)
        stats.add("frames")


def _pose(payload: bytes) -> Any:
    """A ``pose`` topic's message, of whichever of the two pose types it is.

    A PoseWithCovarianceStamped if it decodes as one, else a PoseStamped; MessageError if
    neither. The two differ in length by the covariance's 36 doubles, so a PoseStamped's bytes
    are too short to be read as the other.
    """
    stamped, with_covariance = POSE_TYPES
    try:
        return deserialize_cdr(payload, with_covariance)
    except MessageError:
        return deserialize_cdr(payload, stamped)


class _Outlet:
    """The player's keys: frames and poses, with the history window for services that restart."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        history: HistorySettings,
        run_id: str,
        msgtype: str,
    ) -> None:
        self._session, self._keys, self._history, self._run = session, keys, history, run_id
        self._sensor = "scan" if msgtype == LASERSCAN else "depth"
        self._poses = declare_history_publisher(session, keys.pose, history.samples(POSE_RATE))
        self._frames: Any = None
        self.published = 0

    def poses(self, poses: list[Pose]) -> None:
        for pose in poses:
            self._poses.put(pack(pose))

    def frame(self, frame: SensorFrame) -> None:
        message = pack(frame.to_frame(run=self._run, seq=self.published, sensor=self._sensor))
        if self._frames is None:
            samples = self._history.samples(MAX_RATE, len(message))
            self._frames = declare_history_publisher(self._session, self._keys.frames, samples)
        self._frames.put(message)
        self.published += 1
