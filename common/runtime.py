"""What every long-running service needs: logging, counters of refused input, clean shutdown."""

from __future__ import annotations

import collections
import logging
import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Iterator
from types import FrameType
from typing import TypeVar

import zenoh

from wallmap.common.codec import MessageError, encode
from wallmap.common.messages import Frame, unpack_frame
from wallmap.common.transport import Keys

log = logging.getLogger("wallmap")
T = TypeVar("T")


def setup_logging(service: str) -> logging.Logger:
    """Log lines of ``time level service: message`` to stderr, level from ``WALLMAP_LOG``."""
    level = os.environ.get("WALLMAP_LOG", "INFO").upper()
    logging.basicConfig(
        level=level if level in logging.getLevelNamesMapping() else "INFO",
        format=f"%(asctime)s %(levelname)s {service}: %(message)s",
    )
    zenoh.init_log_from_env_or("error")
    return logging.getLogger(f"wallmap.{service}")


class Stats:
    """Thread-safe counters, with refusals logged by reason (at most once a second per reason)."""

    def __init__(self, logger: logging.Logger) -> None:
        self._counts: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._log = logger
        self._last_logged: dict[str, float] = {}

    def add(self, name: str, n: int = 1) -> None:
        """Count ``n`` events of kind ``name``."""
        with self._lock:
            self._counts[name] += n

    def refuse(self, what: str, reason: str) -> None:
        """Count and log a refused message; the service carries on."""
        self.add("refused")
        self.note(f"refused.{what}", reason, f"refused {what}: {reason}")

    def note(self, name: str, kind: str, message: str, n: int = 1) -> None:
        """Count ``n`` events and log them, at most once a second for each ``kind``."""
        with self._lock:
            self._counts[name] += n
            now = time.monotonic()
            quiet = now - self._last_logged.get(kind, -1e9) < 1.0
            if not quiet:
                self._last_logged[kind] = now
        if not quiet:
            self._log.warning("%s", message)

    def snapshot(self) -> dict[str, int]:
        """A copy of all counters."""
        with self._lock:
            return dict(self._counts)


def _frame_of(sample: zenoh.Sample, stats: Stats) -> Frame | None:
    """A received sample as a frame, counted; None (refused and counted) when malformed."""
    stats.add("received")
    try:
        return unpack_frame(sample.payload.to_bytes())
    except MessageError as err:
        stats.refuse("frame", str(err))
        return None


def received_frames(channel: zenoh.handlers.Handler[zenoh.Sample], stats: Stats) -> Iterator[Frame]:
    """The sensor frames a subscriber receives, counted; malformed ones refused and counted."""
    for sample in drain(channel):
        if (frame := _frame_of(sample, stats)) is not None:
            yield frame


BEHIND = 15  # real-time frames waiting (half a second of a 30 Hz camera) before skipping


def frames_in_turn(
    channel: zenoh.handlers.Handler[zenoh.Sample], stats: Stats, behind: int = BEHIND
) -> Iterator[Frame]:
    """The frames to process, in order; in real-time playback, skipping when truly behind.

    A service slower than the bag must not fall further and further behind: when more than
    ``behind`` real-time frames wait, it skips to the newest, counts what it skipped and says
    so. A short burst (a busy moment on a shared machine) is worked off in order instead. The
    channel is emptied each turn, so it never fills and never stalls the session. Frames of a
    player that sends again (``--fast``) are never dropped and not read ahead: that player
    waits for the pipeline, and the channel's back-pressure is what makes it wait.
    """
    waiting: collections.deque[Frame] = collections.deque()
    for first in received_frames(channel, stats):
        waiting.append(first)
        while waiting:
            while not waiting[-1].resends and (sample := channel.try_recv()) is not None:
                if (frame := _frame_of(sample, stats)) is not None:
                    waiting.append(frame)
            live = [frame for frame in waiting if not frame.resends]
            if len(live) > behind:
                newest = live[-1]
                waiting = collections.deque(f for f in waiting if f.resends or f is newest)
                stats.note(
                    "dropped",
                    "behind",
                    f"skipped {len(live) - 1} frames: slower than real-time playback "
                    "(--fast loses none)",
                    n=len(live) - 1,
                )
            yield waiting.popleft()


class Presence:
    """A service's liveliness token and its counters' queryable: what ``wallmap status`` reads.

    Both stay declared while this object lives; ``undeclare`` ends them at shutdown.
    """

    def __init__(self, session: zenoh.Session, keys: Keys, service: str, stats: Stats) -> None:
        self._service, self._stats, self._started = service, stats, time.time()
        self.token = session.liveliness().declare_token(keys.health(service))
        # Replying to the query at hand from its callback is quick: one locked copy.
        self.queryable = session.declare_queryable(keys.stats(service), self._reply)

    def _reply(self, query: zenoh.Query) -> None:
        body = {
            "service": self._service,
            "uptime": time.time() - self._started,
            "counters": self._stats.snapshot(),
        }
        query.reply(query.key_expr, encode(body))

    def undeclare(self) -> None:
        """Leave: the service no longer shows as live."""
        self.token.undeclare()
        self.queryable.undeclare()


def stop_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM, so services shut down and save their state."""
    stop = threading.Event()

    def handler(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def drain(channel: zenoh.handlers.Handler[T]) -> Iterator[T]:
    """Everything a Zenoh channel receives, until its subscriber or queryable is undeclared."""
    while True:
        try:
            yield channel.recv()
        except zenoh.ZError:
            return
