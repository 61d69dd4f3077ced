"""The odometry service: poses from the sensor frames, for recordings that carry none.

It listens to the same frames as the detector, turns each into its scan row (the detector's row
choice), registers it (``PoseTracker``) and publishes the pose on ``{prefix}/pose`` at the
frame's stamp, where the mapper waits for it. With ``--pose-source none`` on the player, a bag
with nothing but a lidar or a depth camera makes a map. The walls the mapper confirms come back
on ``{prefix}/map/updates`` (and one query at start) and hold the poses onto the map.
"""

from __future__ import annotations

import logging
import queue
import threading

import zenoh
from zenoh.ext import AdvancedPublisher

from wallmap.common.codec import MessageError
from wallmap.common.delivery import declare_history_publisher, received_frames
from wallmap.common.link_settings import HistorySettings, ZenohSettings
from wallmap.common.map_requests import MalformedReplyError, QueryError, fetch_map
from wallmap.common.messages import pack
from wallmap.common.runtime import Presence, Stats, exempt_startup_objects, setup_logging
from wallmap.common.scan_row import RowSelection, finite_scan
from wallmap.common.transport import Keys, open_session
from wallmap.services.odometry.tracker import OdometryConfig, PoseTracker

LOG = logging.getLogger("wallmap.odometry")
QUEUE_DEPTH = 8


def run(
    settings: ZenohSettings,
    config: OdometryConfig,
    stop: threading.Event,
    rows: RowSelection | None = None,
    history: HistorySettings | None = None,
) -> Stats:
    """Run until ``stop`` is set; returns the counters.

    Args:
        settings: The Zenoh session.
        config: The tracker's tuning.
        stop: Set to stop.
        rows: How a depth frame becomes a scan row (the detector's choice by default).
        history: The window of poses kept for a mapper that missed them.
    """
    log = setup_logging("odometry")
    keys = Keys(settings.prefix)
    stats = Stats(log)
    tracker = PoseTracker(config)
    rows, history = rows or RowSelection(), history or HistorySettings()
    log.info("connecting to %s (prefix %r)", ", ".join(settings.connect), settings.prefix)
    with open_session(settings, count=stats.add, stop=stop) as session:
        # Poses with history, for a mapper that restarts; frames without: scan matching goes
        # in order, and a restarted odometry starts afresh.
        publisher = declare_history_publisher(session, keys.pose, history.samples())
        frames = session.declare_subscriber(keys.frames, zenoh.handlers.FifoChannel(QUEUE_DEPTH))
        # Map updates come at most twice a second; a callback queues them for the worker, which
        # takes them before each frame (a channel read only then could fill and stall the session).
        updates: queue.SimpleQueue[bytes] | None = None
        updates_sub = None
        if config.use_walls:
            updates = queue.SimpleQueue()
            updates_sub = session.declare_subscriber(
                keys.map_updates, lambda sample: updates.put(sample.payload.to_bytes())
            )
        token = Presence(session, keys, "odometry", stats)
        if config.use_walls:
            _first_walls(session, keys, tracker, stats)
        worker = threading.Thread(
            target=_work,
            args=(frames.handler, updates, tracker, rows, publisher, stats),
            daemon=True,
        )
        worker.start()
        exempt_startup_objects()
        log.info(
            "ready: %s -> %s (walls as landmarks: %s)",
            keys.frames,
            keys.pose,
            "yes" if config.use_walls else "no",
        )
        stop.wait()
        log.info("stopping: %s", stats.snapshot())
        token.undeclare()
        frames.undeclare()
        if updates_sub is not None:
            updates_sub.undeclare()
        worker.join(timeout=5.0)
    return stats


def _first_walls(session: zenoh.Session, keys: Keys, tracker: PoseTracker, stats: Stats) -> None:
    """The walls mapped before this service started (a restart, or a map kept in a state file)."""
    try:
        tracker.set_walls(fetch_map(session, keys, timeout=1.0).walls)
    except MalformedReplyError as err:
        stats.refuse("map", str(err))
    except QueryError:
        return  # no mapper yet: the walls come with its updates


def _take_updates(updates: queue.SimpleQueue[bytes], tracker: PoseTracker, stats: Stats) -> None:
    while not updates.empty():
        try:
            tracker.take_update(updates.get_nowait())
        except MessageError as err:
            stats.refuse("map update", str(err))


def _work(
    frames: zenoh.handlers.Handler[zenoh.Sample],
    updates: queue.SimpleQueue[bytes] | None,
    tracker: PoseTracker,
    rows: RowSelection,
    publisher: AdvancedPublisher,
    stats: Stats,
) -> None:
    """A pose for every frame, in arrival order, until the subscriber is undeclared."""
    run = None
    for frame in received_frames(frames, stats):
        if frame.run != run:
            if run is not None:
                tracker.restart()
                stats.add("restarts")
                LOG.info("a new run (%s): scan matching starts afresh", frame.run)
            run = frame.run
        if frame.sensor == "depth":
            stats.note(
                "depth_frames",
                "depth",
                "scan matching on a depth camera's row (about 60 degrees wide) is unreliable; "
                "prefer a lidar, or give the player a pose source (docs/real-data.md)",
            )
        if updates is not None:  # the walls are used
            _take_updates(updates, tracker, stats)
        estimate = tracker.update(finite_scan(frame, rows), frame.stamp)
        if not estimate.registration.accepted:
            reason = estimate.registration.reason
            stats.note("unmatched", reason, f"scan at {frame.stamp:.3f} not matched: {reason}")
        if estimate.wall_points:
            stats.add("wall_refined")
        publisher.put(pack(estimate.pose))
        stats.add("published")
