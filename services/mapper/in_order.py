"""Each player run's frames once and in order, whatever order the network brings them in.

Observations come from live publishing and from history (a detector or mapper that restarted,
a router that came back, catches up on what it missed; ``common.history``), so a frame may come
twice, or after later ones. The map is taken in frame order so that a run interrupted and
caught up maps exactly as an uninterrupted one: the same walls, the same ids. A gap waits for
its frames for ``gap_wait`` seconds (history recovers them meanwhile); then it is given up,
and its frames are counted as lost. A run first seen mid-way waits ``start_wait`` for its
history before starting at the earliest frame that came.
"""

from __future__ import annotations

import collections
from collections.abc import Iterable
from dataclasses import dataclass, field

from wallmap.common.messages import Observations, Progress

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
            if not run.held or now - run.since < self.start_wait:
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
