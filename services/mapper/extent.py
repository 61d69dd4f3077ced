"""Where along its line a wall has been seen: counts in 5 cm bins, split into segments.

The union of observed segments is not a wall's true extent: one stray observation stretches it,
and a door inside it disappears. Counting, per bin along the wall, how many observations covered
it keeps what was seen repeatedly, and the runs of such bins are the wall's segments, with doors
and gaps between them. Bins live on an axis fixed when the wall is born (a point and a direction),
so they stay valid while the wall's line estimate moves; points are projected onto that axis.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

BIN = 0.05  # m
MIN_HITS = 2  # observations that make a bin part of the wall (when the wall has that many)
MAX_GAP = 0.3  # m: gaps up to this inside a segment are noise, not a door


class Extent:
    """Observation counts per bin along a fixed axis ``origin + t * direction``."""

    def __init__(self, origin: Array, direction: Array) -> None:
        self.origin = np.asarray(origin, dtype=float)
        self.direction = np.asarray(direction, dtype=float)
        self.first = 0  # bin index of counts[0]
        self.counts = np.zeros(0, dtype=np.int32)

    def along(self, points: Array) -> Array:
        """Positions of map points on the axis."""
        return (np.asarray(points) - self.origin) @ self.direction

    def add(self, segment: Array) -> None:
        """Count the bins covered by an observed segment (2 x 2 map points)."""
        t = self.along(segment)
        lo, hi = (
            math.floor(t.min() / BIN),
            max(math.ceil(t.max() / BIN) - 1, math.floor(t.min() / BIN)),
        )
        self._cover(lo, hi)
        self.counts[lo - self.first : hi - self.first + 1] += 1

    def absorb(self, other: Extent) -> None:
        """Add another wall's counts (a merge), bin by bin, projected onto this axis."""
        positions = (np.arange(len(other.counts)) + other.first + 0.5) * BIN
        centres = other.origin + np.outer(positions, other.direction)
        bins = np.floor(self.along(centres) / BIN).astype(int)
        if len(bins):
            self._cover(int(bins.min()), int(bins.max()))
            np.add.at(self.counts, bins - self.first, other.counts)

    def _cover(self, lo: int, hi: int) -> None:
        if not len(self.counts):
            self.first, self.counts = lo, np.zeros(hi - lo + 1, dtype=np.int32)
            return
        last = self.first + len(self.counts) - 1
        before, after = max(0, self.first - lo), max(0, hi - last)
        if before or after:
            self.counts = np.concatenate(
                [np.zeros(before, np.int32), self.counts, np.zeros(after, np.int32)]
            )
            self.first -= before

    def intervals(self) -> list[tuple[float, float]]:
        """Segments (start, end) on the axis: runs of bins seen ``MIN_HITS`` times, gaps closed."""
        if not len(self.counts):
            return []
        threshold = min(MIN_HITS, int(self.counts.max()))
        seen = np.flatnonzero(self.counts >= threshold)
        # A new segment starts wherever the gap to the previous seen bin exceeds MAX_GAP.
        breaks = np.flatnonzero(np.diff(seen) * BIN - BIN > MAX_GAP + 1e-9) + 1
        starts = seen[np.concatenate(([0], breaks))]
        ends = seen[np.concatenate((breaks - 1, [len(seen) - 1]))] + 1
        return [
            ((self.first + a) * BIN, (self.first + b) * BIN)
            for a, b in zip(starts.tolist(), ends.tolist(), strict=True)
        ]

    def to_json(self) -> dict[str, Any]:
        """For the state file."""
        return {
            "origin": self.origin.tolist(),
            "direction": self.direction.tolist(),
            "first": self.first,
            "counts": self.counts.tolist(),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Extent:
        """From the state file."""
        extent = cls(np.array(data["origin"], float), np.array(data["direction"], float))
        extent.first = int(data["first"])
        extent.counts = np.array(data["counts"], dtype=np.int32)
        return extent
