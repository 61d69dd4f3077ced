"""The median of the last few hundred values, kept as they come. Pure.

The pose judge reads a robust scale every frame from a window of recent values (the jump
detector's deviations, the noise scale's ratios). Sorting the window anew each frame, as
``np.median`` does after copying it into an array, cost more than the rest of those learners
together; a window kept sorted costs one insertion and one deletion per value.
"""

from __future__ import annotations

import bisect
import collections
from collections.abc import Iterable, Iterator


class RollingMedian:
    """The last ``window`` values, in the order they came and sorted.

    Values must be finite (a NaN has no place in a sorted list); the callers' are.
    """

    def __init__(self, window: int) -> None:
        self._order: collections.deque[float] = collections.deque(maxlen=window)
        self._sorted: list[float] = []

    def add(self, value: float) -> None:
        """One value; the oldest leaves once the window is full."""
        if len(self._order) == self._order.maxlen:
            del self._sorted[bisect.bisect_left(self._sorted, self._order[0])]
        self._order.append(value)
        bisect.insort(self._sorted, value)

    def extend(self, values: Iterable[float]) -> None:
        """Several values, oldest first."""
        for value in values:
            self.add(value)

    def clear(self) -> None:
        """Forget every value."""
        self._order.clear()
        self._sorted.clear()

    def median(self) -> float:
        """The window's median, as ``np.median`` gives it (the mean of the middle two)."""
        n = len(self._sorted)
        if not n:
            raise ValueError("the median of no values")
        mid = n // 2
        return self._sorted[mid] if n % 2 else 0.5 * (self._sorted[mid - 1] + self._sorted[mid])

    def __len__(self) -> int:
        return len(self._order)

    def __iter__(self) -> Iterator[float]:
        """The values in the order they came (what a state file keeps)."""
        return iter(self._order)
