"""The mapper's reorder buffer: each run's frames once and in order, gaps waited for, then lost."""

from __future__ import annotations

from wallmap.common.delivery import MAX_HELD, InOrder
from wallmap.common.messages import Observations, Progress


def _obs(seq: int, run: str = "r") -> Observations:
    return Observations(run, seq, 100.0 + seq, "base_link")


def _seqs(items: list[Observations]) -> list[int]:
    return [o.seq for o in items]


def test_frames_in_order_pass_at_once_after_the_start_wait() -> None:
    order = InOrder(gap_wait=5.0, start_wait=1.0)
    assert order.take(_obs(0), now=0.0).ready == []  # a new run waits for its history
    assert order.take(_obs(1), now=0.5).ready == []
    assert _seqs(order.take(None, now=1.0).ready) == [0, 1]
    assert _seqs(order.take(_obs(2), now=1.1).ready) == [2]


def test_a_run_first_seen_mid_way_starts_at_the_earliest_frame_that_came() -> None:
    order = InOrder(start_wait=1.0)
    order.take(_obs(40), now=0.0)
    order.take(_obs(12), now=0.2)  # history arriving after the live frames
    taken = order.take(None, now=1.0)
    assert _seqs(taken.ready) == [12]
    assert taken.lost == 0


def test_a_gap_is_filled_from_history_and_taken_in_order() -> None:
    order = InOrder([Progress("r", 5, 5, 0)], gap_wait=5.0)
    assert order.take(_obs(7), now=0.0).ready == []
    assert order.take(_obs(6), now=1.0).ready == []
    taken = order.take(_obs(5), now=2.0)
    assert _seqs(taken.ready) == [5, 6, 7]
    assert taken.lost == 0
    assert not order.waiting()


def test_frames_already_taken_come_back_as_repeated() -> None:
    order = InOrder([Progress("r", 5, 5, 0)])
    taken = order.take(_obs(3), now=0.0)
    assert taken.ready == []
    assert _seqs(taken.repeated) == [3]
    assert _seqs(order.take(_obs(5), now=0.1).ready) == [5]
    assert _seqs(order.take(_obs(5), now=0.2).repeated) == [5], "twice is once"


def test_a_gap_that_does_not_fill_in_time_is_given_up_and_counted() -> None:
    order = InOrder([Progress("r", 5, 5, 0)], gap_wait=5.0)
    order.take(_obs(9), now=0.0)
    order.take(_obs(10), now=1.0)
    assert order.take(None, now=4.9).ready == []
    assert order.waiting()
    taken = order.take(None, now=5.0)
    assert _seqs(taken.ready) == [9, 10]
    assert taken.lost == 4, "frames 5 to 8"
    late = order.take(_obs(7), now=6.0)  # too late: already given up
    assert (late.ready, _seqs(late.repeated)) == ([], [7])


def test_runs_are_independent() -> None:
    order = InOrder([Progress("a", 0, 0, 0), Progress("b", 0, 0, 0)], gap_wait=5.0)
    assert order.take(_obs(1, "a"), now=0.0).ready == []  # a waits for its frame 0
    assert _seqs(order.take(_obs(0, "b"), now=0.1).ready) == [0]


def test_what_is_held_is_bounded_the_oldest_gap_gives_way() -> None:
    order = InOrder([Progress("r", 0, 0, 0)], gap_wait=1e9)
    for seq in range(1, MAX_HELD + 1):
        taken = order.take(_obs(seq), now=seq * 1e-3)
    assert taken.lost == 0
    taken = order.take(_obs(MAX_HELD + 1), now=10.0)
    assert taken.lost == 1, "frame 0 given up"
    assert _seqs(taken.ready) == list(range(1, MAX_HELD + 2))
