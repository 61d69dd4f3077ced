"""Both ends of the delivery protocol (common/delivery.py), on their own.

The detector's frames in turn: bursts worked off in order, skipping only when far behind. A
real Zenoh session (a peer on no network) delivers to its own subscriber, so the channel is the
one the services read. The mapper's reorder buffer: each run's frames once and in order, gaps
waited for, then lost. The mapper's acknowledgements, and the player's window on them.
"""

from __future__ import annotations

import json
import logging
import threading
import time

import numpy as np
import pytest
import zenoh

from wallmap.common.delivery import (
    AckWindow,
    CatchUpInbox,
    StalledError,
    declare_history_publisher,
    frames_in_turn,
)
from wallmap.common.link_settings import HistorySettings
from wallmap.common.messages import Frame, Progress, pack
from wallmap.common.runtime import Stats

WINDOW = HistorySettings(seconds=0.5)  # 30 frames at the highest rate

KEY = "test/frames"


@pytest.fixture
def local():
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps([]))
    with zenoh.open(conf) as session:
        subscriber = session.declare_subscriber(KEY, zenoh.handlers.FifoChannel(256))
        publisher = session.declare_publisher(KEY)
        yield publisher, subscriber
        subscriber.undeclare()


def _put(publisher, n: int, *, lossless: bool, run: str = "r") -> None:
    points = np.zeros((1, 3, 3), np.float32)
    for seq in range(n):
        publisher.put(pack(Frame(run, seq, 1.0 + seq, "cam", points, np.eye(4), "depth", lossless)))
    time.sleep(0.2)  # delivered to the channel


def _take(subscriber, stats: Stats, n: int) -> list[int]:
    turns = frames_in_turn(subscriber.handler, stats, WINDOW)
    return [next(turns).seq for _ in range(n)]


def test_a_short_burst_is_worked_off_in_order(local) -> None:
    publisher, subscriber = local
    stats = Stats(logging.getLogger("test"))
    burst = 2 * WINDOW.samples()  # a catch-up on the window, and as much again live
    _put(publisher, burst, lossless=False)
    assert _take(subscriber, stats, burst) == list(range(burst))
    assert "dropped" not in stats.snapshot()


def test_far_behind_in_real_time_it_skips_to_the_newest_and_counts_the_rest(local) -> None:
    publisher, subscriber = local
    stats = Stats(logging.getLogger("test"))
    _put(publisher, 80, lossless=False)
    assert _take(subscriber, stats, 1) == [79]
    assert stats.snapshot()["dropped"] == 79


def test_frames_of_a_player_that_sends_again_are_never_skipped(local) -> None:
    publisher, subscriber = local
    stats = Stats(logging.getLogger("test"))
    _put(publisher, 40, lossless=True)
    assert _take(subscriber, stats, 40) == list(range(40))
    assert "dropped" not in stats.snapshot()


def test_a_service_catching_up_takes_the_window_before_the_live_stream() -> None:
    """A live frame already waiting when the service asks the caches for the window comes
    after the window's frames: a restarted detector takes them in the order they were sent,
    its drainer receiving from the moment the inbox exists, before any answer is in."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps([]))
    with zenoh.open(conf) as session:
        publisher = declare_history_publisher(session, KEY, WINDOW.samples())
        _put(publisher, 20, lossless=False)  # sent before the service (re)started
        subscriber = session.declare_subscriber(KEY, zenoh.handlers.FifoChannel(256))
        points = np.zeros((1, 3, 3), np.float32)
        publisher.put(pack(Frame("r", 20, 21.0, "cam", points, np.eye(4), "depth", False)))
        time.sleep(0.2)  # the live frame waits in the channel
        inbox = CatchUpInbox(subscriber.handler, session, KEY, WINDOW)
        taken: list[int] = []
        turns = frames_in_turn(inbox, Stats(logging.getLogger("test")), WINDOW)
        drainer = threading.Thread(target=lambda: taken.extend(next(turns).seq for _ in range(21)))
        drainer.start()
        drainer.join(5.0)
        assert taken == list(range(21))
        subscriber.undeclare()
        publisher.undeclare()


# --- the mapper takes each run's frames once and in order -------------------------------------


def _ack(run: str, processed: int, epoch: str = "e") -> zenoh.Sample:
    """An acknowledgement as the player's subscriber gets it, through a real session."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as session:
        channel = session.declare_subscriber("test/ack", zenoh.handlers.FifoChannel(4))
        session.put("test/ack", pack(Progress(run, processed, processed, 0, epoch)))
        return channel.handler.recv()


def test_the_players_window_follows_its_own_run_and_a_restarted_mapper() -> None:
    window = AckWindow("mine")
    window.on_sample(_ack("theirs", 50))
    assert window.processed == 0, "another player's run"
    window.on_sample(_ack("mine", 10))
    window.on_sample(_ack("mine", 8))
    assert window.processed == 10, "an old acknowledgement that comes late counts for nothing"
    window.on_sample(_ack("mine", 7, epoch="restarted"))
    assert (window.processed, window.epoch) == (7, "restarted"), "a new mapper's word counts"
    window.wait_until(7, stall_timeout=1.0, stop=threading.Event())  # already there: no wait
    with pytest.raises(StalledError, match="no frame for 0 s"):
        window.wait_until(20, stall_timeout=0.2, stop=threading.Event())
    stopped = threading.Event()
    stopped.set()
    window.wait_until(20, stall_timeout=0.2, stop=stopped)  # a stopped player does not wait
