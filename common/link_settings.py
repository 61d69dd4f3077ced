"""The ``[zenoh]`` and ``[history]`` sections: where to connect, and how much is kept.

Plain values, apart from the Zenoh code that uses them (``common.transport``,
``common.delivery``), so the configuration loads where Zenoh is not installed or not wanted:
the offline runner, the benchmarks, a tool that only reads a state file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from wallmap.common.config_file import require

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"
DEFAULT_PREFIX = "wallmap"
MAX_RATE = 60.0  # samples/s a publisher that does not know its rate sizes its cache for


class TransportError(RuntimeError):
    """The session could not be opened; the message says why, in one line."""


def plain_prefix(value: str, what: str, where: str) -> str:
    """A key prefix without its outer slashes.

    TransportError for one that is empty or holds a wildcard: a prefix names one robot's keys,
    not a pattern.
    """
    prefix = value.strip("/")
    if not prefix or any(c in prefix for c in "*$?#"):
        msg = f"invalid {what} {value!r} ({where}): use a plain key expression such as robot1/run2"
        raise TransportError(msg)
    return prefix


@dataclass(frozen=True)
class ZenohSettings:
    """Where and how to connect: the ``zenoh`` section of the configuration.

    Attributes:
        connect: Endpoints of routers (or peers) to connect to.
        prefix: First key segment(s) of every key, so several robots can share a network.
        config_file: A Zenoh json5 config applied before these settings (TLS, access control).
        wait_for_router: Seconds to keep trying to reach the router at start: ``inf`` for
            services (they may start before their router), a few seconds for commands a person
            runs, 0 to fail at once. Each command decides it; it is not configuration.
    """

    connect: tuple[str, ...] = (DEFAULT_CONNECT,)
    prefix: str = DEFAULT_PREFIX
    config_file: Path | None = None
    wait_for_router: float = field(default=0.0, metadata={"config": False})

    def __post_init__(self) -> None:
        prefix = plain_prefix(self.prefix, "prefix", "--prefix, zenoh.prefix")
        if not self.connect:
            msg = "no endpoint to connect to"
            raise TransportError(msg)
        object.__setattr__(self, "prefix", prefix)


@dataclass(frozen=True)
class HistorySettings:
    """How much of a stream is kept for subscribers that missed it.

    Attributes:
        seconds: The window: samples are kept this long (at the rate they are published).
        max_bytes: The most a publisher's cache may hold.
    """

    seconds: float = 30.0
    max_bytes: int = 512 * 1024 * 1024

    def __post_init__(self) -> None:
        require(0 < self.seconds < math.inf, "seconds", "a positive number", self.seconds)
        require(self.max_bytes > 0, "max_bytes", "positive", self.max_bytes)

    def samples(self, rate_hz: float = MAX_RATE, sample_bytes: int = 1) -> int:
        """Samples a cache keeps: the window at ``rate_hz``, within ``max_bytes``."""
        by_time = math.ceil(self.seconds * rate_hz)
        by_size = self.max_bytes // max(sample_bytes, 1)
        return max(1, min(by_time, by_size))
