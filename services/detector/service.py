"""The detector service: sensor frames in over Zenoh, wall observations out.

Frames arrive with the history window (``common.delivery``: a detector restarted mid-run gets the
frames it missed, a link back recovers what was lost on it) through a channel that the
service's own thread drains. Under ``wallmap player --fast`` the player keeps at most 16 frames
beyond what the mapper acknowledged in flight, so a slow detector slows the player and nothing
is lost; in real-time playback it works off bursts in order and skips to the newest frame only
when more than twice the window behind (``frames_in_turn``), telling the mapper which frames it
skipped. Observations are published with the history window too, for a mapper that restarts.
"""

from __future__ import annotations

import threading

import zenoh
from zenoh.ext import AdvancedPublisher

from wallmap.common.allocator import keep_large_buffers
from wallmap.common.codec import encode
from wallmap.common.compiled import compile_detector
from wallmap.common.delivery import (
    declare_history_publisher,
    frames_in_turn,
    subscribe_with_history,
)
from wallmap.common.link_settings import HistorySettings, ZenohSettings
from wallmap.common.messages import Frame, Observations, pack
from wallmap.common.ransac import RowReport
from wallmap.common.runtime import (
    Presence,
    Stats,
    drain,
    exempt_startup_objects,
    setup_logging,
)
from wallmap.common.transport import Keys, open_session
from wallmap.services.detector.detector import DetectorConfig, WallDetector


def run(
    settings: ZenohSettings,
    config: DetectorConfig,
    stop: threading.Event,
    history: HistorySettings | None = None,
) -> Stats:
    """Run until ``stop`` is set; returns the counters.

    ``history``: the window of frames asked for at start and recovered after a loss, and of
    observations kept for a mapper that missed them.
    """
    history = history or HistorySettings()
    log = setup_logging("detector")
    keep_large_buffers()  # whole clouds are megabytes each
    keys = Keys(settings.prefix)
    stats = Stats(log)
    detector = WallDetector(config)
    if (readied := compile_detector()).compiled:
        log.info(
            "compiled the line search in %.1f s (once; cached for later starts)", readied.seconds
        )
    log.info("connecting to %s (prefix %r)", ", ".join(settings.connect), settings.prefix)
    with open_session(settings, count=stats.add, stop=stop) as session:
        publisher = declare_history_publisher(session, keys.observations, history.samples())
        diagnostics = session.declare_publisher(keys.detector_diagnostics)
        frames = subscribe_with_history(
            session,
            keys.frames,
            history,
            lambda channel: _work(channel, detector, publisher, diagnostics, stats, history),
            lambda n: stats.note(
                "missed", "missed", f"{n} frames lost for good (past the history window)", n=n
            ),
        )
        rows = session.declare_queryable(keys.detector_rows)
        token = Presence(session, keys, "detector", stats)
        answers = threading.Thread(target=_answer_rows, args=(rows.handler, config), daemon=True)
        answers.start()
        exempt_startup_objects()
        log.info("ready: %s -> %s (rows: %s)", keys.frames, keys.observations, config.rows)
        stop.wait()
        log.info("stopping: %s", stats.snapshot())
        token.undeclare()
        frames.undeclare()
        rows.undeclare()
        for worker in (frames, answers):
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
    publisher: AdvancedPublisher,
    diagnostics: zenoh.Publisher,
    stats: Stats,
    history: HistorySettings,
) -> None:
    """Detect walls in every frame until the subscriber is undeclared.

    Each frame's diagnostics (points, clusters, lines, what was turned down and why) go out on
    their own key; Zenoh sends nothing when nobody listens.
    """

    def skipped(frames: list[Frame]) -> None:  # the mapper need not wait for them
        for frame in frames:
            publisher.put(
                pack(
                    Observations(
                        frame.run,
                        frame.seq,
                        frame.stamp,
                        "base_link",
                        lossless=frame.lossless,
                        skipped=True,
                    )
                )
            )

    for frame in frames_in_turn(channel, stats, history, skipped):
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
