"""What every long-running service needs: logging, counters of refused input, clean shutdown."""

from __future__ import annotations

import gc
import logging
import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any, TypeVar

import zenoh

from wallmap.common.codec import encode
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


MAX_KINDS = 1024  # log kinds remembered for the once-a-second limit, beyond the last second


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
                if len(self._last_logged) > MAX_KINDS:  # reasons quote what came: keep it bounded
                    self._last_logged = {
                        k: t for k, t in self._last_logged.items() if now - t < 1.0
                    }
        if not quiet:
            self._log.warning("%s", message)

    def snapshot(self) -> dict[str, int]:
        """A copy of all counters."""
        with self._lock:
            return dict(self._counts)


class Presence:
    """A service's liveliness token and its counters' queryable: what ``wallmap status`` reads.

    Both stay declared while this object lives; ``undeclare`` ends them at shutdown.
    """

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        service: str,
        stats: Stats,
        details: Callable[[], dict[str, Any]] | None = None,
    ) -> None:
        """``details``: more of the service's state for its reply (quick: no lock, no wait)."""
        self._service, self._stats, self._started = service, stats, time.time()
        self._details = details
        self.token = session.liveliness().declare_token(keys.health(service))
        # Replying to the query at hand from its callback is quick: one locked copy.
        self.queryable = session.declare_queryable(keys.stats(service), self._reply)

    def _reply(self, query: zenoh.Query) -> None:
        body = {
            "service": self._service,
            "uptime": time.time() - self._started,
            "counters": self._stats.snapshot(),
            **(self._details() if self._details is not None else {}),
        }
        query.reply(query.key_expr, encode(body))

    def undeclare(self) -> None:
        """Leave: the service no longer shows as live."""
        self.token.undeclare()
        self.queryable.undeclare()


_STOPS: list[threading.Event] = []  # each stop_on_signals() event, set when a thread dies
_FAILURES: list[BaseException] = []  # what killed a thread, for the command's exit status


def exempt_startup_objects() -> None:
    """Leave what start-up made out of the cycle collector's full collections.

    A service that has loaded numpy, numba's compiled loops and zenoh tracks some 100,000
    objects that live as long as it does, and a full collection walks them all: measured here,
    the detector ran one of 45 ms in the middle of a frame, once in 784 depth frames (a frame
    and a half late at 30 Hz). Frozen, they are skipped (the longest collection in the same run:
    0.4 ms). What is garbage by then is collected first.
    """
    gc.collect()
    gc.freeze()


def stop_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM, so services shut down and save their state.

    Set too when a thread dies of an exception (``thread_failures``): a service whose worker
    died would otherwise look alive, answer its status, and do nothing.
    """
    stop = threading.Event()

    def handler(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    _STOPS.append(stop)
    threading.excepthook = _on_thread_failure
    return stop


def _on_thread_failure(args: threading.ExceptHookArgs) -> None:
    """Log the dead thread's traceback, remember why, and stop the service."""
    if args.exc_type is SystemExit:
        return
    name = args.thread.name if args.thread is not None else "a thread"
    exc_info = (args.exc_type, args.exc_value, args.exc_traceback)
    log.error("%s died; the service stops", name, exc_info=exc_info)
    _FAILURES.append(args.exc_value or args.exc_type())
    for stop in _STOPS:
        stop.set()


def thread_failures() -> list[BaseException]:
    """The exceptions threads died of in this process (``stop_on_signals``), oldest first."""
    return list(_FAILURES)


def drain(channel: zenoh.handlers.Handler[T]) -> Iterator[T]:
    """Everything a Zenoh channel receives, until its subscriber or queryable is undeclared."""
    while True:
        try:
            yield channel.recv()
        except zenoh.ZError:
            return
