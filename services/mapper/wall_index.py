"""A grid over the map so association looks only at walls near an observation.

Scanning every wall for every observation costs time in proportion to the map's size; a city
block of floors holds thousands of walls. Each wall is filed under the grid cells its extent
(grown by a margin) covers; an observation asks the cells its own segment covers. The result is a
superset of the walls within the margin, which the caller then checks exactly.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


class WallIndex:
    """Wall ids by grid cell."""

    def __init__(self, cell: float = 2.0, margin: float = 1.0) -> None:
        self.cell = cell
        self.margin = margin
        self._cells: defaultdict[tuple[int, int], set[int]] = defaultdict(set)
        self._filed: dict[int, list[tuple[int, int]]] = {}

    def _bounds(self, segment: Array, margin: float) -> tuple[int, int, int, int]:
        """The first and last cell columns and rows of the segment's box grown by ``margin``."""
        (ax, ay), (bx, by) = segment.tolist()
        cell = self.cell
        return (
            math.floor((min(ax, bx) - margin) / cell),
            math.floor((max(ax, bx) + margin) / cell),
            math.floor((min(ay, by) - margin) / cell),
            math.floor((max(ay, by) + margin) / cell),
        )

    def _cover(self, segment: Array, margin: float) -> list[tuple[int, int]]:
        """Cells of the segment's bounding box grown by ``margin``."""
        x0, x1, y0, y1 = self._bounds(segment, margin)
        return [(i, j) for i in range(x0, x1 + 1) for j in range(y0, y1 + 1)]

    def file(self, wall_id: int, ends: Array) -> None:
        """File (or re-file) a wall under the cells near its extent."""
        cells = self._cover(ends, self.margin)
        if self._filed.get(wall_id) == cells:
            return  # the usual case: an update moves a wall's ends by millimetres
        self.remove(wall_id)
        for cell in cells:
            self._cells[cell].add(wall_id)
        self._filed[wall_id] = cells

    def remove(self, wall_id: int) -> None:
        """Forget a wall (merged away)."""
        for cell in self._filed.pop(wall_id, ()):
            ids = self._cells[cell]
            ids.discard(wall_id)
            if not ids:
                del self._cells[cell]

    def near(self, segment: Array) -> set[int]:
        """Ids of every wall whose grown extent may come within ``margin`` of ``segment``."""
        x0, x1, y0, y1 = self._bounds(segment, 0.0)
        cells, found = self._cells, set[int]()
        for i in range(x0, x1 + 1):
            for j in range(y0, y1 + 1):
                ids = cells.get((i, j))
                if ids:
                    found |= ids
        return found

    def __len__(self) -> int:
        return len(self._filed)
