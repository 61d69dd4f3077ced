"""Facts about time for ``wallmap doctor``: gaps between samples, and each topic's clock.

Pose sources, tf links and clocks are all judged by the stretches between consecutive stamps, so
finding those stretches and summarising them as the report's `Intervals` (relative to the
report's t0, rounded to the millisecond) is done once, here.
"""

from collections.abc import Sequence

import numpy as np

from wallmap.doctor_facts import GAP_LIMIT, JUMP_LIMIT, LISTED, ClockFacts, Gap, Intervals
from wallmap.services.player.bag_contents import Stamps

Spans = list[tuple[float, float]]  # (start, end) in absolute seconds, sorted


def gap_spans(stamps: np.ndarray) -> Spans:
    """Stretches longer than GAP_LIMIT between consecutive sample times."""
    stamps = np.unique(stamps)
    steps = np.diff(stamps)
    return [(float(stamps[i]), float(stamps[i + 1])) for i in np.nonzero(steps > GAP_LIMIT)[0]]


def union(spans: Spans) -> Spans:
    """Merge overlapping spans: a tf chain has no fresh sample where any of its links has none."""
    merged: Spans = []
    for start, end in sorted(spans):
        if merged and start <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], end))
        else:
            merged.append((start, end))
    return merged


def _summary(starts: Sequence[float], lengths: Sequence[float], t0: float) -> Intervals:
    """Intervals relative to t0, rounded to the millisecond for people and scripts alike."""
    gaps = [Gap(round(s - t0, 3), round(n, 3)) for s, n in zip(starts, lengths, strict=True)]
    if not gaps:
        return Intervals()
    return Intervals(len(gaps), max(gaps, key=lambda g: abs(g.length)), gaps[:LISTED])


def span_summary(spans: Spans, t0: float) -> Intervals:
    """Spans as the report's intervals: each one's start and length."""
    return _summary([s for s, _ in spans], [e - s for s, e in spans], t0)


def inside(stamps: np.ndarray, spans: Spans) -> int:
    """How many stamps fall strictly inside one of the spans."""
    return sum(int(np.count_nonzero((stamps > s) & (stamps < e))) for s, e in spans)


def clock_facts(topic: str, stream: Stamps, t0: float, bag_start: float) -> ClockFacts:
    """Steps back and jumps between consecutive messages, and header stamps vs receive times."""
    stamps, receive = np.asarray(stream.stamps), np.asarray(stream.receive)
    facts = ClockFacts(topic, int(stamps.size), zero_stamps=stream.zero)
    if stamps.size == 0:
        return facts
    steps, receive_steps = np.diff(stamps), np.diff(receive)
    back = np.nonzero(steps < 0)[0]
    jump = np.nonzero(steps > JUMP_LIMIT)[0]
    late = np.nonzero(receive_steps > JUMP_LIMIT)[0]
    facts.backward = _summary(stamps[back], steps[back], t0)
    facts.jumps = _summary(stamps[jump], steps[jump], t0)
    facts.receive_jumps = _summary(receive[late], receive_steps[late], bag_start)
    offsets = stamps - receive
    median = float(np.median(offsets))
    facts.offset = round(median, 6)
    facts.offset_spread = round(float(np.max(np.abs(offsets - median))), 6)
    return facts
