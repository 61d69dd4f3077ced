"""The line search, compiled (numba): a row's sequential RANSAC in one call.

A 320-point scan row gives about one line, and the same search in numpy is a few hundred small
array calls a frame, each a few microseconds of overhead for a few hundred points of work: most
of a depth frame's detector time. Here each step of it is one loop over the points, and the
rounds of the search (``sequential_lines``) and the row's clusters (``row_lines``) run in one
call: numba draws from numpy's random generator as numpy does. The arithmetic is the numpy
statements', term for term (``line_fit`` and ``ransac`` keep the maths' explanations); sums are
taken in another order, so they agree to rounding, not to the bit.

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
# The line search's settings as ``ransac.RansacConfig.searched_by`` hands them over.
Counts = tuple[int, int, int, int]
Limits = tuple[float, float, float, float, float, float, float, float]


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


# What ``fit_values`` gives, in order (``line_fit.LineFit.from_values`` reads them so).
FIT_FIELDS = (
    "nx", "ny", "offset", "cx", "cy", "c00", "c01", "c11",
    "p0x", "p0y", "p1x", "p1y", "n_points", "rms", "angle_sd", "noise_ratio",
)  # fmt: skip
_FIT_SIZE = len(FIT_FIELDS)  # numba reads module integers as constants; not tuples of names
_P0X, _P0Y, _P1X, _P1Y, _ANGLE_SD = (
    FIT_FIELDS.index(f) for f in ("p0x", "p0y", "p1x", "p1y", "angle_sd")
)
# Why ``sequential_lines`` turned a candidate down, by index into its counts.
REJECTIONS = (
    "no line with min_points inliers",
    "piece below min_points (cut at a gap or kink)",
    "shorter than min_length",
    "direction less sure than max_angle_sd",
)
_REJECTION_COUNT = len(REJECTIONS)


@njit(cache=True, nogil=True)
def _larger(a: float, b: float) -> float:
    """Python's ``max(a, b)``, NaN and all: ``b`` only when it is larger."""
    return b if b > a else a


@njit(cache=True, nogil=True)
def fit_values(points: Array, weights: Array, estimated: bool, cov_scale: float) -> Array:
    """``line_fit.fit_line``'s numbers (``FIT_FIELDS``); ``estimated``: no per-point noise given.

    ``line_fit`` explains the covariance; this is its arithmetic, term for term, so that a
    line fitted here and one fitted there are the same to the bit.
    """
    n = points.shape[0]
    nx, ny, offset, cx, cy, total = weighted_line(points, weights)
    wtt, wrr, rr, t_min, t_max = line_spread(points, weights, nx, ny, cx, cy)
    chi2_per_dof = wrr / max(n - 2, 1)
    scale2 = chi2_per_dof if estimated else _larger(chi2_per_dof, 1.0)
    var_angle = scale2 / _larger(wtt, 1e-12)
    var_offset = scale2 / total
    # Rotating the normal by d_angle about the centroid moves (u, v) along (jx, jy).
    c_along = cy * nx - cx * ny
    jx, jy = nx * c_along - offset * ny, ny * c_along + offset * nx
    out = np.empty(_FIT_SIZE)
    out[0], out[1], out[2], out[3], out[4] = nx, ny, offset, cx, cy
    out[5] = cov_scale * (var_angle * jx * jx + var_offset * nx * nx)
    out[6] = cov_scale * (var_angle * jx * jy + var_offset * nx * ny)
    out[7] = cov_scale * (var_angle * jy * jy + var_offset * ny * ny)
    out[8], out[9] = cx + t_min * -ny, cy + t_min * nx
    out[10], out[11] = cx + t_max * -ny, cy + t_max * nx
    out[12], out[13] = n, math.sqrt(rr / n)
    out[14] = math.sqrt(cov_scale * var_angle)
    out[15] = math.nan if estimated else math.sqrt(chi2_per_dof)
    return out


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
    the order ``sequential_lines`` takes them.
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
def _round_inliers(
    pts: Array, sig: Array, near: Array, rng: np.random.Generator, counts: Counts
) -> Indices:
    """One round: hypotheses drawn and scored, the best one's inliers refitted (line_inliers)."""
    iterations, min_points, _, scored = counts
    n = pts.shape[0]
    first = rng.integers(0, n, iterations)
    second = (first + rng.integers(1, n, iterations)) % n  # never the same point
    return line_inliers(pts, sig, near, first, second, -(-n // scored), min_points)


@njit(cache=True, nogil=True)
def _pieces(
    pts: Array, sig: Array, fit: Array, max_gap: float, min_points: int, split_f: float
) -> tuple[Indices, Indices]:
    """A line's points cut at gaps along it and at kinks: their order along it, the pieces."""
    along = pts[:, 0] * -fit[1] + pts[:, 1] * fit[0]
    order = np.argsort(along)
    return order, segment_ranges(pts, sig, along, order, max_gap, min_points, split_f)


@njit(cache=True, nogil=True)
def _refusal(piece: Array, share: float, limits: Limits) -> int:
    """Why a piece of a line is not one (an index into ``REJECTIONS``), or -1: it is.

    ``share``: of its cluster's points. A line with most of them, and long, has no neighbour to
    blend with, and may be less sure of its direction.
    """
    _, _, _, min_length, max_sd, lone_share, lone_length, lone_sd = limits
    length = math.hypot(piece[_P1X] - piece[_P0X], piece[_P1Y] - piece[_P0Y])
    limit = max_sd
    if share >= lone_share and length >= lone_length:
        limit = _larger(max_sd, lone_sd)
    if length < min_length:
        return 2
    return 3 if piece[_ANGLE_SD] > limit else -1


@njit(cache=True, nogil=True)
def sequential_lines(
    points: Array,
    sigmas: Array,
    band: Array,
    rng: np.random.Generator,
    counts: Counts,
    limits: Limits,
) -> tuple[Array, NDArray[np.int64], Indices, Indices]:
    """One cluster's sequential RANSAC (``ransac.detect_lines`` says what it does).

    ``counts`` and ``limits``: ``ransac.RansacConfig.searched_by``'s. Returns the lines'
    ``fit_values`` (a row each), how many candidates each of ``REJECTIONS`` turned down, and
    the pieces unsure of their direction (their points, one after another; where each starts).
    """
    _, min_points, max_lines, _ = counts
    max_gap, split_f, cov_scale = limits[0], limits[1], limits[2]
    n_all = points.shape[0]
    fits = np.empty((n_all // min_points + 1, _FIT_SIZE))
    rejected = np.zeros(_REJECTION_COUNT, dtype=np.int64)
    unsure = np.empty(n_all, dtype=np.intp)
    unsure_starts = np.zeros(n_all // min_points + 2, dtype=np.intp)
    n_fits = n_unsure = 0
    remaining = np.arange(n_all)
    while remaining.shape[0] >= min_points and n_fits < max_lines:
        pts, sig = points[remaining], sigmas[remaining]
        taken = _round_inliers(pts, sig, band[remaining], rng, counts)
        if taken.shape[0] == 0:
            rejected[0] += 1
            break
        fit = fit_values(pts[taken], 1.0 / (sig[taken] * sig[taken]), False, cov_scale)
        order, pieces = _pieces(pts[taken], sig[taken], fit, max_gap, min_points, split_f)
        taken_out = np.zeros(remaining.shape[0], dtype=np.bool_)
        for k in range(pieces.shape[0]):
            size = pieces[k, 1] - pieces[k, 0]
            if size < min_points:
                rejected[1] += 1
                continue
            idx = taken[order[pieces[k, 0] : pieces[k, 1]]]
            taken_out[idx] = True
            # A line not cut anywhere is the fit just made; only the pieces of a cut one are new.
            piece = fit
            if size != taken.shape[0]:
                piece = fit_values(pts[idx], 1.0 / (sig[idx] * sig[idx]), False, cov_scale)
            refusal = _refusal(piece, size / n_all, limits)
            if refusal < 0:
                fits[n_fits] = piece
                n_fits += 1
                continue
            rejected[refusal] += 1
            if refusal == 3:  # unsure of its direction: a second look beside its neighbour
                start = unsure_starts[n_unsure]
                unsure[start : start + size] = remaining[idx]
                n_unsure += 1
                unsure_starts[n_unsure] = start + size
        if not taken_out.any():
            break
        remaining = remaining[~taken_out]
    end = unsure_starts[n_unsure]
    return fits[:n_fits].copy(), rejected, unsure[:end].copy(), unsure_starts[: n_unsure + 1].copy()


@njit(cache=True, nogil=True)
def row_lines(
    points: Array,
    sigmas: Array,
    band: Array,
    starts: Indices,
    rng: np.random.Generator,
    counts: Counts,
    limits: Limits,
) -> tuple[Array, Indices, NDArray[np.int64], Indices, Indices, Indices]:
    """``sequential_lines`` over each cluster of a row in turn, in one call.

    One call a row, not one a cluster: numba takes 10 us to hand a call its ``rng``.
    ``points`` are the row's finite points cluster after cluster, the clusters starting at
    ``starts`` (``cluster_bounds``); a cluster with fewer than min_points is passed over.
    Returns the lines' ``fit_values`` and the cluster of each, the rejections summed over the
    clusters, and the unsure pieces (indices within their cluster, where each starts, and the
    cluster of each).
    """
    n, min_points = points.shape[0], counts[1]
    room = n // min_points + 1
    fits, fit_cluster = np.empty((room, _FIT_SIZE)), np.empty(room, dtype=np.intp)
    rejected = np.zeros(_REJECTION_COUNT, dtype=np.int64)
    unsure, unsure_cluster = np.empty(n, dtype=np.intp), np.empty(room, dtype=np.intp)
    unsure_starts = np.zeros(room + 1, dtype=np.intp)
    n_fits = n_pieces = 0
    for c in range(starts.shape[0] - 1):
        a, b = starts[c], starts[c + 1]
        if b - a < min_points:
            continue
        found, refused, pieces, piece_starts = sequential_lines(
            points[a:b], sigmas[a:b], band[a:b], rng, counts, limits
        )
        fits[n_fits : n_fits + found.shape[0]] = found
        fit_cluster[n_fits : n_fits + found.shape[0]] = c
        n_fits += found.shape[0]
        rejected += refused
        end = unsure_starts[n_pieces]
        unsure[end : end + pieces.shape[0]] = pieces
        for k in range(piece_starts.shape[0] - 1):
            unsure_cluster[n_pieces] = c
            n_pieces += 1
            unsure_starts[n_pieces] = end + piece_starts[k + 1]
    return (
        fits[:n_fits].copy(),
        fit_cluster[:n_fits].copy(),
        rejected,
        unsure[: unsure_starts[n_pieces]].copy(),
        unsure_starts[: n_pieces + 1].copy(),
        unsure_cluster[:n_pieces].copy(),
    )


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
    """Compile (or load from the cache) the kernels Python calls, now, not on the first frame.

    The others (``line_inliers``, ``segment_ranges``, ...) run inside these only: their own
    entry points would be loaded from the cache for nothing.
    """
    points = np.array([[1.0, float(i) * 0.05] for i in range(30)])
    sigmas = np.full(30, 0.01)
    cluster_bounds(points, 0, math.inf)
    fit_values(points, 1.0 / sigmas**2, False, 1.0)
    bend_cut(points, sigmas, 12, 6.0)
    row_lines(
        points,
        sigmas,
        3 * sigmas,
        np.array([0, 30], dtype=np.intp),
        np.random.default_rng(0),
        (8, 12, 8, 256),
        (0.3, 6.0, 4.0, 0.25, 0.04, 0.9, 0.5, 0.1),
    )
