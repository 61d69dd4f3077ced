"""The mapper's side of delivery: each run's frames taken once and in order, and acknowledged.

Steps 4 and 5 of ``common.delivery``'s protocol, apart from Zenoh: ``InOrder`` puts a run's
frames back in order (history can bring one twice, or late) and ``RunProgress`` says how far
each run has come, the acknowledgement a ``--fast`` player paces itself by. Pure, so the mapper's
intake that uses them is tested without a network.
"""

from __future__ import annotations

import collections
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from wallmap.common.messages import Observations, Progress, pack

# --- 4: the mapper takes each run's frames once and in order -------------------------------

MAX_RUNS = 16  # runs remembered
MAX_HELD = 4096  # observations held for a gap, over all runs: then the oldest gap gives way


@dataclass
class _Run:
    next: int | None  # the next frame to take; None until the run's start is decided
    held: dict[int, Observations] = field(default_factory=dict)
    since: float = 0.0  # when the head of the line started waiting


@dataclass(frozen=True)
class Taken:
    """What a call to :meth:`InOrder.take` produced."""

    ready: list[Observations]  # in frame order, to process now
    lost: int  # frames given up on (gaps that did not fill in time)
    repeated: list[Observations]  # frames already taken, come again (their ack was lost)


class InOrder:
    """Hold observations until their turn comes; give up gaps after ``gap_wait`` seconds."""

    def __init__(
        self, runs: Iterable[Progress] = (), *, gap_wait: float = 10.0, start_wait: float = 1.0
    ) -> None:
        self.gap_wait, self.start_wait = gap_wait, start_wait
        self._runs: collections.OrderedDict[str, _Run] = collections.OrderedDict(
            (r.run, _Run(r.processed)) for r in runs
        )

    def take(self, observations: Observations | None, now: float) -> Taken:
        """Add an observation (or None, to let time pass); what is ready, lost or repeated."""
        repeated = []
        if observations is not None:
            run = self._runs.get(observations.run)
            if run is None:
                run = self._runs[observations.run] = _Run(None, since=now)
                while len(self._runs) > MAX_RUNS:
                    self._runs.popitem(last=False)
            self._runs.move_to_end(observations.run)
            if run.next is not None and observations.seq < run.next:
                repeated.append(observations)
            else:
                if not run.held:
                    run.since = now
                run.held.setdefault(observations.seq, observations)
        ready, lost = [], 0
        for run in self._runs.values():
            lost += self._release(run, now, ready)
        while sum(len(r.held) for r in self._runs.values()) > MAX_HELD:
            oldest = min((r for r in self._runs.values() if r.held), key=lambda r: r.since)
            lost += self._skip(oldest, now, ready)
        return Taken(ready, lost, repeated)

    def _release(self, run: _Run, now: float, ready: list[Observations]) -> int:
        """Move the run's frames that are next into ``ready``; give up a gap held too long."""
        if run.next is None:
            # A run's first frame is number 0: with it there is nothing earlier to wait for.
            # A run first seen mid-way waits ``start_wait`` for its history to come.
            if 0 not in run.held and (not run.held or now - run.since < self.start_wait):
                return 0
            run.next = min(run.held)
        lost = 0
        while run.held:
            if run.next in run.held:
                ready.append(run.held.pop(run.next))
                run.next += 1
                run.since = now
            elif now - run.since >= self.gap_wait:
                lost += self._skip(run, now, ready)
            else:
                break
        return lost

    def _skip(self, run: _Run, now: float, ready: list[Observations]) -> int:
        """Give up the run's current gap: jump to its earliest held frame."""
        start = min(run.held)
        lost = start - (run.next if run.next is not None else start)
        run.next = start
        run.since = now
        while run.next in run.held:
            ready.append(run.held.pop(run.next))
            run.next += 1
        return lost

    def waiting(self) -> bool:
        """Whether anything is held (the caller should come back soon, even if nothing comes)."""
        return any(run.held for run in self._runs.values())


ACK_EVERY = 8  # frames between acknowledgements while the mapper is busy


class RunProgress:
    """How far the mapper has taken each player run: what it acknowledges, and keeps.

    ``processed`` is the next frame number a run may send (frames are taken in order, so every
    frame before it is done), with how many were integrated and dropped; the latest ``MAX_RUNS``
    runs are kept, and saved with the map. The mapper's ``epoch`` (one per process) goes with
    every acknowledgement, so a player sees a restarted mapper as such. ``count``, ``again`` and
    ``flush`` run on the mapper's observation thread; ``runs`` is read under the caller's lock.
    """

    def __init__(self, runs: Iterable[Progress] = (), epoch: str = "") -> None:
        self.epoch = epoch
        self.runs: collections.OrderedDict[str, Progress] = collections.OrderedDict(
            (r.run, replace(r, epoch=epoch)) for r in runs
        )
        self._unsent: dict[str, Progress] = dict(self.runs)  # runs restored: said first thing

    def count(self, run: str, seq: int, *, integrated: bool) -> Progress:
        """Frame ``seq`` of ``run`` is done (integrated, or dropped); its acknowledgement waits."""
        old = self.runs.pop(run, Progress(run, 0, 0, 0))
        new = Progress(
            run,
            seq + 1,
            old.integrated + int(integrated),
            old.dropped + int(not integrated),
            self.epoch,
        )
        self.runs[run] = new
        while len(self.runs) > MAX_RUNS:
            self.runs.popitem(last=False)
        self._unsent[run] = new
        return new

    def again(self, run: str) -> None:
        """A frame already taken came again: its acknowledgement was lost, so say it again."""
        if (progress := self.runs.get(run)) is not None:
            self._unsent[run] = progress

    def flush(self, put: Callable[[bytes], Any]) -> None:
        """Publish the acknowledgements waiting, one per run."""
        for progress in self._unsent.values():
            put(pack(progress))
        self._unsent.clear()
