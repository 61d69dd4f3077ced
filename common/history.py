"""Bounded history on the live streams, so a restarted service or a link back catches up.

A live sensor does not replay. So every stream a service reads (sensor frames, poses, wall
observations) is published with a cache of its recent samples, and read by subscribers that ask
for that history when they start (a service restarted mid-run gets what it missed) and that
detect and recover missed samples (a link or a router back after an outage): Zenoh's advanced
publishers and subscribers (``zenoh.ext``), with a heartbeat so that even the last samples
before a quiet spell are recovered. What is older than the window is lost; the subscriber is
told (``on_miss``), and the service counts and reports it.

The window is in seconds (``--history``, default 30 s: 900 frames of a 30 Hz camera) and in
bytes: a cache never holds more than ``max_bytes`` (default 512 MB), whatever the frames weigh.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh
from zenoh import ext

HEARTBEAT = 0.5  # s between a publisher's heartbeats: how soon a lost last sample is noticed
CHANNEL_SLACK = 64  # samples a subscriber's channel holds beyond twice the window
ASK_TIMEOUT = 10.0  # s the caches have to answer a service's own history query
MAX_RATE = 60.0  # samples/s a publisher that does not know its rate sizes its cache for


@dataclass(frozen=True)
class History:
    """How much of a stream is kept for subscribers that missed it.

    Attributes:
        seconds: The window: samples are kept this long (at the rate they are published).
        max_bytes: The most a publisher's cache may hold.
    """

    seconds: float = 30.0
    max_bytes: int = 512 * 1024 * 1024

    def samples(self, rate_hz: float = MAX_RATE, sample_bytes: int = 1) -> int:
        """Samples a cache keeps: the window at ``rate_hz``, within ``max_bytes``."""
        by_time = math.ceil(self.seconds * rate_hz)
        by_size = self.max_bytes // max(sample_bytes, 1)
        return max(1, min(by_time, by_size))


def declare_history_publisher(
    session: zenoh.Session, key: str, samples: int, *, block: bool = True
) -> ext.AdvancedPublisher:
    """A publisher that keeps its last ``samples`` samples for subscribers that missed them.

    ``block``: congestion control BLOCK (the stream must not lose samples on a slow link),
    else DROP (progress and the like).
    """
    congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
    return ext.declare_advanced_publisher(
        session,
        key,
        congestion_control=congestion,
        cache=ext.CacheConfig(max_samples=samples),
        sample_miss_detection=ext.MissDetectionConfig(heartbeat=HEARTBEAT, sporadic_heartbeat=None),
        publisher_detection=True,
    )


CATCH_UP_POLL = 0.01  # s between looks at the channel while the caches' answer comes in


class CatchUpInbox:
    """A subscriber's channel, and what the caches answered to the service's own history query.

    Zenoh's history query at subscription can lose a race: a live sample that comes before the
    query is registered makes the older history look delivered, and it is dropped (seen here in
    about one restart in ten). So each service also asks the caches itself, once, at start;
    their answer arrives in this inbox beside the live samples. A sample may then come twice;
    the consumers take each frame once (the mapper by frame number, ``InOrder``).
    """

    def __init__(self, channel: zenoh.handlers.Handler[zenoh.Sample]) -> None:
        self._channel = channel
        self._fetched: collections.deque[zenoh.Sample] = collections.deque()
        self._asking = threading.Event()

    def ask(self, session: zenoh.Session, key: str, history: History) -> None:
        """Query every cache of ``key`` for its window; the answer comes in the background."""
        self._asking.set()
        selector = f"{key}/@adv/**?_max={history.samples()};_time=[now(-{history.seconds:g}s)..]"
        session.get(
            selector,
            zenoh.handlers.Callback(self._on_reply, self._asking.clear),
            consolidation=zenoh.ConsolidationMode.NONE,
            accept_replies=zenoh.ReplyKeyExpr.ANY,
            timeout=ASK_TIMEOUT,
        )

    def _on_reply(self, reply: zenoh.Reply) -> None:  # Zenoh's thread: keep it short
        if reply.ok is not None:
            self._fetched.append(reply.ok)

    def try_recv(self) -> zenoh.Sample | None:
        """The next sample, or None when none waits."""
        if self._fetched:
            return self._fetched.popleft()
        return self._channel.try_recv()

    def recv(self) -> zenoh.Sample:
        """The next sample, waiting for one. Raises zenoh.ZError once the channel is closed."""
        while self._asking.is_set():
            if (sample := self.try_recv()) is not None:
                return sample
            time.sleep(CATCH_UP_POLL)
        if self._fetched:
            return self._fetched.popleft()
        return self._channel.recv()


@dataclass
class HistorySubscription:
    """A history subscriber, its miss listener and the thread that drains it.

    Kept together, because dropping the subscriber or the listener ends the subscription.
    """

    subscriber: ext.AdvancedSubscriber[Any]
    misses: ext.SampleMissListener[None]
    drainer: threading.Thread

    def undeclare(self) -> None:
        """End the subscription; the drainer sees its channel close and returns."""
        self.misses.undeclare()
        self.subscriber.undeclare()

    def join(self, timeout: float) -> None:
        """Wait for the drainer to finish what it holds."""
        self.drainer.join(timeout)


def subscribe_with_history(
    session: zenoh.Session,
    key: str,
    history: History,
    drain: Callable[[Any], None],
    on_miss: Callable[[int], None],
) -> HistorySubscription:
    """A subscriber that gets the window's history at start and recovers what it misses.

    ``drain(inbox)`` runs on its own thread and reads the ``CatchUpInbox`` (the subscriber's
    channel and the answer to the service's own history query) until the channel closes.

    The channel holds twice the window: the history arrives at once, and while a channel is
    full Zenoh's receiving thread waits inside the subscriber's state lock. Declaring the miss
    listener then waits for that lock while holding Python's GIL, so the drainer cannot empty
    the channel: a deadlock (seen: a restarted detector or mapper hung at "connecting"). A
    channel that holds the whole window never fills at start; its memory is bounded by the
    publishers' caches it copies. ``on_miss`` runs on Zenoh's thread with the number of samples
    lost for good.
    """
    channel = zenoh.handlers.FifoChannel(2 * history.samples() + CHANNEL_SLACK)
    subscriber = ext.declare_advanced_subscriber(
        session,
        key,
        channel,
        history=ext.HistoryConfig(
            detect_late_publishers=True,
            max_samples=history.samples(),
            max_age=history.seconds,
        ),
        recovery=ext.RecoveryConfig(heartbeat=True, periodic_queries=None),
        subscriber_detection=True,
    )
    inbox = CatchUpInbox(subscriber.handler)
    drainer = threading.Thread(target=drain, args=(inbox,), daemon=True)
    drainer.start()
    misses = subscriber.sample_miss_listener(lambda miss: on_miss(miss.nb))
    inbox.ask(session, key, history)
    return HistorySubscription(subscriber, misses, drainer)
