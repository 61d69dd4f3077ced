"""The mapper service: poses and wall observations in, the wall map served as a queryable.

Three worker threads, each draining one Zenoh channel (no work is done in Zenoh's callbacks):
poses go into the pose buffer; observations wait for a pose that covers their stamp (in arrival
order, for at most ``pose_wait`` seconds) and are folded into the map; queries get a snapshot.
After each batch of observations the mapper acknowledges each player run's frames on the
progress key, which is how ``wallmap player --fast`` knows how far ahead it may publish. The main
thread saves the state file every few seconds and on shutdown.
"""

from __future__ import annotations

import collections
import json
import logging
import threading
import time
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import zenoh

from wallmap.common.codec import SCHEMA_VERSION, MessageError, encode
from wallmap.common.config_file import require
from wallmap.common.delivery import (
    ACK_EVERY,
    History,
    HistorySubscription,
    InOrder,
    RunProgress,
    subscribe_with_history,
)
from wallmap.common.map_query import MapQuery, answer_map_queries
from wallmap.common.messages import Observations, Pose, Progress, pack, unpack_observations
from wallmap.common.runtime import Presence, Stats, drain, setup_logging
from wallmap.common.transport import Keys, ZenohSettings, open_session
from wallmap.services.mapper import serving, state_file
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.pose_buffer import Lookup, PoseBuffer, PoseBufferConfig, SourcePose
from wallmap.services.mapper.pose_correction import PoseCorrector, SlamConfig
from wallmap.services.mapper.pose_input import PoseInput, make_pose_input
from wallmap.services.mapper.pose_judge import JudgeConfig, PoseJudge
from wallmap.services.mapper.rooms_server import RoomsServer
from wallmap.services.mapper.ros2_out import Ros2Outlet
from wallmap.services.mapper.wall_map import WallMap
from wallmap.services.pipeline import Mapping

T = TypeVar("T")

MAX_PENDING = 2048  # observations waiting for poses (a few KB each)
HOLD_POLL = 0.02  # s between looks at a held gap
UPDATE_PERIOD = 0.5  # s between map updates while busy
ACK_REPEAT = 1.0  # s between two repeats of the newest run's acknowledgement...
REPEAT_FOR = 30.0  # ...for this long after it last moved
UPDATE_FRAMES = 5  # frames integrated that make an update due sooner (a bag played --fast)
DROP_REASONS = {Lookup.WAIT: "pose_timeout", Lookup.MISSING: "no_pose"}
BACKLOG = "backlog"  # dropped because MAX_PENDING newer frames wait for poses too
LATENCY_WAIT = 0.5  # s a frame waits for the pose its latency asks for, before extrapolating


@dataclass(frozen=True)
class MapperSettings:
    """How the mapper service runs (the map's own tuning is in ``MapperConfig``).

    Attributes:
        state: file the map is kept in across restarts, or None.
        pose_key: key expression the poses come from (default: the prefix's pose key).
        pose_format: ``wallmap`` or ``ros2:<type>`` (CDR from a ROS 2 system, see pose_input).
        pose_frames: ``PARENT>CHILD`` of the pose, for ``ros2:tf2_msgs/msg/TFMessage``.
        pose_wait: longest an observation waits for its pose (s, wall clock).
        gap_wait: longest a frame waits for earlier ones of its run (s, wall clock): missing
            frames come back from the history meanwhile, or are given up and counted as lost.
        save_every: seconds between state saves while the map changes.
        slam: take the poses as odometry and correct them with the walls (``--slam``).
        judge: how every pose is judged against the walls (``--trust-poses``, ``--pose-latency``).
        ros2_out: publish the map as ROS 2 markers and a path (``services.mapper.ros2_out``).
        map: how the map associates, merges and serves walls.
        poses: how long poses are kept and how far they are interpolated.
    """

    state: Path | None = None
    pose_key: str | None = None
    pose_format: str = "wallmap"
    pose_frames: str = "map>base_link"
    pose_wait: float = 5.0
    gap_wait: float = 10.0
    save_every: float = 2.0
    slam: SlamConfig = field(default_factory=SlamConfig)
    judge: JudgeConfig = field(default_factory=JudgeConfig)
    ros2_out: bool = True
    map: MapperConfig = field(default_factory=MapperConfig)
    poses: PoseBufferConfig = field(default_factory=PoseBufferConfig)

    def __post_init__(self) -> None:
        require(self.pose_wait >= 0, "pose_wait", ">= 0", self.pose_wait)
        require(self.gap_wait >= 0, "gap_wait", ">= 0", self.gap_wait)
        require(self.save_every > 0, "save_every", "positive", self.save_every)
        parent, _, child = self.pose_frames.partition(">")
        require(bool(parent and child), "pose_frames", "PARENT>CHILD", self.pose_frames)


class MapperCore:
    """The mapping, the pose buffer and per-run counters behind one lock, shared by the workers.

    The mapping is the pipeline's stage (``services.pipeline.Mapping``): the map and, under
    ``--slam``, the pose correction.
    """

    def __init__(self, mapping: Mapping, stats: Stats, runs: Iterable[Progress] = ()) -> None:
        self.mapping = mapping
        self.corrector = mapping.corrector  # --slam
        self.judge = mapping.judge  # every pose judged against the walls (the default)
        self.poses = mapping.poses
        # What the judge found of the pose source, for `wallmap status`: replaced (never
        # changed in place) after each frame, so the status queryable reads it without a lock.
        self.pose_source: dict[str, Any] = {} if self.judge is None else self.judge.summary()
        self.stats = stats
        self.lock = threading.Condition()
        self.dirty = False
        # Set once UPDATE_FRAMES frames were integrated since the last map update (the map's
        # count of frames then): a bag played --fast goes through hundreds of frames a second,
        # and the odometry holds its poses onto the walls of those updates (every
        # UPDATE_PERIOD alone, it would see 150 frames old ones).
        self.update_due = threading.Event()
        self.updated_frames = self.map.frames
        # Each run's progress, with this process's epoch in every acknowledgement.
        self.progress = RunProgress(runs, epoch=uuid.uuid4().hex[:12])
        self._replies: dict[tuple[object, ...], bytes] = {}  # encoded, for one map state

    @property
    def map(self) -> WallMap:
        """The wall map (the mapping's: a remap replaces it)."""
        return self.mapping.map

    def source_pose(self, stamp: float, waited: float) -> SourcePose | Lookup:
        """The source's pose for the instant ``stamp``, at the stamp its latency says.

        A latency estimate may ask for a pose the source has not sent (yet, or ever, at the
        end of a run): after LATENCY_WAIT the newest pose is carried on to it, up to the
        lookahead the judge allows. Call with the lock held.
        """
        mapping = self.mapping
        ahead = mapping.lookahead if waited >= LATENCY_WAIT else 0.0
        return self.poses.sample(mapping.source_stamp(stamp), extrapolate=ahead)

    def reply(self, query: MapQuery, fmt: str) -> bytes:
        """The encoded map reply plus the mapper's counters, built once per map state.

        Many clients polling a map that does not change then cost one encoding between them.
        """
        counts = self.stats.snapshot()
        extra: dict[str, object] = {
            "dropped": counts.get("dropped", 0),
            "dropped_reasons": {
                reason: counts.get(f"dropped.{reason}", 0)
                for reason in (*DROP_REASONS.values(), BACKLOG)
            },
            "refused": counts.get("refused", 0),
            "skipped": counts.get("skipped", 0),
            "lost": counts.get("lost", 0),
            "missed": {what: counts.get(f"missed.{what}", 0) for what in ("observations", "poses")},
        }
        with self.lock:
            if self.corrector is not None:
                extra["slam"] = self.corrector.summary()
            if self.judge is not None:
                extra["pose_source"] = self.pose_source
            state = (self.map.version, len(self.map.merges), json.dumps(extra))
            if self._replies and next(iter(self._replies))[0] != state:
                self._replies.clear()
            key = (state, query, fmt)
            if key not in self._replies:
                body = replace(serving.reply(self.map, query), counters=extra).to_map()
                if fmt == "json":
                    self._replies[key] = json.dumps({"v": SCHEMA_VERSION, **body}).encode()
                else:
                    self._replies[key] = encode(body)
            return self._replies[key]


def run(
    settings: ZenohSettings,
    mapper: MapperSettings,
    stop: threading.Event,
    history: History | None = None,
    config: dict[str, Any] | None = None,
) -> Stats:
    """Run until ``stop`` is set, then save the state; returns the counters.

    ``history``: the window of observations and poses asked for at start and recovered.
    ``config``: the run's whole configuration (plain values), kept in the state file with the
    map, so a map says how it was made.
    """
    history = history or History()
    log = setup_logging("mapper")
    keys = Keys(settings.prefix)
    stats = Stats(log)
    core = _restore(mapper, stats, log)
    pose_key = mapper.pose_key or keys.pose
    log.info("connecting to %s (prefix %r)", ", ".join(settings.connect), settings.prefix)
    with open_session(settings, count=stats.add, stop=stop) as session:
        progress = session.declare_publisher(keys.progress)
        updates = session.declare_publisher(keys.map_updates)
        corrected = _CorrectedPoses(session, keys, log) if core.corrector is not None else None
        ros2 = Ros2Outlet(session, keys) if mapper.ros2_out else None
        observe = (progress, mapper.pose_wait, mapper.gap_wait, corrected)
        poses, observations = _subscribe(
            session, (pose_key, keys.observations), history, core, mapper, observe
        )
        queryable = session.declare_queryable(keys.map_walls)
        rooms = RoomsServer(session, keys, core.lock, core.mapping, stats, mapper.ros2_out)
        workers = [
            threading.Thread(
                target=answer_map_queries,
                args=(queryable.handler, core.reply, core.stats.add),
                daemon=True,
            ),
            threading.Thread(target=_updates, args=(core, updates, stop, ros2), daemon=True),
            threading.Thread(target=_repeat_progress, args=(core, progress, stop), daemon=True),
            *rooms.workers(stop),
        ]
        for worker in workers:
            worker.start()
        token = Presence(session, keys, "mapper", stats, lambda: _details(core))
        log.info("ready: poses from %s, observations from %s", pose_key, keys.observations)
        while not stop.wait(mapper.save_every):
            _save(core, mapper.state, config)
        log.info("stopping: %s", stats.snapshot())
        token.undeclare()
        for entity in (poses, observations, queryable, rooms, *([ros2] if ros2 else [])):
            entity.undeclare()
        for worker in (poses, observations, *workers):
            worker.join(timeout=5.0)
    _save(core, mapper.state, config)
    return stats


def _subscribe(
    session: zenoh.Session,
    keys: tuple[str, str],
    history: History,
    core: MapperCore,
    mapper: MapperSettings,
    observe: tuple[zenoh.Publisher, float, float, _CorrectedPoses | None],
) -> tuple[HistorySubscription, HistorySubscription]:
    """The poses and the observations, each with history.

    A mapper restarted on its state file takes what it missed meanwhile. ``observe``: the rest
    of what ``_observations`` takes.
    """
    pose_key, observation_key = keys
    pose_input = make_pose_input(mapper.pose_format, mapper.pose_frames)
    poses = subscribe_with_history(
        session,
        pose_key,
        history,
        lambda channel: _poses(channel, core, pose_input),
        _missed(core.stats, "poses"),
    )
    observations = subscribe_with_history(
        session,
        observation_key,
        history,
        lambda channel: _observations(channel, core, *observe),
        _missed(core.stats, "observations"),
    )
    return poses, observations


def _details(core: MapperCore) -> dict[str, Any]:
    """What ``wallmap status`` shows of the mapper beyond its counters (no lock: a snapshot)."""
    return {"pose_source": core.pose_source} if core.judge is not None else {}


def _missed(stats: Stats, what: str) -> Callable[[int], None]:
    """Counts and says what the history window could not bring back (Zenoh's thread)."""
    return lambda n: stats.note(
        f"missed.{what}", what, f"{n} {what} lost for good (past the history window)", n=n
    )


def _restore(mapper: MapperSettings, stats: Stats, log: logging.Logger) -> MapperCore:
    """The map, each run's progress and the pose correction, from the state file if there is one."""
    wall_map = state_file.load(mapper.state, mapper.map) if mapper.state else WallMap(mapper.map)
    if wall_map.walls:
        log.info("loaded %d walls from %s", len(wall_map.walls), mapper.state)
    runs = state_file.load_runs(mapper.state) if mapper.state else []
    corrector = _corrector(mapper)
    if corrector is not None:
        corrector.check(wall_map)
    judge = _judge(mapper) if corrector is None else None
    mapping = Mapping(
        judge=mapper.judge,
        wall_map=wall_map,
        corrector=corrector,
        judged=judge,
        poses=PoseBuffer(mapper.poses),
    )
    saved_rooms = state_file.load_entry(mapper.state, "rooms") if mapper.state else None
    if saved_rooms is not None:
        try:
            mapping.rooms.restore(saved_rooms)
        except ValueError as err:
            msg = f"state file {mapper.state} has an unusable 'rooms' entry ({err}); move it away"
            raise state_file.StateError(msg) from err
    return MapperCore(mapping, stats, runs)


def _corrector(mapper: MapperSettings) -> PoseCorrector | None:
    """The pose correction of ``--slam``, from the state file when it has one."""
    if not mapper.slam.enabled:
        return None
    return _restored(
        mapper,
        "slam",
        lambda: PoseCorrector(mapper.slam),
        lambda saved: PoseCorrector.from_json(saved, mapper.slam),
    )


def _judge(mapper: MapperSettings) -> PoseJudge | None:
    """The pose judge, from the state file when it has one (what it learnt of the source)."""
    if not mapper.judge.enabled:
        return None
    return _restored(
        mapper,
        "poses",
        lambda: PoseJudge(mapper.judge),
        lambda saved: PoseJudge.from_json(saved, mapper.judge),
    )


def _restored(
    mapper: MapperSettings,
    entry: str,
    fresh: Callable[[], T],
    restore: Callable[[dict[str, Any]], T],
) -> T:
    """A state file's ``entry`` restored, or ``fresh()`` without one; one line if unusable."""
    saved = state_file.load_entry(mapper.state, entry) if mapper.state else None
    if saved is None:
        return fresh()
    try:
        return restore(saved)
    except (KeyError, TypeError, ValueError) as err:
        msg = f"state file {mapper.state} has an unusable {entry!r} entry ({err}); move it away"
        raise state_file.StateError(msg) from err


class _CorrectedPoses:
    """``{prefix}/pose/corrected`` and ``{prefix}/pose/correction`` (map -> odom) under --slam.

    Published from the observations thread, frame by frame; DROP, so a slow reader never holds
    the map back. It also says when the pose runs on odometry alone, once per stretch.
    """

    ALONE_AFTER = 15  # frames without a wall fixing the pose before it is said

    def __init__(self, session: zenoh.Session, keys: Keys, log: logging.Logger) -> None:
        self._log = log
        drop = zenoh.CongestionControl.DROP
        self._pose = session.declare_publisher(keys.pose_corrected, congestion_control=drop)
        self._correction = session.declare_publisher(keys.pose_correction, congestion_control=drop)
        self._alone_since: int | None = None

    def publish(self, corrector: PoseCorrector, pose: Pose, odom_frame: str) -> None:
        """Say the corrected pose of a frame, and the correction that takes odometry there."""
        self._pose.put(pack(pose))
        if (correction := corrector.correction(pose.stamp, odom_frame)) is not None:
            self._correction.put(pack(correction))
        if corrector.streak == 0:
            if self._alone_since is not None and self._alone_since >= self.ALONE_AFTER:
                self._log.info("walls fix the pose again after %d frames", self._alone_since)
            self._alone_since = None
            return
        self._alone_since = corrector.streak
        if corrector.streak == self.ALONE_AFTER:
            self._log.warning(
                "running on odometry alone: no mapped wall fixed the pose for %d frames",
                self.ALONE_AFTER,
            )


def _save(core: MapperCore, path: Path | None, config: dict[str, Any] | None) -> None:
    if path is None:
        return
    with core.lock:
        if not core.dirty:
            return
        slam = core.corrector.to_json() if core.corrector is not None else None
        poses = core.judge.to_json() if core.judge is not None else None
        runs = core.progress.runs.values()
        rooms = core.mapping.rooms.to_json()
        document = state_file.to_json(core.map, runs, slam, config, poses, rooms)
        core.dirty = False
    state_file.write(path, document)


def _poses(
    channel: zenoh.handlers.Handler[zenoh.Sample], core: MapperCore, pose_input: PoseInput
) -> None:
    for sample in drain(channel):
        try:
            poses = pose_input.decode(sample.payload.to_bytes(), str(sample.key_expr))
        except MessageError as err:
            core.stats.refuse("pose", str(err))
            continue
        with core.lock:
            for pose in poses:
                core.poses.add(pose)
            core.lock.notify_all()
        core.stats.add("poses", len(poses))


def _observations(
    channel: zenoh.handlers.Handler[zenoh.Sample],
    core: MapperCore,
    progress: zenoh.Publisher,
    pose_wait: float,
    gap_wait: float,
    corrected: _CorrectedPoses | None = None,
) -> None:
    """Fold observations into the map in frame order, each once its pose is known."""
    waiting = _Waiting(core, pose_wait, gap_wait, corrected)
    unacked = 0  # frames processed since the last acknowledgement
    while True:
        try:
            if not waiting.pending and not waiting.order.waiting():
                core.progress.flush(progress.put)  # idle: tell the players where we are
                unacked = 0
                waiting.add(channel.recv())
            # Everything that has arrived, before any wait for a pose: a full channel would
            # stall the session's receiving thread, and with it the poses these observations
            # wait for and every map query.
            while (sample := channel.try_recv()) is not None:
                waiting.add(sample)
        except zenoh.ZError:
            return
        waiting.add(None)  # time passes: gaps held too long are given up
        done = waiting.process()
        if not done and not waiting.pending:
            time.sleep(HOLD_POLL)  # a gap is held: history may fill it
        unacked += done
        if unacked >= ACK_EVERY:
            core.progress.flush(progress.put)
            unacked = 0


def _updates(
    core: MapperCore, updates: zenoh.Publisher, stop: threading.Event, ros2: Ros2Outlet | None
) -> None:
    """Publish the walls that changed, and the ROS 2 markers.

    An update goes every UPDATE_PERIOD s, or sooner once UPDATE_FRAMES frames were integrated,
    when walls changed or frames were integrated (its frames and stamp say how current the map
    is). The markers (the whole served map, rebuilt: tens of ms for a thousand walls) go at
    most every UPDATE_PERIOD s, and once more after the last change.
    """
    markers_stale, markers_due = False, 0.0
    while not stop.is_set():
        core.update_due.wait(UPDATE_PERIOD)
        core.update_due.clear()
        served = None
        with core.lock:
            changed = bool(core.map.changed or core.map.removed)
            grown = changed or core.map.frames != core.updated_frames
            changes = serving.take_changes(core.map) if grown else None
            core.updated_frames = core.map.frames
            markers_stale |= changed
            if ros2 is not None and markers_stale and time.monotonic() >= markers_due:
                served = serving.reply(core.map, MapQuery(trajectory=True))
                markers_stale, markers_due = False, time.monotonic() + UPDATE_PERIOD
        if changes is not None:
            updates.put(encode(changes.to_map()))
        if ros2 is not None and served is not None:
            ros2.publish(served)


def _repeat_progress(core: MapperCore, progress: zenoh.Publisher, stop: threading.Event) -> None:
    """Say the newest run's progress again every ACK_REPEAT s, for REPEAT_FOR s after it moved.

    An acknowledgement sent while a router restarts is lost, and an idle mapper has nothing new
    to say: the player would wait for it until it gives up. Saying it again costs a small
    message a second; a player takes the furthest it has heard.
    """
    said, moved = None, 0.0
    while not stop.wait(ACK_REPEAT):
        with core.lock:
            latest = next(reversed(core.progress.runs.values()), None)
        if latest is None:
            continue
        if latest != said:
            said, moved = latest, time.monotonic()
        if time.monotonic() - moved <= REPEAT_FOR:
            progress.put(pack(latest))


class _Waiting:
    """Observations in frame order (``InOrder``), then waiting for their poses; runs' progress.

    At most MAX_PENDING wait for poses: when poses are that far behind, the oldest gives way
    (dropped and counted), so the mapper never stops reading its channel.
    """

    def __init__(
        self,
        core: MapperCore,
        pose_wait: float,
        gap_wait: float,
        corrected: _CorrectedPoses | None = None,
    ) -> None:
        self.core = core
        self.corrected = corrected
        self.pose_wait = pose_wait
        self.pending: collections.deque[tuple[float, Observations]] = collections.deque()
        with core.lock:  # runs restored from the state file go on from where they stood
            self.order = InOrder(core.progress.runs.values(), gap_wait=gap_wait)

    def add(self, sample: zenoh.Sample | None) -> None:
        """Take a received sample (None: none, time passed): in frame order, once each."""
        obs = None
        if sample is not None:
            try:
                obs = unpack_observations(sample.payload.to_bytes())
            except MessageError as err:
                self.core.stats.refuse("observations", str(err))
                return
        taken = self.order.take(obs, time.monotonic())
        for again in taken.repeated:  # its acknowledgement was lost on the way: say it again
            self.core.stats.add("repeated")
            with self.core.lock:
                self.core.progress.again(again.run)
        if taken.lost:
            self.core.stats.note(
                "lost",
                "lost",
                f"gave up {taken.lost} frames that never came (past the history "
                "window, or a service was down longer)",
                n=taken.lost,
            )
        for ready in taken.ready:
            self._queue(ready)

    def _queue(self, obs: Observations) -> None:
        if len(self.pending) >= MAX_PENDING:
            _, oldest = self.pending.popleft()
            self._done(oldest, integrated=False)
            _count_drop(self.core.stats, oldest, BACKLOG, self.pose_wait)
        self.pending.append((time.monotonic(), obs))

    def process(self) -> int:
        """Integrate or drop the observations at the head whose turn has come; how many."""
        done = 0
        while self.pending and self._process_head():
            done += 1
        return done

    def _process_head(self) -> bool:
        """Integrate or drop the oldest observation; False when it must wait longer."""
        core = self.core
        arrived, obs = self.pending[0]
        if obs.skipped:  # the detector skipped it (behind in real time) and said so
            self.pending.popleft()
            self._done(obs, integrated=False)
            core.stats.add("skipped")
            return True
        with core.lock:
            source = core.source_pose(obs.stamp, time.monotonic() - arrived)
            if source is Lookup.WAIT and time.monotonic() - arrived < self.pose_wait:
                core.lock.wait(timeout=0.05)  # woken by a new pose
                return False
            self.pending.popleft()
            integrated = not isinstance(source, Lookup)
            if isinstance(source, SourcePose):
                pose = core.mapping.integrate(obs, source)
                if core.corrector is not None and self.corrected is not None and pose:
                    self.corrected.publish(core.corrector, pose, source.pose.frame)
                if core.judge is not None:
                    core.pose_source = core.judge.summary()
                core.dirty = True
                if core.map.frames - core.updated_frames >= UPDATE_FRAMES:
                    core.update_due.set()
            self._done(obs, integrated=integrated)
        if integrated:
            core.stats.add("integrated")
        else:
            _count_drop(core.stats, obs, DROP_REASONS[source], self.pose_wait)
        return True

    def _done(self, obs: Observations, *, integrated: bool) -> None:
        with self.core.lock:
            self.core.progress.count(obs.run, obs.seq, integrated=integrated)


def _count_drop(stats: Stats, obs: Observations, reason: str, pose_wait: float) -> None:
    """Count and log (at most once a second per reason) a frame dropped for want of a pose."""
    why = {
        "pose_timeout": f"no pose covered it within {pose_wait:.1f} s (is a pose source running?)",
        "no_pose": "no pose near its stamp (before the first pose, or in a gap)",
        BACKLOG: f"{MAX_PENDING} newer frames wait for poses too (is a pose source running?)",
    }[reason]
    stats.add("dropped")
    stats.note(f"dropped.{reason}", reason, f"dropped the frame at {obs.stamp:.3f}: {why}")
