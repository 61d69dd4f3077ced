"""The line search's inner loops, compiled (numba): one pass over a cluster's points each.

A 320-point scan row gives about one line, and the same search in numpy is a few hundred small
array calls a frame, each a few microseconds of overhead for a few hundred points of work: most
of a depth frame's detector time. Here each step of it is one loop over the points. The
arithmetic is the numpy version's, term for term (``line_fit`` and ``ransac`` keep the maths'
explanations); sums are taken in another order, so results agree to rounding, not to the bit.

Compiled once per machine and cached beside this file (or in the user's cache where that is
not writable); ``warm_up`` compiles or loads them before the first frame needs them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

Array = NDArray[np.float64]
Indices = NDArray[np.intp]


@njit(cache=True, nogil=True)
def weighted_line(points: Array, weights: Array) -> tuple[float, float, float, float, float, float]:
    """Unit normal (away from the origin), offset, centroid and total weight of a TLS line."""
    n = points.shape[0]
    total = 0.0
    mx = 0.0
    my = 0.0
    for i in range(n):
        total += weights[i]
        mx += weights[i] * points[i, 0]
        my += weights[i] * points[i, 1]
    cx, cy = mx / total, my / total
    sxx = sxy = syy = 0.0
    for i in range(n):
        dx, dy = points[i, 0] - cx, points[i, 1] - cy
        sxx += weights[i] * dx * dx
        sxy += weights[i] * dx * dy
        syy += weights[i] * dy * dy
    angle = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    nx, ny = -math.sin(angle), math.cos(angle)
    offset = nx * cx + ny * cy
    if offset < 0.0:
        nx, ny, offset = -nx, -ny, -offset
    return nx, ny, offset, cx, cy, total


@njit(cache=True, nogil=True)
def line_spread(
    points: Array, weights: Array, nx: float, ny: float, cx: float, cy: float
) -> tuple[float, float, float, float, float]:
    """Along a line through (cx, cy): sum w t^2, sum w r^2, sum r^2, lowest and highest t."""
    wtt = wrr = rr = 0.0
    t_min, t_max = math.inf, -math.inf
    for i in range(points.shape[0]):
        dx, dy = points[i, 0] - cx, points[i, 1] - cy
        t = -ny * dx + nx * dy
        r = nx * dx + ny * dy
        wtt += weights[i] * t * t
        wrr += weights[i] * r * r
        rr += r * r
        t_min = min(t_min, t)
        t_max = max(t_max, t)
    return wtt, wrr, rr, t_min, t_max


@njit(cache=True, nogil=True)
def _within(points: Array, band: Array, nx: float, ny: float, offset: float) -> NDArray[np.bool_]:
    """Which points lie within their band of the line (nx, ny, offset)."""
    n = points.shape[0]
    inside = np.empty(n, dtype=np.bool_)
    for i in range(n):
        inside[i] = abs(points[i, 0] * nx + points[i, 1] * ny - offset) <= band[i]
    return inside


@njit(cache=True, nogil=True)
def _indices(inside: NDArray[np.bool_], at_least: int) -> Indices:
    """The indices where ``inside`` holds, or none if fewer than ``at_least``."""
    found = np.empty(inside.shape[0], dtype=np.intp)
    count = 0
    for i in range(inside.shape[0]):
        if inside[i]:
            found[count] = i
            count += 1
    return found[:count] if count >= at_least else found[:0]


@njit(cache=True, nogil=True)
def line_inliers(
    points: Array,
    sigmas: Array,
    band: Array,
    first: Indices,
    second: Indices,
    step: int,
    min_points: int,
) -> Indices:
    """The inliers of the best two-point hypothesis, refitted once; empty when too few.

    Hypotheses are scored on every ``step``-th point; the best one's inliers over all points
    give a weighted line, whose own inliers (the refinement picks up what the pair missed)
    are returned.
    """
    best, best_count = 0, -1
    for h in range(first.shape[0]):
        sx, sy = points[first[h], 0], points[first[h], 1]
        dx, dy = points[second[h], 0] - sx, points[second[h], 1] - sy
        length = math.hypot(dx, dy)
        nx, ny = -dy / length, dx / length
        offset = nx * sx + ny * sy
        count = 0
        for i in range(0, points.shape[0], step):
            if abs(nx * points[i, 0] + ny * points[i, 1] - offset) <= band[i]:
                count += 1
        if count > best_count:
            best, best_count = h, count
    sx, sy = points[first[best], 0], points[first[best], 1]
    dx, dy = points[second[best], 0] - sx, points[second[best], 1] - sy
    length = math.hypot(dx, dy)
    nx, ny = -dy / length, dx / length
    inside = _within(points, band, nx, ny, nx * sx + ny * sy)
    if _indices(inside, min_points).shape[0] == 0:
        return np.empty(0, dtype=np.intp)
    weights = np.zeros(points.shape[0])  # the pair's inliers weigh in; the others do not
    for i in range(points.shape[0]):
        if inside[i]:
            weights[i] = 1.0 / (sigmas[i] * sigmas[i])
    nx, ny, offset, _, _, _ = weighted_line(points, weights)
    return _indices(_within(points, band, nx, ny, offset), min_points)


@njit(cache=True, nogil=True)
def _scatter_residual(w: float, sx: float, sy: float, sxx: float, sxy: float, syy: float) -> float:
    """Weighted sum of squared TLS residuals from running sums (the 2x2 scatter's eigenvalue)."""
    a = sxx - sx * sx / w
    b = sxy - sx * sy / w
    c = syy - sy * sy / w
    return 0.5 * (a + c) - math.sqrt(0.25 * (a - c) * (a - c) + b * b)


@njit(cache=True, nogil=True)
def bend_cut(points: Array, sigmas: Array, min_points: int, f_threshold: float) -> int:
    """``line_fit.bend_split``'s cut: the first part's size, or -1 to keep one line."""
    n = points.shape[0]
    if n < 2 * min_points:
        return -1
    mx, my = points[n // 2, 0], points[n // 2, 1]  # centred on a middle point: precise sums
    sums = np.empty((6, n))  # running sums of w, wx, wy, wxx, wxy, wyy
    w_, x_, y_, xx, xy, yy = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for i in range(n):
        w = 1.0 / (sigmas[i] * sigmas[i])
        x, y = points[i, 0] - mx, points[i, 1] - my
        wx, wy = w * x, w * y
        w_, x_, y_ = w_ + w, x_ + wx, y_ + wy
        xx, xy, yy = xx + wx * x, xy + wx * y, yy + wy * y
        sums[0, i], sums[1, i], sums[2, i] = w_, x_, y_
        sums[3, i], sums[4, i], sums[5, i] = xx, xy, yy
    one = _scatter_residual(w_, x_, y_, xx, xy, yy)
    best, lowest = -1, math.inf
    for k in range(min_points - 1, n - min_points):
        a0, a1, a2 = sums[0, k], sums[1, k], sums[2, k]
        a3, a4, a5 = sums[3, k], sums[4, k], sums[5, k]
        two = _scatter_residual(a0, a1, a2, a3, a4, a5) + _scatter_residual(
            w_ - a0, x_ - a1, y_ - a2, xx - a3, xy - a4, yy - a5
        )
        if two < lowest or best < 0:
            best, lowest = k, two
    residual = max(lowest, 1e-12)
    f = ((one - residual) / 3.0) / (residual / (n - 5))
    return best + 1 if f > f_threshold else -1


@njit(cache=True, nogil=True)
def segment_ranges(
    points: Array,
    sigmas: Array,
    along: Array,
    order: Indices,
    max_gap: float,
    min_points: int,
    split_f: float,
) -> Indices:
    """A line's points cut at gaps along it and at kinks: the pieces as runs of ``order``.

    ``along``: the points' positions along the line; ``order``: their sorting (numpy's, passed
    in: a sort compiled here costs seconds of compiling). Each piece is a (start, end) row, in
    the order ``ransac._segments`` hands them out.
    """
    n = points.shape[0]
    ordered = np.empty((n, 2))
    ordered_sigmas = np.empty(n)
    for i in range(n):
        ordered[i, 0], ordered[i, 1] = points[order[i], 0], points[order[i], 1]
        ordered_sigmas[i] = sigmas[order[i]]
    pending = np.empty((2 * n + 1, 2), dtype=np.intp)  # a stack of runs still to look at
    waiting = 0
    start = 0
    for i in range(1, n):
        if along[order[i]] - along[order[i - 1]] > max_gap:
            pending[waiting, 0], pending[waiting, 1] = start, i
            waiting += 1
            start = i
    pending[waiting, 0], pending[waiting, 1] = start, n
    waiting += 1
    done = np.empty((2 * n + 1, 2), dtype=np.intp)
    count = 0
    while waiting:
        waiting -= 1
        lo, hi = pending[waiting, 0], pending[waiting, 1]
        cut = bend_cut(ordered[lo:hi], ordered_sigmas[lo:hi], min_points, split_f)
        if cut < 0:
            done[count, 0], done[count, 1] = lo, hi
            count += 1
        else:
            pending[waiting, 0], pending[waiting, 1] = lo, lo + cut
            pending[waiting + 1, 0], pending[waiting + 1, 1] = lo + cut, hi
            waiting += 2
    return done[:count].copy()


@njit(cache=True, nogil=True)
def cluster_bounds(points: Array, nan_run: int, max_jump: float) -> tuple[Indices, Indices]:
    """The finite points' indices and where clusters start among them (``split_at_nans``)."""
    n = points.shape[0]
    index = np.empty(n, dtype=np.intp)
    count = 0
    for i in range(n):
        if math.isfinite(points[i, 0]) and math.isfinite(points[i, 1]):
            index[count] = i
            count += 1
    starts = np.empty(count + 1, dtype=np.intp)
    cuts = 0
    if count:
        starts[0] = 0
        cuts = 1
    for k in range(1, count):
        a, b = index[k - 1], index[k]
        skipped = b - a - 1
        jump = math.hypot(points[b, 0] - points[a, 0], points[b, 1] - points[a, 1])
        if skipped > nan_run or jump > max_jump:
            starts[cuts] = k
            cuts += 1
    starts[cuts] = count
    return index[:count].copy(), starts[: cuts + 1].copy()


def warm_up() -> None:
    """Compile (or load from the cache) every kernel now, not on the first frame."""
    points = np.array([[1.0, float(i) * 0.05] for i in range(30)])
    sigmas = np.full(30, 0.01)
    pick = np.arange(4, dtype=np.intp)
    line_inliers(points, sigmas, 3 * sigmas, pick, pick + 10, 1, 12)
    nx, ny, _, cx, cy, _ = weighted_line(points, 1.0 / sigmas**2)
    line_spread(points, 1.0 / sigmas**2, nx, ny, cx, cy)
    along = points @ np.array([-ny, nx])
    segment_ranges(points, sigmas, along, np.argsort(along), 0.3, 12, 6.0)
    cluster_bounds(points, 0, math.inf)
