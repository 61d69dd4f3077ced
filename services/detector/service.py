"""The detector service: sensor frames in over Zenoh, wall observations out.

Frames arrive through a bounded FIFO channel that the service's own thread drains. Under
``wallmap player --fast``, when the detector falls behind, the channel fills and Zenoh pushes back
on the publisher (the observations are sent with congestion control BLOCK), so no frame is lost;
in real-time playback it works off short bursts in order and skips to the newest frame only when
truly behind (``frames_in_turn``).
"""

from __future__ import annotations

import threading

import zenoh

from wallmap.common.allocator import keep_large_buffers
from wallmap.common.codec import encode
from wallmap.common.messages import pack
from wallmap.common.ransac import RowReport
from wallmap.common.runtime import (
    Presence,
    Stats,
    drain,
    frames_in_turn,
    setup_logging,
)
from wallmap.common.transport import Keys, ZenohSettings, open_session
from wallmap.services.detector.detector import DetectorConfig, WallDetector

QUEUE_DEPTH = 8


def run(settings: ZenohSettings, config: DetectorConfig, stop: threading.Event) -> Stats:
    """Run until ``stop`` is set; returns the counters."""
    log = setup_logging("detector")
    keep_large_buffers()  # whole clouds are megabytes each
    keys = Keys(settings.prefix)
    stats = Stats(log)
    detector = WallDetector(config)
    log.info("connecting to %s (prefix %r)", ", ".join(settings.connect), settings.prefix)
    with open_session(settings, count=stats.add) as session:
        publisher = session.declare_publisher(
            keys.observations, congestion_control=zenoh.CongestionControl.BLOCK
        )
        diagnostics = session.declare_publisher(keys.detector_diagnostics)
        subscriber = session.declare_subscriber(
            keys.frames, zenoh.handlers.FifoChannel(QUEUE_DEPTH)
        )
        rows = session.declare_queryable(keys.detector_rows)
        token = Presence(session, keys, "detector", stats)
        workers = [
            threading.Thread(
                target=_work,
                args=(subscriber.handler, detector, publisher, diagnostics, stats),
                daemon=True,
            ),
            threading.Thread(target=_answer_rows, args=(rows.handler, config), daemon=True),
        ]
        for worker in workers:
            worker.start()
        log.info("ready: %s -> %s (rows: %s)", keys.frames, keys.observations, config.rows)
        stop.wait()
        log.info("stopping: %s", stats.snapshot())
        token.undeclare()
        subscriber.undeclare()
        rows.undeclare()
        for worker in workers:
            worker.join(timeout=5.0)
    return stats


def _answer_rows(channel: zenoh.handlers.Handler[zenoh.Query], config: DetectorConfig) -> None:
    """Tell players which row to send: they then send that row only, not whole clouds."""
    for query in drain(channel):
        with query:
            query.reply(query.key_expr, encode(config.rows.to_map()))


def _work(
    channel: zenoh.handlers.Handler[zenoh.Sample],
    detector: WallDetector,
    publisher: zenoh.Publisher,
    diagnostics: zenoh.Publisher,
    stats: Stats,
) -> None:
    """Detect walls in every frame until the subscriber is undeclared.

    Each frame's diagnostics (points, clusters, lines, what was turned down and why) go out on
    their own key; Zenoh sends nothing when nobody listens.
    """
    for frame in frames_in_turn(channel, stats):
        report = RowReport()
        observations = detector.detect(frame, report)
        publisher.put(pack(observations))
        diagnostics.put(
            encode(
                {
                    "run": frame.run,
                    "seq": frame.seq,
                    "stamp": frame.stamp,
                    "sensor": frame.sensor,
                    "band": None if frame.band is None else list(frame.band),
                    "walls": len(observations.walls),
                    "noise_scale": detector.noise[frame.sensor].scale,
                    **report.to_map(),
                }
            )
        )
        stats.add("published")
        stats.add("walls", len(observations.walls))
