"""Regions of a boolean grid: connected components, outlines as polygons, simplification.

What room segmentation needs of image processing, in numpy, a little Python and one compiled
pass (components, ``room_kernels``): the mapper carries no image library.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wallmap.common import compiled

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


def label(mask: Mask) -> tuple[NDArray[np.int32], int]:
    """4-connected components of ``mask``: labels 0..n-1 (-1 outside ``mask``), and n.

    Components are numbered by their first cell, row-major (``room_kernels.label4``).
    """
    return compiled.room_kernels().label4(compiled.plain(mask, np.bool_))


def spread(counts: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Items counted per group, listed end to end: each one's group and its place in the group.

    ``counts`` [2, 0, 3] gives groups [0, 0, 2, 2, 2] and places [0, 1, 0, 1, 2]: a loop over
    groups and their items done as whole arrays.
    """
    counts = np.asarray(counts, dtype=np.int64)
    group = np.repeat(np.arange(len(counts)), counts)
    return group, np.arange(len(group)) - np.repeat(np.cumsum(counts) - counts, counts)


def touches_border(labels: NDArray[np.int32], n: int) -> NDArray[np.bool_]:
    """Per label, whether it reaches the grid's edge (open to what lies beyond the grid)."""
    edge = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    out = np.zeros(n, dtype=bool)
    out[edge[edge >= 0]] = True
    return out


def outline(mask: Mask) -> Array:
    """The outer boundary of ``mask``'s cells, counter-clockwise, in cell units (its corners).

    Cell (i, j) spans [i, i+1] x [j, j+1]. Boundary edges are chained with the region on their
    left; where two loops touch at a corner the sharper left turn is taken, so loops stay apart.
    Of the loops, the one of largest area is the outer boundary (holes run clockwise). Edges in
    a straight line are joined first (``_straight_edges``): a loop is walked corner to corner.
    """
    m = np.zeros((mask.shape[0] + 2, mask.shape[1] + 2), dtype=bool)
    m[1:-1, 1:-1] = mask
    nxt: dict[tuple[int, int], list[tuple[int, int]]] = {}
    # x = i (rows), y = j (columns), in padded corner units; region on the left of each edge;
    # each unit edge given by its lower corner along its line.
    i, j = np.nonzero(m[1:, :] & ~m[:-1, :])  # cell (i+1, j) in, (i, j) out: at x = i+1, -y
    _straight_edges(nxt, i + 1, j, axis=1, step=-1)
    i, j = np.nonzero(m[:-1, :] & ~m[1:, :])  # cell (i, j) in, (i+1, j) out: at x = i+1, +y
    _straight_edges(nxt, i + 1, j, axis=1, step=1)
    i, j = np.nonzero(m[:, 1:] & ~m[:, :-1])  # cell (i, j+1) in, (i, j) out: at y = j+1, +x
    _straight_edges(nxt, i, j + 1, axis=0, step=1)
    i, j = np.nonzero(m[:, :-1] & ~m[:, 1:])  # cell (i, j) in, (i, j+1) out: at y = j+1, -x
    _straight_edges(nxt, i, j + 1, axis=0, step=-1)
    best, best_area = np.zeros((0, 2)), 0.0
    while nxt:
        loop = _walk(nxt)
        area = polygon_area(loop)
        if area > best_area:
            best, best_area = loop, area
    return best - 1.0  # the padding


def _straight_edges(
    nxt: dict[tuple[int, int], list[tuple[int, int]]],
    x: NDArray[np.int64],
    y: NDArray[np.int64],
    axis: int,
    step: int,
) -> None:
    """Unit edges from (x, y), one along ``axis`` by ``step`` each, joined into straight runs.

    A corner inside a run is never a corner of another edge (cells on either side of the line
    are in on one side and out on the other all along), so the join loses no junction.
    """
    line, along = (x, y) if axis == 1 else (y, x)
    order = np.lexsort((along, line))
    line, along = line[order], along[order]
    breaks = np.flatnonzero((np.diff(line) != 0) | (np.diff(along) != 1)) + 1
    first = np.concatenate([[0], breaks]).astype(np.int64)
    last = np.concatenate([breaks - 1, [len(line) - 1]]).astype(np.int64)
    if not len(line):
        return
    lo, hi = along[first], along[last] + 1  # a run's corners along its line
    start, end = (lo, hi) if step > 0 else (hi, lo)
    for k, a, b in zip(line[first].tolist(), start.tolist(), end.tolist(), strict=True):
        p, q = ((k, a), (k, b)) if axis == 1 else ((a, k), (b, k))
        nxt.setdefault(p, []).append(q)


def _walk(nxt: dict[tuple[int, int], list[tuple[int, int]]]) -> Array:
    """One closed loop of edges, removed from ``nxt``."""
    start = next(iter(nxt))
    points = [start]
    here, came = start, None
    while True:
        options = nxt[here]
        if len(options) > 1 and came is not None:
            dx, dy = here[0] - came[0], here[1] - came[1]
            # The left turn first: (-dy, dx) is the incoming direction turned left.
            options.sort(key=lambda p: (p[0] - here[0]) * -dy + (p[1] - here[1]) * dx, reverse=True)
        going = options.pop(0)
        if not options:
            del nxt[here]
        came, here = here, going
        if here == start:
            break
        points.append(here)
    return np.asarray(points, dtype=float)


def polygon_area(points: Array) -> float:
    """Signed area (shoelace): positive for a counter-clockwise polygon."""
    if len(points) < 3:
        return 0.0
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def polygon_centroid(points: Array) -> Array:
    """The centroid of a simple polygon's area."""
    x, y = points[:, 0], points[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    if abs(area) < 1e-12:
        return points.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


def simplify(points: Array, tolerance: float) -> Array:
    """A closed polygon with vertices dropped while it stays within ``tolerance`` (Douglas-Peucker).

    Split at a vertex sure to stay (the farthest from the mean: a corner of the convex hull)
    and the vertex farthest from it, each half simplified as an open chain.
    """
    if len(points) < 4:
        return points
    points = np.roll(
        points, -int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1))), axis=0
    )
    far = int(np.argmax(np.linalg.norm(points - points[0], axis=1)))
    closed = np.vstack([points, points[:1]])
    first = _chain(closed[: far + 1], tolerance)
    second = _chain(closed[far:], tolerance)
    return np.vstack([first[:-1], second[:-1]])


def _chain(points: Array, tolerance: float) -> Array:
    """Douglas-Peucker on an open chain, iteratively (no recursion limit on long outlines)."""
    keep = np.zeros(len(points), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(points) - 1)]
    while stack:
        a, b = stack.pop()
        if b <= a + 1:
            continue
        seg = points[b] - points[a]
        rel = points[a + 1 : b] - points[a]
        norm = float(np.hypot(*seg))
        if norm < 1e-12:
            dist = np.hypot(rel[:, 0], rel[:, 1])
        else:
            dist = np.abs(rel[:, 0] * seg[1] - rel[:, 1] * seg[0]) / norm
        k = int(np.argmax(dist))
        if dist[k] > tolerance:
            mid = a + 1 + k
            keep[mid] = True
            stack += [(a, mid), (mid, b)]
    return points[keep]


def inside_polygon(points: Array, polygon: Array) -> NDArray[np.bool_]:
    """Whether each of ``points`` (n, 2) lies inside ``polygon`` (even-odd rule)."""
    inside = np.zeros(len(points), dtype=bool)
    x, y = points[:, 0], points[:, 1]
    for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        crosses = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (x < at)
    return inside


def convex_hull(points: Array) -> Array:
    """The convex hull of ``points`` (n, 2), counter-clockwise (Andrew's monotone chain)."""
    pts = np.unique(points, axis=0)
    if len(pts) < 3:
        return pts

    def half(ordered: Array) -> list[Array]:
        chain: list[Array] = []
        for p in ordered:
            while len(chain) >= 2:
                (ax, ay), (bx, by) = chain[-2], chain[-1]
                if (bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax) > 0:
                    break
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])
