"""The floor the sensor saw as free: a grid counting the rays and the robot's passes over it.

Rooms are regions of seen floor bounded by walls and doors (``common.rooms``); the walls come
from the map, the floor from here. Every frame's free rays (``Observations.rays``: from the
sensor to where rays in the height band ended) cross free floor up to a little before their
end, and the robot stands on free floor wherever it is. Rays are sampled every half cell, so
a ray crossing a cell counts about twice in it; a cell is free at ``MIN_FREE`` counts, about
two rays or one pass of the robot: one stray return through a crack does not make a room.

Frames are drawn in batches (``add_frames``), their samples counted by a compiled loop where
they are made (``room_kernels.count_samples``, the cells numpy's arithmetic gives): 0.05-0.07
ms a drawn frame of the 320x240 depth bag, where making every sample in numpy and counting
them took 0.33 ms. The grid grows as the map does (a building is not known in advance) and
saturates its counts at 255. No Zenoh, so the mapper and the offline runner share it.
"""

from __future__ import annotations

import base64
import functools
import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common import compiled, se2

Array = NDArray[np.float64]

CELL = 0.1  # m
MIN_FREE = 2  # samples in a cell (about one ray, or a pass of the robot) to be free floor
RAY_SHORT = 0.2  # m: a ray's last stretch is not counted (it ends on the wall, or near it)
ROBOT_RADIUS = 0.2  # m of floor around the sensor that the robot stands on
GROW = 64  # cells added on a side when the grid grows (amortises the copies)


class FreeSpace:
    """Counts per ``cell`` over a growing grid in the map frame; cell (i, j) is x then y."""

    def __init__(self, cell: float = CELL) -> None:
        self.cell = cell
        self.origin = np.zeros(2, dtype=np.int64)  # cell index of counts[0, 0]
        self.counts = np.zeros((0, 0), dtype=np.uint8)

    def add_rays(self, pose: Array, origin: Array | None, ends: Array | None) -> None:
        """A frame's free rays, in the robot frame at ``pose`` (x, y, yaw).

        The sensor is at ``origin``; the rays end at ``ends`` (n, 2). Without rays, the floor
        the robot stands on.
        """
        self.add_frames([(pose, origin, ends)])

    def add_frames(self, frames: Sequence[tuple[Array, Array | None, Array | None]]) -> None:
        """Frames' poses and free rays (as ``add_rays``), counted together."""
        if not frames:
            return
        rays = [self._rays(np.asarray(p, dtype=float), o, e) for p, o, e in frames]
        starts = np.array([start for start, _, _ in rays], dtype=np.float64).reshape(-1, 2)
        units = np.concatenate([unit for _, unit, _ in rays]).reshape(-1, 2)
        usable = np.concatenate([length for _, _, length in rays])
        firsts = np.cumsum([0] + [len(length) for _, _, length in rays], dtype=np.int64)
        disc = compiled.plain(_disc_offsets(self.cell), np.float64)  # a copy: it is read-only
        # Two passes over the samples, none of them kept: the cells they reach (the grid grows
        # to hold them), then their counts. 0.05-0.07 ms a drawn depth frame; 0.2 when the
        # cells were made in one pass and counted by numpy, 0.33 when numpy made the samples.
        sampled = (starts, units, usable, firsts, disc, 0.5 * self.cell, self.cell)
        kernels = compiled.room_kernels()
        low, high = kernels.sample_bounds(sampled)
        self._cover(low, high)
        kernels.count_samples(self.counts, self.origin, sampled)

    def add_robot(self, position: Array) -> None:
        """The floor the robot stands on at ``position`` (x, y)."""
        self.add_points(self._disc(np.asarray(position, dtype=float)))

    def _rays(
        self, pose: Array, origin: Array | None, ends: Array | None
    ) -> tuple[Array, Array, Array]:
        """Where the sensor is, and the unit direction and usable length of each ray.

        A ray is sampled every half cell short of its end (``RAY_SHORT``); one too short for
        that, and a frame without rays, leaves the robot's disc around the sensor only.
        """
        rot = se2.rotation(float(pose[2]))
        start = pose[:2] + (rot @ np.asarray(origin, dtype=float) if origin is not None else 0.0)
        none = (start, np.empty((0, 2)), np.empty(0))
        if ends is None or not len(ends):
            return none
        rays = pose[:2] + np.asarray(ends, dtype=float).reshape(-1, 2) @ rot.T - start
        length = np.hypot(rays[:, 0], rays[:, 1])
        usable = length - RAY_SHORT
        keep = usable > 0
        if not keep.any():
            return none
        return start, rays[keep] / length[keep][:, None], usable[keep]

    def _disc(self, centre: Array) -> Array:
        return centre + _disc_offsets(self.cell)

    def add_points(self, points: Array) -> None:
        """One count per point (n, 2) in the cell it falls in, saturating at 255."""
        if not len(points):
            return
        cells = np.floor(points / self.cell).astype(np.int64)
        low, high = cells.min(axis=0), cells.max(axis=0)
        self._cover(low, high)
        # Counted over the points' own box of the grid, not all of it: a frame or two at a time.
        i, j = (cells - low).T
        shape = tuple((high - low + 1).tolist())
        added = np.bincount(i * shape[1] + j, minlength=shape[0] * shape[1]).reshape(shape)
        at = low - self.origin
        box = self.counts[at[0] : at[0] + shape[0], at[1] : at[1] + shape[1]]
        box[...] = np.minimum(box + np.minimum(added, 255), 255)

    def _cover(self, low: NDArray[np.int64], high: NDArray[np.int64]) -> None:
        """Grow the grid (by ``GROW`` cells a side at least) to hold cells ``low``..``high``."""
        shape = np.array(self.counts.shape, dtype=np.int64)
        if self.counts.size and (low >= self.origin).all() and (high < self.origin + shape).all():
            return
        if not self.counts.size:
            new_low, new_high = low - GROW, high + GROW
        else:
            new_low = np.where(low < self.origin, low - GROW, self.origin)
            new_high = np.where(high >= self.origin + shape, high + GROW, self.origin + shape - 1)
        grown = np.zeros(tuple(new_high - new_low + 1), dtype=np.uint8)
        if self.counts.size:
            at = self.origin - new_low
            grown[at[0] : at[0] + shape[0], at[1] : at[1] + shape[1]] = self.counts
        self.origin, self.counts = new_low, grown

    def free(self) -> NDArray[np.bool_]:
        """Cells seen free (``MIN_FREE`` counts), over ``counts``' grid."""
        return self.counts >= MIN_FREE

    def to_json(self) -> dict[str, Any]:
        """The grid for a state file: counts compressed (a floor is mostly runs of equal counts)."""
        packed = base64.b64encode(zlib.compress(self.counts.tobytes(), 6)).decode("ascii")
        return {
            "cell": self.cell,
            "origin": self.origin.tolist(),
            "shape": list(self.counts.shape),
            "counts": packed,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> FreeSpace:
        """Inverse of ``to_json``; ValueError says what is wrong."""
        try:
            space = cls(float(data["cell"]))
            shape = tuple(int(n) for n in data["shape"])
            raw = zlib.decompress(base64.b64decode(data["counts"]))
            counts = np.frombuffer(raw, dtype=np.uint8).reshape(shape).copy()
            origin = np.asarray(data["origin"], dtype=np.int64).reshape(2)
        except (KeyError, TypeError, ValueError, zlib.error) as err:
            msg = f"free space: {err}"
            raise ValueError(msg) from err
        space.origin, space.counts = origin, counts
        return space


@functools.lru_cache(maxsize=4)
def _disc_offsets(cell: float) -> Array:
    """Points every half cell over the robot's footprint, about its centre.

    Made once per cell size: every drawn frame adds them.
    """
    span = np.arange(-ROBOT_RADIUS, ROBOT_RADIUS + 1e-9, 0.5 * cell)
    grid = np.stack(np.meshgrid(span, span), axis=-1).reshape(-1, 2)
    offsets = grid[np.hypot(grid[:, 0], grid[:, 1]) <= ROBOT_RADIUS]
    offsets.flags.writeable = False
    return offsets
