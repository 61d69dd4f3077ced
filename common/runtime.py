"""What every long-running service needs: logging, counters of refused input, clean shutdown."""

from __future__ import annotations

import collections
import logging
import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from types import FrameType
from typing import TypeVar

import zenoh

from wallmap.common.codec import MessageError, encode
from wallmap.common.history import History
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


class _Once:
    """Which frames were taken already, among the last ``size``: history can bring one twice."""

    def __init__(self, size: int) -> None:
        self._size = size
        self._seen: collections.OrderedDict[tuple[str, int], None] = collections.OrderedDict()

    def first(self, frame: Frame) -> bool:
        """Whether this is the first time ``frame`` comes (and remember it)."""
        key = (frame.run, frame.seq)
        if key in self._seen:
            return False
        self._seen[key] = None
        if len(self._seen) > self._size:
            self._seen.popitem(last=False)
        return True


def frames_in_turn(
    channel: zenoh.handlers.Handler[zenoh.Sample],
    stats: Stats,
    history: History,
    on_skip: Callable[[list[Frame]], None] | None = None,
) -> Iterator[Frame]:
    """The frames to process, in arrival order; in real-time playback, skipping when far behind.

    A service slower than the bag must not fall further and further behind: when more real-time
    frames wait than twice the history window holds (its frames at the highest rate, or its
    bytes: a restarted service's catch-up on the whole window, and as much again), it skips to
    the newest, counts what it skipped, says so and hands the skipped frames to
    ``on_skip`` (the detector tells the mapper, which then does not wait for them). A burst (a
    busy moment, the history a restarted service catches up on) is worked off in order. The
    channel is emptied each turn, so it never fills and never stalls the session. Frames of a
    player that waits for the pipeline (``--fast``) are never dropped and not read ahead (that
    player keeps only a few in flight). A frame that comes again
    (from history) is counted as ``repeated`` and not taken twice.
    """
    most = history.samples()
    once = _Once(4 * most)
    waiting: collections.deque[Frame] = collections.deque()

    def take(frame: Frame) -> None:
        if once.first(frame):
            waiting.append(frame)
        else:
            stats.add("repeated")

    for first in received_frames(channel, stats):
        take(first)
        while waiting:
            try:
                while not waiting[-1].lossless and (sample := channel.try_recv()) is not None:
                    if (frame := _frame_of(sample, stats)) is not None:
                        take(frame)
            except zenoh.ZError:  # the subscriber was undeclared: the service stops
                return
            live = [frame for frame in waiting if not frame.lossless]
            if len(live) > 2 * most or sum(f.points.nbytes for f in live) > 2 * history.max_bytes:
                newest = live[-1]
                waiting = collections.deque(f for f in waiting if f.lossless or f is newest)
                stats.note(
                    "dropped",
                    "behind",
                    f"skipped {len(live) - 1} frames: more behind real-time playback than the "
                    f"history window ({history.seconds:g} s; --fast loses none)",
                    n=len(live) - 1,
                )
                if on_skip is not None:
                    on_skip(live[:-1])
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
