"""The band stack's per-point work, compiled (numba): what rises through it, where rays end.

``scan_row.upright_points`` and ``scan_row.free_rays`` explain the method; these are their
loops. In numpy they were some sixty whole-array calls over a few thousand points a frame,
most of a depth frame's time before the line search; here each is a pass or two over the
points. The arithmetic is numpy's, in the same precision (heights in float32, floor positions
in float64), so the points kept are the same.

Compiled once per machine and cached, as ``line_kernels`` is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numpy.typing import NDArray

Array = NDArray[np.float64]
Stack = NDArray[np.float32]
_ROW = 1_000_003  # cell key = x * _ROW + y: unique for any floor plan a sensor sees


# A player's searched rows: a strided, read-only view over the message as often as not (a cloud's
# rows in the bag's memory map). Typed so, one compiled loop takes every layout without a copy.
_ROWS = types.Array(types.float32, 3, "A", readonly=True)


@njit(
    types.float32[:, :, ::1](
        _ROWS, types.float64[:, ::1], types.float64, types.float64, types.intp
    ),
    cache=True,
    nogil=True,
)
def band_stack(points: Stack, mount: Array, low: float, high: float, levels: int) -> Stack:
    """Per column, the points nearest ``levels`` heights spread over ``[low, high]``.

    ``scan_row.band_stack`` explains it; heights and their distances are float32, as numpy
    computes them there, and the first row of equals is taken, as ``argmin`` does. A point is
    tried against the level its height falls in and the two beside it only: no other level is
    within half a spacing of it, so the picks are those of trying every level, in two thirds of
    the time on a cloud's rows (most points lie outside the band, and are passed over at once).
    """
    rows, width = points.shape[0], points.shape[1]
    a, b = np.float32(mount[2, 0]), np.float32(mount[2, 1])
    c, d = np.float32(mount[2, 2]), np.float32(mount[2, 3])
    spacing = (high - low) / levels
    half = np.float32(0.5 * spacing)
    targets = np.empty(levels, dtype=np.float32)
    for level in range(levels):
        targets[level] = np.float32(low + (level + 0.5) * spacing)
    best = np.full((levels, width), np.inf, dtype=np.float32)
    row_of = np.full((levels, width), -1, dtype=np.intp)
    below, above = low - spacing, high + spacing
    for r in range(rows):
        for j in range(width):
            height = points[r, j, 0] * a + points[r, j, 1] * b + points[r, j, 2] * c + d
            if not below < height < above:  # no level within reach (or a NaN height)
                continue
            near = math.floor((height - low) / spacing)
            for level in range(max(near - 1, 0), min(near + 2, levels)):
                cost = abs(height - targets[level])
                if cost <= half and cost < best[level, j]:  # False for a NaN height
                    best[level, j] = cost
                    row_of[level, j] = r
    stack = np.full((levels, width, 3), np.nan, dtype=np.float32)
    for level in range(levels):
        for j in range(width):
            if row_of[level, j] >= 0:
                stack[level, j, :] = points[row_of[level, j], j, :]
    return stack


@njit(cache=True, nogil=True)
def base_positions(
    stack: Stack, mount: Array, cell: float
) -> tuple[NDArray[np.float32], Array, NDArray[np.bool_], NDArray[np.int64]]:
    """Each stack point's height (float32, as the player's), floor position and validity.

    And the floor cell (``cell`` m square) of each valid point, in order, as one key.
    """
    levels, width = stack.shape[0], stack.shape[1]
    a, b = np.float32(mount[2, 0]), np.float32(mount[2, 1])
    c, d = np.float32(mount[2, 2]), np.float32(mount[2, 3])
    height = np.empty((levels, width), dtype=np.float32)
    xy = np.empty((levels, width, 2))
    valid = np.empty((levels, width), dtype=np.bool_)
    keys = np.empty(levels * width, dtype=np.int64)
    count = 0
    for k in range(levels):
        for j in range(width):
            p = stack[k, j]
            height[k, j] = p[0] * a + p[1] * b + p[2] * c + d
            x, y, z = np.float64(p[0]), np.float64(p[1]), np.float64(p[2])
            xy[k, j, 0] = x * mount[0, 0] + y * mount[0, 1] + z * mount[0, 2] + mount[0, 3]
            xy[k, j, 1] = x * mount[1, 0] + y * mount[1, 1] + z * mount[1, 2] + mount[1, 3]
            ok = math.isfinite(xy[k, j, 0]) and math.isfinite(xy[k, j, 1])
            valid[k, j] = ok and math.isfinite(height[k, j])
            if valid[k, j]:
                cx = np.int64(math.floor(xy[k, j, 0] / cell))
                keys[count] = cx * _ROW + np.int64(math.floor(xy[k, j, 1] / cell))
                count += 1
    return height, xy, valid, keys[:count]


@njit(cache=True, nogil=True)
def _find(ordered: NDArray[np.int64], key: np.int64) -> int:
    """Where ``key`` is in ``ordered`` (ascending), or -1: a binary search."""
    lo, hi = 0, ordered.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if ordered[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo if lo < ordered.shape[0] and ordered[lo] == key else -1


@njit(cache=True, nogil=True)
def cell_spread(
    keys: NDArray[np.int64], order: NDArray[np.intp], values: Array
) -> tuple[Array, Array]:
    """Per point, the lowest and highest ``values`` over its floor cell and the 8 around it.

    ``keys``: the points' cells (``base_positions``); ``order``: their sorting (numpy's, passed
    in: a sort compiled here costs seconds of compiling). Per occupied cell first (a cell's
    extremes over its run), then each cell's neighbours looked up among the occupied cells by
    binary search.
    """
    n = keys.shape[0]
    cell_of = np.empty(n, dtype=np.int64)
    unique = np.empty(n, dtype=np.int64)
    low = np.empty(n)
    high = np.empty(n)
    cells = -1
    for i in range(n):
        p = order[i]
        if cells < 0 or keys[p] != unique[cells]:
            cells += 1
            unique[cells], low[cells], high[cells] = keys[p], values[p], values[p]
        else:
            low[cells] = min(low[cells], values[p])
            high[cells] = max(high[cells], values[p])
        cell_of[p] = cells
    cells += 1
    unique = unique[:cells]
    around_low = np.full(cells, np.inf)
    around_high = np.full(cells, -np.inf)
    for u in range(cells):
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                at = _find(unique, unique[u] + dx * _ROW + dy)
                if at >= 0:
                    around_low[u] = min(around_low[u], low[at])
                    around_high[u] = max(around_high[u], high[at])
    return around_low[cell_of], around_high[cell_of]


@njit(cache=True, nogil=True)
def _column_extents(
    height: NDArray[np.float32], valid: NDArray[np.bool_]
) -> tuple[Array, Array, float]:
    """Per column the highest and lowest valid height (-inf, inf: none); the band all span."""
    levels, width = valid.shape
    column_top = np.full(width, -np.inf)
    column_bottom = np.full(width, np.inf)
    for k in range(levels):
        for j in range(width):
            if valid[k, j]:
                column_top[j] = max(column_top[j], np.float64(height[k, j]))
                column_bottom[j] = min(column_bottom[j], np.float64(height[k, j]))
    highest, lowest = -np.inf, np.inf
    for j in range(width):
        if column_top[j] > -np.inf:
            highest, lowest = max(highest, column_top[j]), min(lowest, column_bottom[j])
    return column_top, column_bottom, highest - lowest if highest > -np.inf else 0.0


@njit(cache=True, nogil=True)
def upright_choice(
    stack: Stack,
    height: NDArray[np.float32],
    xy: Array,
    valid: NDArray[np.bool_],
    keys: NDArray[np.int64],
    order: NDArray[np.intp],
    share: float,
    top_reach: float,
    cell: float,
) -> Stack:
    """``scan_row.upright_points`` from ``base_positions``' and the cells' sorting."""
    levels, width = valid.shape
    values = np.empty(keys.shape[0])
    at = 0
    for k in range(levels):
        for j in range(width):
            if valid[k, j]:
                values[at] = np.float64(height[k, j])
                at += 1
    low, high = cell_spread(keys, order, values)
    rise = np.zeros((levels, width))
    top = np.full((levels, width), -np.inf)
    at = 0
    for k in range(levels):
        for j in range(width):
            if valid[k, j]:
                top[k, j], rise[k, j] = high[at], high[at] - low[at]
                at += 1
    column_top, column_bottom, band = _column_extents(height, valid)
    middle = 0.5 * (levels - 1)
    out = np.full((width, 3), np.nan, dtype=np.float32)
    kept = np.zeros(levels, dtype=np.bool_)
    for j in range(width):
        seen = column_top[j] > -np.inf
        visible = column_top[j] - column_bottom[j] if seen else 0.0
        need = min(share * band, share * visible)
        best, preference = -1, -np.inf
        for k in range(levels):
            kept[k] = valid[k, j] and rise[k, j] >= need and top[k, j] >= column_top[j] - top_reach
            if kept[k]:
                score = rise[k, j] - 1e-3 * abs(k - middle)
                if score > preference:
                    best, preference = k, score
        if best < 0:
            continue
        # The mean of the kept points on the best one's spot (see upright_points).
        sx, sy, sz, weight = np.float32(0), np.float32(0), np.float32(0), np.float32(0)
        for k in range(levels):
            if kept[k]:
                dx, dy = xy[k, j, 0] - xy[best, j, 0], xy[k, j, 1] - xy[best, j, 1]
                if math.sqrt(dx * dx + dy * dy) <= 2 * cell:
                    sx += stack[k, j, 0]
                    sy += stack[k, j, 1]
                    sz += stack[k, j, 2]
                    weight += np.float32(1)
        out[j, 0], out[j, 1], out[j, 2] = sx / weight, sy / weight, sz / weight
    return out


@njit(cache=True, nogil=True)
def farthest_ends(xy: Array, valid: NDArray[np.bool_], ox: float, oy: float) -> Array:
    """Per column, the floor position of its farthest valid point from (ox, oy); (n, 2)."""
    levels, width = valid.shape
    ends = np.empty((width, 2))
    count = 0
    for j in range(width):
        best, reach = -1, -1.0
        for k in range(levels):
            if valid[k, j]:
                dx, dy = xy[k, j, 0] - ox, xy[k, j, 1] - oy
                r = math.sqrt(dx * dx + dy * dy)
                if r > reach:
                    best, reach = k, r
        if best >= 0 and reach > 0:
            ends[count, 0], ends[count, 1] = xy[best, j, 0], xy[best, j, 1]
            count += 1
    return ends[:count].copy()


def warm_up_stack() -> None:
    """Compile (or load from the cache) a player's loop, ``band_stack``, alone."""
    band_stack(np.zeros((4, 3, 3), dtype=np.float32), np.eye(4), 1.3, 2.1, 6)


def warm_up() -> None:
    """Compile (or load from the cache) every kernel now, not on the first frame."""
    warm_up_stack()
    stack = np.zeros((2, 3, 3), dtype=np.float32)
    height, xy, valid, keys = base_positions(stack, np.eye(4), 0.04)
    upright_choice(stack, height, xy, valid, keys, np.argsort(keys), 0.6, 0.1, 0.04)
    farthest_ends(xy, valid, 0.0, 0.0)
