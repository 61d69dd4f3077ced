"""Room segmentation's loops, compiled (numba): over the grid's cells, and ends by segments.

``rooms.find_rooms`` explains the method; these are its per-cell and per-pair loops. A building
of a hundred rooms is a few hundred thousand cells and hundreds of wall ends by hundreds of
segments, and in numpy each of these was a dozen whole-array calls (runs, searches, sorts,
divisions, boolean matrices); here each is a pass or two. They release the GIL, so the mapper's
rooms worker does not hold up its frames while it segments.

Compiled once per machine and cached, as ``line_kernels`` is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

Array = NDArray[np.float64]


@njit(cache=True, nogil=True)
def _root(parent: NDArray[np.int32], k: int) -> int:
    """The root of ``k``'s tree, halving the path on the way (every parent is below its child)."""
    while parent[k] != k:
        parent[k] = parent[parent[k]]
        k = parent[k]
    return k


@njit(cache=True, nogil=True)
def label4(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int32], int]:
    """4-connected components of ``mask``: labels 0..n-1 (-1 outside), and n.

    Components are numbered by their first cell, row-major. One pass gives each cell its upper
    or left neighbour's provisional label (a new one if it has neither), joining the two trees
    where both are labelled; the smaller root stays, so a component's root is its first label,
    made at its first cell. A second pass numbers the roots in order and relabels. A cell with
    a new label has no labelled neighbour above or to its left, so no two such cells touch:
    half the cells, rounded up, at most.
    """
    rows, cols = mask.shape
    labels = np.full((rows, cols), -1, dtype=np.int32)
    parent = np.empty((rows * cols + 1) // 2 + 1, dtype=np.int32)
    made = 0
    for i in range(rows):
        for j in range(cols):
            if not mask[i, j]:
                continue
            up = labels[i - 1, j] if i > 0 else -1
            left = labels[i, j - 1] if j > 0 else -1
            if up < 0 and left < 0:
                parent[made] = made
                labels[i, j] = made
                made += 1
            elif up < 0 or left < 0:
                labels[i, j] = max(up, left)
            else:
                a, b = _root(parent, up), _root(parent, left)
                low = min(a, b)
                parent[max(a, b)] = low
                labels[i, j] = low
    final = np.empty(made, dtype=np.int32)
    n = 0
    for k in range(made):  # a parent precedes its children: its number is known
        if parent[k] == k:
            final[k] = n
            n += 1
        else:
            final[k] = final[parent[k]]
    for i in range(rows):
        for j in range(cols):
            if labels[i, j] >= 0:
                labels[i, j] = final[labels[i, j]]
    return labels, n


@njit(cache=True, nogil=True)
def draw_segments(
    mask: NDArray[np.bool_],
    lo: NDArray[np.int64],
    hi: NDArray[np.int64],
    p: Array,
    q: Array,
    origin: NDArray[np.int64],
    cell: float,
    radius: float,
) -> None:
    """Mark the cells of ``mask`` whose centres lie within ``radius`` of a segment p[k]-q[k].

    Each segment's box of cells, ``lo[k]`` to ``hi[k]`` inclusive (local, within the grid);
    local cell (i, j) is global ``origin + (i, j)``, its centre half a cell in.
    """
    for k in range(len(p)):
        px, py = p[k, 0], p[k, 1]
        dx, dy = q[k, 0] - px, q[k, 1] - py
        scale = 1.0 / max(dx * dx + dy * dy, 1e-12)
        for i in range(lo[k, 0], hi[k, 0] + 1):
            rx = (i + origin[0] + 0.5) * cell - px
            for j in range(lo[k, 1], hi[k, 1] + 1):
                ry = (j + origin[1] + 0.5) * cell - py
                t = min(max((rx * dx + ry * dy) * scale, 0.0), 1.0)
                if math.hypot(rx - t * dx, ry - t * dy) <= radius:
                    mask[i, j] = True


@njit(cache=True, nogil=True)
def cells_by_label(
    labels: NDArray[np.int32], n: int, origin: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Every labelled cell as ``origin + (i, j)``, and where each label's group ends.

    Grouped by label 0..n-1, row-major within each group.
    """
    rows, cols = labels.shape
    ends = np.zeros(n, dtype=np.int64)
    for i in range(rows):
        for j in range(cols):
            if labels[i, j] >= 0:
                ends[labels[i, j]] += 1
    for k in range(1, n):
        ends[k] += ends[k - 1]
    at = np.zeros(n, dtype=np.int64)
    at[1:] = ends[:-1]
    cells = np.empty((ends[-1] if n else 0, 2), dtype=np.int64)
    for i in range(rows):
        for j in range(cols):
            k = labels[i, j]
            if k >= 0:
                cells[at[k], 0] = origin[0] + i
                cells[at[k], 1] = origin[1] + j
                at[k] += 1
    return cells, ends


@njit(cache=True, nogil=True)
def near_pairs(points: Array, lo: Array, hi: Array) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (point k, box s) with the point inside box s (``lo[s]`` to ``hi[s]``, inclusive).

    In order of point, then box.
    """
    found = 0
    for pass_ in range(2):  # count, then fill
        if pass_:
            k_out = np.empty(found, dtype=np.int64)
            s_out = np.empty(found, dtype=np.int64)
            found = 0
        for k in range(len(points)):
            x, y = points[k, 0], points[k, 1]
            for s in range(len(lo)):
                if lo[s, 0] <= x <= hi[s, 0] and lo[s, 1] <= y <= hi[s, 1]:
                    if pass_:
                        k_out[found] = k
                        s_out[found] = s
                    found += 1
    return k_out, s_out


@njit(cache=True, nogil=True)
def label_counts(
    labels: NDArray[np.int32], n: int, seen: NDArray[np.bool_]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Cells per label 0..n-1 (-1: none), and of those the ``seen`` ones."""
    cells = np.zeros(n, dtype=np.int64)
    seen_cells = np.zeros(n, dtype=np.int64)
    rows, cols = labels.shape
    for i in range(rows):
        for j in range(cols):
            k = labels[i, j]
            if k >= 0:
                cells[k] += 1
                if seen[i, j]:
                    seen_cells[k] += 1
    return cells, seen_cells


@njit(cache=True, nogil=True)
def grow(labels: NDArray[np.int32], barrier: NDArray[np.bool_], steps: int) -> None:
    """Labels grown ``steps`` cells into unlabelled ``barrier`` cells, in place.

    Each step takes from the neighbour above, then below, left, right, in turn, each after
    the one before: a cell gets the first labelled neighbour in that order.
    """
    rows, cols = labels.shape
    for _ in range(steps):
        for i in range(rows - 1, 0, -1):  # from above: rows in descending order, so a row
            for j in range(cols):  # takes from the one above it before that one changed
                if barrier[i, j] and labels[i, j] < 0 and labels[i - 1, j] >= 0:
                    labels[i, j] = labels[i - 1, j]
        for i in range(rows - 1):  # from below
            for j in range(cols):
                if barrier[i, j] and labels[i, j] < 0 and labels[i + 1, j] >= 0:
                    labels[i, j] = labels[i + 1, j]
        for i in range(rows):
            for j in range(cols - 1, 0, -1):  # from the left
                if barrier[i, j] and labels[i, j] < 0 and labels[i, j - 1] >= 0:
                    labels[i, j] = labels[i, j - 1]
            for j in range(cols - 1):  # from the right
                if barrier[i, j] and labels[i, j] < 0 and labels[i, j + 1] >= 0:
                    labels[i, j] = labels[i, j + 1]


@njit(cache=True, nogil=True)
def nearest_ahead(
    among: NDArray[np.int64],
    point: Array,
    outward: Array,
    piece: NDArray[np.int64],
    a: Array,
    b: Array,
    reach: float,
    cos_max: float,
) -> Array:
    """Per end of ``among``, the nearest point of another segment ahead of it; NaN where none.

    ``rooms._nearest_ahead`` says what is ahead. Tried in the order of the segments' first
    ends, then their second ends, then the end's feet on them, each by segment: the first of
    a tie in distance is taken.
    """
    out = np.full((len(point), 2), np.nan)
    for k in among:
        px, py, ox, oy = point[k, 0], point[k, 1], outward[k, 0], outward[k, 1]
        best, first = np.inf, (3, 0)  # the distance, and (kind, segment) of the first at it
        for s in range(len(a)):
            if s == piece[k] or not (
                min(a[s, 0], b[s, 0]) - reach <= px <= max(a[s, 0], b[s, 0]) + reach
                and min(a[s, 1], b[s, 1]) - reach <= py <= max(a[s, 1], b[s, 1]) + reach
            ):
                continue
            sx, sy = b[s, 0] - a[s, 0], b[s, 1] - a[s, 1]
            rx, ry = px - a[s, 0], py - a[s, 1]
            t = min(max((rx * sx + ry * sy) / max(sx * sx + sy * sy, 1e-12), 0.0), 1.0)
            for kind in range(3):
                if kind == 0:
                    x, y = a[s, 0], a[s, 1]
                elif kind == 1:
                    x, y = b[s, 0], b[s, 1]
                else:
                    x, y = a[s, 0] + t * sx, a[s, 1] + t * sy
                gx, gy = x - px, y - py
                dist = math.hypot(gx, gy)
                if dist <= 1e-6 or dist > reach or not (gx * ox + gy * oy) / dist >= cos_max:
                    continue
                if dist < best or (dist == best and (kind, s) < first):
                    best, first = dist, (kind, s)
                    out[k, 0], out[k, 1] = x, y
    return out


@njit(cache=True, nogil=True)
def _along(usable: float, step: float) -> int:
    """How many samples a ray has: every ``step`` from its start while within ``usable``."""
    n = 0
    while float(n) * step <= usable:
        n += 1
    return n


# Frames' samples, as ``free_space`` hands them over: ``(starts, units, usable, firsts, disc,
# step, cell)``. Frame ``f``'s rays are ``units[firsts[f]:firsts[f + 1]]`` from ``starts[f]``,
# sampled every ``step`` while within their ``usable`` length; its robot's ``disc`` (offsets)
# is around ``starts[f]``; the grid's cells are ``cell`` wide.
Samples = tuple[Array, Array, Array, NDArray[np.int64], Array, float, float]


@njit(cache=True, nogil=True)
def _visit_samples(
    samples: Samples,
    counts: NDArray[np.uint8],
    origin: NDArray[np.int64],
    bounds: NDArray[np.int64],
) -> None:
    """Visit the cell of every sample: count it, or widen ``bounds`` if ``counts`` is empty.

    A sample's cell is worked out as numpy does it, term for term: ``floor((start + (n step)
    unit) / cell)``. Counted in ``counts`` (cell ``origin + (i, j)`` at ``[i, j]``, saturating
    at 255), or the lowest and highest cells kept in ``bounds`` (2, 2).
    """
    starts, units, usable, firsts, disc, step, cell = samples
    counting = counts.size > 0
    for f in range(starts.shape[0]):
        x, y = starts[f, 0], starts[f, 1]
        for k in range(firsts[f], firsts[f + 1]):
            for n in range(_along(usable[k], step)):
                along = float(n) * step
                i, j = (
                    math.floor((x + along * units[k, 0]) / cell),
                    math.floor((y + along * units[k, 1]) / cell),
                )
                _visit(i, j, counting, counts, origin, bounds)
        for d in range(disc.shape[0]):
            i, j = math.floor((x + disc[d, 0]) / cell), math.floor((y + disc[d, 1]) / cell)
            _visit(i, j, counting, counts, origin, bounds)


@njit(cache=True, nogil=True, inline="always")  # a call a sample otherwise: 3x the time
def _visit(
    i: int,
    j: int,
    counting: bool,
    counts: NDArray[np.uint8],
    origin: NDArray[np.int64],
    bounds: NDArray[np.int64],
) -> None:
    """One sample in cell (i, j): counted, or taken into ``bounds`` (see ``_visit_samples``)."""
    if counting:
        counts[i - origin[0], j - origin[1]] = min(counts[i - origin[0], j - origin[1]] + 1, 255)
    else:
        bounds[0, 0], bounds[1, 0] = min(bounds[0, 0], i), max(bounds[1, 0], i)
        bounds[0, 1], bounds[1, 1] = min(bounds[0, 1], j), max(bounds[1, 1], j)


@njit(cache=True, nogil=True)
def sample_bounds(samples: Samples) -> NDArray[np.int64]:
    """The lowest and highest cells (2, 2) of frames' samples (``Samples``)."""
    bounds = np.empty((2, 2), dtype=np.int64)
    bounds[0, :] = np.iinfo(np.int64).max
    bounds[1, :] = np.iinfo(np.int64).min
    _visit_samples(samples, np.zeros((0, 0), dtype=np.uint8), bounds[0], bounds)
    return bounds


@njit(cache=True, nogil=True)
def count_samples(counts: NDArray[np.uint8], origin: NDArray[np.int64], samples: Samples) -> None:
    """One count (saturating at 255) per sample, in a grid holding ``sample_bounds``' cells."""
    _visit_samples(samples, counts, origin, np.empty((2, 2), dtype=np.int64))


def warm_up() -> None:
    """Compile (or load from the cache) every kernel now, not at the first update."""
    mask = np.ones((3, 3), dtype=np.bool_)
    labels, n = label4(mask)
    cells_by_label(labels, n, np.zeros(2, dtype=np.int64))
    label_counts(labels, n, mask)
    grow(labels, mask, 1)
    box = np.zeros((1, 2), dtype=np.int64)
    point = np.zeros((1, 2))
    draw_segments(mask, box, box, point, point, np.zeros(2, dtype=np.int64), 0.1, 0.1)
    near_pairs(point, point, point)
    one = np.zeros(1, dtype=np.int64)
    nearest_ahead(one, point, point, one, point, point, 1.0, 0.5)
    samples = (point, point, np.zeros(1), np.zeros(2, dtype=np.int64), point, 0.05, 0.1)
    count_samples(np.zeros((3, 3), np.uint8), sample_bounds(samples)[0], samples)
