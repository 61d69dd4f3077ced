"""The mapper service: poses and wall observations in, the wall map served as a queryable.

Only wiring: threads draining Zenoh channels (no work in Zenoh's callbacks) around the pure
parts. Poses go into the core's buffer; observations go through the ``Intake`` (frame order,
pose waits, drops) into the ``Mapping``; queries get a cached reply; map updates and repeated
acknowledgements go out on their own threads; the state file is saved from the main thread.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from wallmap.common import compiled
from wallmap.common.codec import MessageError, encode
from wallmap.common.delivery import HistorySubscription, subscribe_with_history
from wallmap.common.frame_order import ACK_EVERY
from wallmap.common.link_settings import HistorySettings, ZenohSettings
from wallmap.common.map_query import MapQuery
from wallmap.common.map_requests import answer_map_queries
from wallmap.common.messages import pack
from wallmap.common.runtime import (
    Presence,
    Stats,
    drain,
    exempt_startup_objects,
    setup_logging,
)
from wallmap.common.transport import Keys, open_session
from wallmap.services.mapper import ros2_out, serving
from wallmap.services.mapper.core import MapperCore
from wallmap.services.mapper.corrected_poses import CorrectedPoses
from wallmap.services.mapper.intake import Intake
from wallmap.services.mapper.pose_input import PoseInput, make_pose_input
from wallmap.services.mapper.restore import restore, save
from wallmap.services.mapper.rooms_server import RoomsServer
from wallmap.services.mapper.ros2_out import Ros2Outlet
from wallmap.services.mapper.settings import MapperSettings

HOLD_POLL = 0.02  # s between looks at a held gap
POSE_POLL = 0.05  # s a frame waiting for its pose sleeps, unless a pose comes sooner
UPDATE_PERIOD = 0.5  # s between map updates while busy
ACK_REPEAT = 1.0  # s between two repeats of the newest run's acknowledgement...
REPEAT_FOR = 30.0  # ...for this long after it last moved


def _load_ahead(log: logging.Logger, ros2: bool) -> None:
    """What the mapper would load at first use, loaded before it says ready.

    Its frame path's compiled loops (the pose judge's, the map's) and, publishing to ROS 2,
    the typestore and its serializers: loaded at first use, numba's import and cache and
    rosbags' typestore (some tenths of a second of CPU each) fell among a recording's first
    frames and slowed them. The rooms' loops load on the rooms' worker as it starts, off the
    frame path (``compiled.compile_mapper``).
    """
    if (readied := compiled.compile_mapper()).compiled:
        log.info(
            "compiled the mapper's loops in %.1f s (once; cached for later starts)",
            readied.seconds,
        )
    if ros2:
        ros2_out.warm_up()
    exempt_startup_objects()  # what is loaded by now lives as long as the mapper


def run(
    settings: ZenohSettings,
    mapper: MapperSettings,
    stop: threading.Event,
    history: HistorySettings | None = None,
    config: dict[str, Any] | None = None,
) -> Stats:
    """Run until ``stop`` is set, then save the state; returns the counters.

    ``history``: the window of observations and poses asked for at start and recovered.
    ``config``: the run's whole configuration (plain values), kept in the state file with the
    map, so a map says how it was made.
    """
    history = history or HistorySettings()
    log = setup_logging("mapper")
    keys = Keys(settings.prefix)
    stats = Stats(log)
    core = restore(mapper, stats, log)
    _load_ahead(log, mapper.ros2_out)
    pose_key = mapper.pose_key or keys.pose
    log.info("connecting to %s (prefix %r)", ", ".join(settings.connect), settings.prefix)
    with open_session(settings, count=stats.add, stop=stop) as session:
        progress = session.declare_publisher(keys.progress)
        updates = session.declare_publisher(keys.map_updates)
        core.updates_wanted = updates.matching_status.matching
        listening = updates.declare_matching_listener(
            lambda status: setattr(core, "updates_wanted", status.matching)
        )
        corrected = CorrectedPoses(session, keys, log) if core.corrector is not None else None
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
            save(core, mapper.state, config)
        log.info("stopping: %s", stats.snapshot())
        token.undeclare()
        for entity in (poses, observations, queryable, listening, rooms, *([ros2] if ros2 else [])):
            entity.undeclare()
        for worker in (poses, observations, *workers):
            worker.join(timeout=5.0)
    save(core, mapper.state, config)
    return stats


def _subscribe(
    session: zenoh.Session,
    keys: tuple[str, str],
    history: HistorySettings,
    core: MapperCore,
    mapper: MapperSettings,
    observe: tuple[zenoh.Publisher, float, float, CorrectedPoses | None],
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
            core.poses_added += len(poses)
            core.lock.notify_all()
        core.stats.add("poses", len(poses))


def _observations(
    channel: zenoh.handlers.Handler[zenoh.Sample],
    core: MapperCore,
    progress: zenoh.Publisher,
    pose_wait: float,
    gap_wait: float,
    corrected: CorrectedPoses | None = None,
) -> None:
    """Fold observations into the map in frame order, each once its pose is known (``Intake``)."""
    on_pose = None
    if corrected is not None and core.corrector is not None:
        corrector = core.corrector
        on_pose = lambda pose, frame: corrected.publish(corrector, pose, frame)  # noqa: E731
    intake = Intake(core, pose_wait, gap_wait, on_pose)
    unacked = 0  # frames processed since the last acknowledgement
    while True:
        try:
            if intake.idle:
                core.progress.flush(progress.put)  # idle: tell the players where we are
                unacked = 0
                intake.add(channel.recv().payload.to_bytes(), time.monotonic())
            # Everything that has arrived, before any wait for a pose: a full channel would
            # stall the session's receiving thread, and with it the poses these observations
            # wait for and every map query.
            while (sample := channel.try_recv()) is not None:
                intake.add(sample.payload.to_bytes(), time.monotonic())
        except zenoh.ZError:
            return
        intake.tick(time.monotonic())
        done = intake.process(time.monotonic())
        if intake.pending and not done:  # the head waits for its pose: woken by a new one
            with core.lock:
                core.lock.wait_for(lambda: core.poses_added != intake.poses_seen, POSE_POLL)
        elif not done:
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
    is); while nothing subscribes to them, the changes are held (``serving.HeldChanges``). The
    markers (the whole served map, rebuilt: tens of ms for a thousand walls) go at most every
    UPDATE_PERIOD s, and once more after the last change.
    """
    markers_stale, markers_due = False, 0.0
    held = serving.HeldChanges()  # while nothing subscribes to the updates
    while not stop.is_set():
        core.update_due.wait(UPDATE_PERIOD)
        core.update_due.clear()
        served, changes = None, None
        with core.lock:
            changed = bool(core.map.changed or core.map.removed)
            markers_stale |= changed
            if core.updates_wanted:
                held.give_back(core.map)
                if core.map.changed or core.map.removed or core.map.frames != core.updated_frames:
                    changes = serving.take_changes(core.map)
            else:
                held.hold(core.map)
            core.updated_frames = core.map.frames
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
