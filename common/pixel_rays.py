"""Which image rows of a depth camera can see the band at all, from the rays its pixels look along.

A player reads every k-th row of each frame (``scan_row.rows_to_search``) and keeps, per column,
the points nearest a few heights of the band. On a robot's level camera below the band (most
robots: a camera at 0.3-1.2 m, the band at 1.3-2.1 m) every row below the horizon looks down, and
none of its points, at any range, rises to the band: half the rows read for nothing, and reading
them is most of a player's frame (each row a fresh stretch of the bag's pages).

A pinhole camera's pixel (column c, row r) looks along ``M @ (c, r, 1)`` in the sensor frame, for
one 3x3 matrix M (the inverse intrinsics, turned into whatever frame the cloud is given in). A
point's height over the floor is then ``h0 + t * (a @ M @ (c, r, 1))`` for its range t > 0, with
``a`` the mount's up row and ``h0`` the sensor's height, so whether a row's points climb or fall
is an affine function of (c, r). ``fit_pixel_rays`` recovers M from a few surveyed frames' own
points (no camera_info needed: a PointCloud2 carries none), and refuses a sensor that is not a
pinhole (a lens left distorted, a spinning lidar's organized cloud). ``PixelRays.reaching`` then
drops, per frame and with that frame's tilted mount, the rows none of whose rays comes within
``MARGIN`` of level towards the band: their points could never be picked, so the band's stack is
the same, to the bit, with or without them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

FIT_POINTS = 1000  # points per surveyed frame the fit uses, spread over the frame
MIN_POINTS = 200  # fewer valid points in all, and M is not fitted
MIN_SPREAD = 3  # distinct rows and columns the points must come from, at least
TOLERANCE = math.radians(0.25)  # a fitted ray this far from its point's direction: no pinhole
MARGIN = math.radians(1.0)  # a row is dropped if all its rays point this far away from the band
CLEARANCE = 1e-3  # m: the sensor must lie this far below (above) the band to drop rows


@dataclass(frozen=True)
class PixelRays:
    """A pinhole camera's rays: pixel (c, r) of a frame ``width`` wide looks along M (c, r, 1).

    Attributes:
        matrix: M, 3x3, in the frame the camera's points are given in; its sign puts the rays
            on the points' side.
        width: The width in pixels of the frames it was fitted on.
    """

    matrix: Array
    width: int
    # Per span of rows read, the unit rays at the two ends of each row: (3, 2 * rows). A frame
    # then costs one product with its mount's up row (a few microseconds, not thirty).
    _ends: dict[tuple[int, int, int], Array] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def reaching(self, rows: slice, height: int, mount: Array, band: tuple[float, float]) -> slice:
        """Of the image rows ``rows`` (of ``height``), the span whose points may reach ``band``.

        ``mount`` is the frame's T_base_sensor (its tilt included). Rows are dropped only from
        either end of the span, and at least two stay (a stack is made of two rows or more), so
        the answer is a slice read as ``rows`` is. Every row is kept when the camera is in the
        band, or when the dropped rows would not be at an end.
        """
        start, stop, step = rows.indices(height)
        count = len(range(start, stop, step))
        away = _away(float(mount[2, 3]), band)
        if count <= 2 or away == 0.0:
            return rows
        # The vertical part of a ray, ``a @ M @ (c, r, 1)``, is affine in c and its length
        # convex, so a row's rays all point away from the band when its two end rays do.
        rise = away * (mount[2, :3] @ self._unit_ends(start, stop, step))
        dropped = (rise >= math.sin(MARGIN)).reshape(2, count).all(axis=0)
        kept = np.flatnonzero(~dropped)
        if kept.size == count:
            return rows
        first, last = (int(kept[0]), int(kept[-1])) if kept.size else (0, 0)
        if kept.size and dropped[first : last + 1].any():  # a gap in the middle: keep them all
            return rows
        if last == first:  # one row left: a neighbour joins it
            first, last = (first - 1, last) if last == count - 1 else (first, last + 1)
        return slice(start + first * step, start + last * step + 1, step)

    def _unit_ends(self, start: int, stop: int, step: int) -> Array:
        ends = self._ends.get((start, stop, step))
        if ends is None:
            index = np.arange(start, stop, step, dtype=np.float64)
            pixels = np.concatenate(
                [
                    np.stack([np.full_like(index, c), index, np.ones_like(index)], axis=1)
                    for c in (0.0, float(self.width - 1))
                ]
            )
            rays = pixels @ self.matrix.T
            ends = (rays / np.linalg.norm(rays, axis=1, keepdims=True)).T
            self._ends[(start, stop, step)] = ends
        return ends


def _away(h0: float, band: tuple[float, float]) -> float:
    """-1 for a sensor below the band (rows looking down never reach it), 1 above, 0 in it."""
    low, high = band
    if h0 < low - CLEARANCE:
        return -1.0
    if h0 > high + CLEARANCE:
        return 1.0
    return 0.0


def fit_pixel_rays(grids: Sequence[tuple[NDArray[np.floating], slice]]) -> PixelRays | None:
    """The rays of the camera whose organized grids these are, or None if it is no pinhole.

    Each grid is (rows, w, 3), NaN where there is no return, with the image rows it holds
    (``slice(None)`` for a whole frame, ``slice(0, None, k)`` for every k-th row). The fit is
    the direct linear one (each point's direction parallel to M (c, r, 1)), on pixel
    coordinates centred and scaled so that it is well conditioned, and it is kept only if every
    point's direction is within ``TOLERANCE`` of its ray.
    """
    pixels, directions = _samples(grids)
    widths = {grid.shape[1] for grid, _ in grids}
    if len(widths) != 1 or len(directions) < MIN_POINTS:
        return None
    if min(len(np.unique(pixels[:, 0])), len(np.unique(pixels[:, 1]))) < MIN_SPREAD:
        return None
    centre, scale = pixels.mean(axis=0), pixels.std(axis=0).max()
    normal = np.array(
        [[1 / scale, 0, -centre[0] / scale], [0, 1 / scale, -centre[1] / scale], [0, 0, 1]]
    )
    homogeneous = np.column_stack([pixels, np.ones(len(pixels))])
    matrix = _null_matrix(homogeneous @ normal.T, directions)
    if matrix is None:
        return None
    matrix = matrix @ normal
    rays = homogeneous @ matrix.T
    if np.sum(rays * directions) < 0:  # M is found up to its sign: the rays go to the points
        matrix, rays = -matrix, -rays
    cosines = np.sum(rays * directions, axis=1) / np.linalg.norm(rays, axis=1)
    if cosines.min() < math.cos(TOLERANCE):
        return None
    return PixelRays(matrix, widths.pop())


def _samples(grids: Sequence[tuple[NDArray[np.floating], slice]]) -> tuple[Array, Array]:
    """(column, row) of about FIT_POINTS valid points a grid, and their unit directions.

    The points are taken evenly over the grid's pixels before they are tested (a survey's 24
    whole VGA frames are seven million points, 0.2 s to go over).
    """
    pixels, directions = [np.empty((0, 2))], [np.empty((0, 3))]
    for grid, rows in grids:
        if grid.ndim != 3 or grid.shape[2] != 3 or grid.size == 0 or (rows.step or 1) < 1:
            continue
        start, step = rows.start or 0, rows.step or 1
        flat = grid.reshape(-1, 3)
        tried = np.arange(0, len(flat), max(1, len(flat) // (4 * FIT_POINTS)))
        points = flat[tried].astype(np.float64)
        length = np.linalg.norm(points, axis=1)
        valid = np.flatnonzero(np.isfinite(length) & (length > 1e-6))
        valid = valid[:: max(1, len(valid) // FIT_POINTS)]
        row, column = np.divmod(tried[valid], grid.shape[1])
        pixels.append(np.column_stack([column, start + step * row]).astype(np.float64))
        directions.append(points[valid] / length[valid, None])
    return np.concatenate(pixels), np.concatenate(directions)


def _null_matrix(pixels: Array, directions: Array) -> Array | None:
    """The 3x3 M with ``directions x (M pixels) = 0`` in least squares; None if not unique.

    Each point gives the three rows of a cross product with its direction; the solution is the
    eigenvector of the smallest eigenvalue, unique when the next one is well clear of it.
    """
    n = len(pixels)
    x, y, z = directions.T
    zero = np.zeros((n, 3))
    p = pixels
    design = np.concatenate(
        [
            np.hstack([zero, -z[:, None] * p, y[:, None] * p]),
            np.hstack([z[:, None] * p, zero, -x[:, None] * p]),
            np.hstack([-y[:, None] * p, x[:, None] * p, zero]),
        ]
    )
    values, vectors = np.linalg.eigh(design.T @ design)
    if values[1] <= 1e-9 * values[-1]:
        return None
    return vectors[:, 0].reshape(3, 3)
