"""Where along its line a wall has been seen: counts in 5 cm bins, split into segments.

The union of observed segments is not a wall's true extent: one stray observation stretches it,
and a door inside it disappears. Counting, per bin along the wall, how many observations covered
it keeps what was seen repeatedly, and the runs of such bins are the wall's segments, with doors
and gaps between them. Bins live on an axis fixed when the wall is born (a point and a direction),
so they stay valid while the wall's line estimate moves; points are projected onto that axis.

Bins also count the sensor's rays that crossed them on their way to something behind: where more
frames saw through a bin than saw the wall there, there is no wall (a door, the gap above an
appliance mistaken for a wall, a line the detector drew across free space), and the bin is not
part of any segment.
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
MIN_THROUGH = 2  # rays through a bin before it can be free space
THROUGH_REACH = 3.0  # m past the extent where rays are counted too: what was seen of a gap
PIECE = 4  # bins (20 cm) in which a gap's being seen through is judged


class Extent:
    """Observation counts per bin along a fixed axis ``origin + t * direction``."""

    def __init__(self, origin: Array, direction: Array) -> None:
        self.origin = np.asarray(origin, dtype=float)
        self.direction = np.asarray(direction, dtype=float)
        self.first = 0  # bin index of counts[0]
        self.counts = np.zeros(0, dtype=np.int32)
        self.through = np.zeros(0, dtype=np.int32)  # rays that crossed each bin
        self.revision = 0  # grows with every change, for caches of the segments

    def along(self, points: Array) -> Array:
        """Positions of map points on the axis."""
        return (np.asarray(points) - self.origin) @ self.direction

    def add(self, segment: Array) -> None:
        """Count the bins covered by an observed segment (2 x 2 map points)."""
        first, last = self.along(segment).tolist()  # two positions: min and max in floats
        low, high = min(first, last), max(first, last)
        lo, hi = math.floor(low / BIN), max(math.ceil(high / BIN) - 1, math.floor(low / BIN))
        self._cover(lo, hi)
        self.counts[lo - self.first : hi - self.first + 1] += 1
        self.revision += 1

    def add_through(self, points: Array) -> int:
        """Count rays that crossed the wall's line at map points; how many were counted.

        Counted on the extent and up to ``THROUGH_REACH`` past its ends: what was seen of the
        gaps around the wall.
        """
        if not len(self.counts):
            return 0
        bins = np.floor(self.along(points) / BIN).astype(int)
        reach = round(THROUGH_REACH / BIN)
        last = self.first + len(self.counts) - 1
        bins = bins[(bins >= self.first - reach) & (bins <= last + reach)]
        if len(bins):
            self._cover(int(bins.min()), int(bins.max()))
            np.add.at(self.through, bins - self.first, 1)
            self.revision += 1
        return len(bins)

    def seen_through(self, start: float, end: float) -> float:
        """Share of the stretch between two positions on the axis that rays crossed.

        Counted in 20 cm pieces (a ray in a piece counts for it): a depth camera's rays in
        the band are a few centimetres apart at a few metres, and not every bin gets one.
        """
        lo, hi = math.floor(start / BIN) - self.first, math.ceil(end / BIN) - self.first
        crossed = np.zeros(max(hi - lo, 1), dtype=bool)
        inside = slice(max(lo, 0), max(min(hi, len(self.through)), 0))
        part = self.through[inside] > 0
        crossed[inside.start - lo : inside.start - lo + len(part)] = part
        pieces = -(-len(crossed) // PIECE)
        padded = np.zeros(pieces * PIECE, dtype=bool)
        padded[: len(crossed)] = crossed
        return float(padded.reshape(pieces, PIECE).any(axis=1).mean())

    def free(self) -> NDArray[np.bool_]:
        """Bins seen through in more frames than the wall was seen there: no wall."""
        return (self.through >= MIN_THROUGH) & (self.through > self.counts)

    def free_share(self) -> float:
        """Share of the bins seen repeatedly that are free (seen through): 0 for a true wall."""
        if not len(self.counts):
            return 0.0
        seen = self.counts >= min(MIN_HITS, int(self.counts.max()))
        return float((seen & self.free()).sum() / max(int(seen.sum()), 1))

    def absorb(self, other: Extent) -> None:
        """Add another wall's counts (a merge), bin by bin, projected onto this axis."""
        positions = (np.arange(len(other.counts)) + other.first + 0.5) * BIN
        centres = other.origin + np.outer(positions, other.direction)
        bins = np.floor(self.along(centres) / BIN).astype(int)
        if len(bins):
            self._cover(int(bins.min()), int(bins.max()))
            np.add.at(self.counts, bins - self.first, other.counts)
            np.add.at(self.through, bins - self.first, other.through)
            self.revision += 1

    def _cover(self, lo: int, hi: int) -> None:
        if not len(self.counts):
            self.first, self.counts = lo, np.zeros(hi - lo + 1, dtype=np.int32)
            self.through = np.zeros(hi - lo + 1, dtype=np.int32)
            return
        last = self.first + len(self.counts) - 1
        before, after = max(0, self.first - lo), max(0, hi - last)
        if before or after:
            pad = (np.zeros(before, np.int32), np.zeros(after, np.int32))
            self.counts = np.concatenate([pad[0], self.counts, pad[1]])
            self.through = np.concatenate([pad[0], self.through, pad[1]])
            self.first -= before

    def intervals(self) -> list[tuple[float, float]]:
        """Segments (start, end) on the axis: runs of bins seen ``MIN_HITS`` times, gaps closed.

        Free bins (seen through) are left out, unless that would leave nothing: a wall seen
        through everywhere keeps its segments (and is not served, see ``free_share``).
        """
        if not len(self.counts):
            return []
        threshold = min(MIN_HITS, int(self.counts.max()))
        seen = self.counts >= threshold
        walled = seen & ~self.free()
        seen = np.flatnonzero(walled if walled.any() else seen)
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
            "through": self.through.tolist(),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Extent:
        """From the state file."""
        extent = cls(np.array(data["origin"], float), np.array(data["direction"], float))
        extent.first = int(data["first"])
        extent.counts = np.array(data["counts"], dtype=np.int32)
        through = data.get("through")  # absent from state files before rays were counted
        extent.through = (
            np.zeros_like(extent.counts) if through is None else np.array(through, dtype=np.int32)
        )
        return extent
