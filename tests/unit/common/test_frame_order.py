"""Each run's frames taken once and in order, and acknowledged: the mapper's side of delivery."""

from __future__ import annotations

from wallmap.common.frame_order import MAX_HELD, MAX_RUNS, InOrder, RunProgress
from wallmap.common.messages import Observations, Progress, unpack_progress


def _obs(seq: int, run: str = "r") -> Observations:
    return Observations(run, seq, 100.0 + seq, "base_link")


def _seqs(items: list[Observations]) -> list[int]:
    return [o.seq for o in items]


def test_a_runs_first_frame_passes_at_once_and_the_rest_in_order() -> None:
    order = InOrder(gap_wait=5.0, start_wait=1.0)
    assert _seqs(order.take(_obs(0), now=0.0).ready) == [0], "nothing comes before frame 0"
    assert _seqs(order.take(_obs(1), now=0.1).ready) == [1]
    assert order.take(_obs(3), now=0.2).ready == []  # 2 first
    assert _seqs(order.take(_obs(2), now=0.3).ready) == [2, 3]


def test_a_run_first_seen_mid_way_waits_for_its_history() -> None:
    order = InOrder(gap_wait=5.0, start_wait=1.0)
    assert order.take(_obs(7), now=0.0).ready == []  # a live frame: 0 to 6 may be on their way
    assert order.take(_obs(8), now=0.5).ready == []
    assert _seqs(order.take(None, now=1.0).ready) == [7, 8]


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


# --- acknowledgements and the --fast window ------------------------------------------------------


def test_the_mapper_acknowledges_each_run_once_per_flush_with_its_epoch() -> None:
    progress = RunProgress([Progress("old", 5, 4, 1, "before")], epoch="now")
    sent: list[bytes] = []
    progress.flush(sent.append)
    assert [unpack_progress(b) for b in sent] == [Progress("old", 5, 4, 1, "now")], (
        "a run restored from the state file is said first thing, by this process"
    )
    for seq in range(3):
        progress.count("a", seq, integrated=seq != 1)
    progress.count("b", 0, integrated=True)
    sent.clear()
    progress.flush(sent.append)
    acks = {p.run: p for p in map(unpack_progress, sent)}
    assert acks == {"a": Progress("a", 3, 2, 1, "now"), "b": Progress("b", 1, 1, 0, "now")}
    sent.clear()
    progress.flush(sent.append)
    assert sent == [], "nothing new, nothing sent"
    progress.again("a")  # its frame came again: the acknowledgement was lost on the way
    progress.flush(sent.append)
    assert [unpack_progress(b).run for b in sent] == ["a"]


def test_the_mapper_remembers_the_latest_runs_only() -> None:
    progress = RunProgress(epoch="e")
    for i in range(MAX_RUNS + 3):
        progress.count(f"run{i}", 0, integrated=True)
    assert list(progress.runs) == [f"run{i}" for i in range(3, MAX_RUNS + 3)]
