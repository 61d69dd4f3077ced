"""Delivery: how frames, poses and observations reach the map once each, in order, all of them.

Both ends of the protocol, in the order a frame travels:

1. **Publishing with a window.** Every live stream (the player's frames and poses, the
   detector's observations) is published with a cache of its last ``HistorySettings.seconds``
   (Zenoh's advanced publishers, with heartbeats, so even the last samples before a quiet spell are
   recovered). A live sensor does not replay: the window is what a service that restarts, or a
   link that comes back, can still get.
2. **Subscribing with history.** Each service's subscriber asks for the window when it starts
   and recovers samples it missed (``subscribe_with_history``), and asks the caches itself as
   well (``CatchUpInbox``: Zenoh's own start-up query can lose a race with the first live
   sample). What is older than the window is lost for good: Zenoh says how many, and the
   service counts them (``missed``).
3. **The detector takes frames in turn** (``frames_in_turn``): each once (history can bring one
   twice), bursts worked off in order, and in real-time playback, when more frames wait than
   twice the window holds, it skips to the newest and tells the mapper which frames it skipped.
4. **The mapper takes each run's frames once and in order** (``InOrder``), so a run interrupted
   and caught up maps exactly as an uninterrupted one: the same walls, the same ids. A gap waits
   ``gap_wait`` seconds for history to fill it, then is given up and counted as lost.
5. **Acknowledgements and back-pressure.** The mapper says how far each run has come on
   ``{prefix}/mapper/progress`` (``RunProgress``, kept in its state file across restarts);
   under ``--fast`` the player keeps at most ``window`` frames beyond that in flight
   (``AckWindow``), so a slow pipeline slows the player and nothing is dropped. In real time
   nothing waits for acknowledgements.

docs/deployment.md says what survives what, and for how long.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import zenoh
from zenoh import ext

from wallmap.common.codec import MessageError
from wallmap.common.link_settings import HistorySettings
from wallmap.common.messages import (
    Frame,
    unpack_frame,
    unpack_progress,
)
from wallmap.common.runtime import Stats, drain

# --- 1, 2: publishing with a window, subscribing with history -----------------------------

HEARTBEAT = 0.5  # s between a publisher's heartbeats: how soon a lost last sample is noticed
CHANNEL_SLACK = 64  # samples a subscriber's channel holds beyond twice the window
ASK_TIMEOUT = 10.0  # s the caches have to answer a service's own history query


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

    Live samples wait in the channel until the answer is in: a restarted service works off the
    window first, in the order it was published, then the live stream. A detector restarted
    mid-run so takes the frames as the first one did, and its noise learning (``NoiseLevel``)
    comes to the frames the mapper still needs as it was: a live frame taken first, with the
    learning not yet warm, gave the map a wall more (seen: one restart under load in ten).
    The inbox asks as it is made: a receive begun before the question (the service's drainer,
    waiting on the channel) would take the next live sample ahead of the whole window.
    """

    def __init__(
        self,
        channel: zenoh.handlers.Handler[zenoh.Sample],
        session: zenoh.Session,
        key: str,
        history: HistorySettings,
    ) -> None:
        """Ask every cache of ``key`` for its window; the answer comes in the background."""
        self._channel = channel
        self._fetched: collections.deque[zenoh.Sample] = collections.deque()
        self._asking = threading.Event()
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
        """The next sample, or None when none waits (live ones wait while the caches answer)."""
        if self._fetched:
            return self._fetched.popleft()
        if self._asking.is_set():
            return None
        return self._channel.try_recv()

    def recv(self) -> zenoh.Sample:
        """The next sample, waiting for one. Raises zenoh.ZError once the channel is closed."""
        while self._asking.is_set() and not self._fetched:
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
    history: HistorySettings,
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
    inbox = CatchUpInbox(subscriber.handler, session, key, history)
    drainer = threading.Thread(target=drain, args=(inbox,), daemon=True)
    drainer.start()
    misses = subscriber.sample_miss_listener(lambda miss: on_miss(miss.nb))
    return HistorySubscription(subscriber, misses, drainer)


# --- 3: the detector takes frames in turn ----------------------------------------------------


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
    history: HistorySettings,
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


# --- 5: back-pressure (the mapper's side, 4 and 5, is ``common.frame_order``) ------------------

STALL_POLL = 0.05  # s between looks at the stop event while a player waits for acknowledgements


class StalledError(RuntimeError):
    """The mapper acknowledged nothing for too long; the message says how far it had come."""


class AckWindow:
    """A player's view of the mapper's acknowledgements of its run: the ``--fast`` window.

    The progress subscriber hands each sample to ``on_sample`` (a few microseconds under a
    lock), so acknowledgements never pile up in a channel nobody reads: in real-time playback
    nothing waits for them, and a full channel would block the session's receiving thread,
    which then could neither reconnect to a restarted router nor close.
    """

    def __init__(self, run: str) -> None:
        self.run = run
        self.processed = 0
        self.integrated = 0
        self.epoch: str | None = None  # the mapper process acknowledging
        self._changed = threading.Condition()
        self.last_change = time.monotonic()

    def on_sample(self, sample: zenoh.Sample) -> None:
        """Zenoh's callback: take one acknowledgement (others' runs and malformed ones ignored)."""
        try:
            progress = unpack_progress(sample.payload.to_bytes())
        except MessageError:
            return
        if progress.run != self.run:
            return
        with self._changed:
            # A new mapper process (restarted on its state file) may stand behind the old one:
            # its word counts, and what it lacks comes to it from the history.
            if progress.epoch != self.epoch or progress.processed > self.processed:
                self.epoch = progress.epoch
                self.processed, self.integrated = progress.processed, progress.integrated
                self.last_change = time.monotonic()
                self._changed.notify_all()

    def wait_until(self, processed: int, stall_timeout: float, stop: threading.Event) -> None:
        """Wait for ``processed`` frames to be acknowledged (or ``stop``).

        Frames lost on the way (a detector or the router restarting) come back from the
        history: the player only waits.

        Raises:
            StalledError: no acknowledgement for ``stall_timeout`` s.
        """
        with self._changed:
            while self.processed < processed and not stop.is_set():
                if time.monotonic() - self.last_change > stall_timeout:
                    msg = (
                        f"the mapper acknowledged no frame for {stall_timeout:.0f} s "
                        f"({self.processed} of {processed} done); is it running?"
                    )
                    raise StalledError(msg)
                self._changed.wait(STALL_POLL)
