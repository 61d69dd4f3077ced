"""One mapped wall: its EKF state, its line's geometry, how far it was seen. Pure.

The state is the wall line's closest point ``s`` to an anchor (``common.wall_model``), with its
covariance ``p``; the line's foot point, direction and normal follow it (``set_state``), in
arrays and in plain floats for the association's hot loop. ``ends`` is the union of everything
observed (it decides which walls an observation may join); ``extent`` counts observations along
the wall, which gives the segments served between doors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from wallmap.common import wall_model
from wallmap.services.mapper.extent import Extent
from wallmap.services.mapper.map_config import MapperConfig

Array = NDArray[np.float64]


class LineFrame(NamedTuple):
    """A wall's line as plain floats, for hot loops: its foot point, direction and normal."""

    fx: float
    fy: float
    dx: float
    dy: float
    nx: float
    ny: float


@dataclass
class Wall:
    """One mapped wall: its EKF state (anchored closest point), covariance and extent.

    ``ends`` is the union of everything observed (it decides which walls an observation may
    join); ``extent`` counts observations along the wall and gives the served segments.
    """

    id: int
    s: Array
    p: Array
    anchor: Array
    ends: Array  # 2x2, map frame, on the line
    extent: Extent
    n_obs: int
    first_seen: float
    last_seen: float
    views: int
    last_view: Array  # (x, y, yaw) of the last distinct viewpoint
    depth_obs: int = 0  # observations from a depth camera (the rest from a scanner)

    def __post_init__(self) -> None:
        self._segments: tuple[tuple[int, bytes], Array] | None = None
        self.set_state(self.s, self.p)

    def set_state(self, s: Array, p: Array) -> None:
        """New EKF state; the line's foot point, direction and normal follow."""
        self.s, self.p = s, p
        self.foot = wall_model.foot(s, self.anchor)
        (fx, fy), (sx, sy) = self.foot.tolist(), s.tolist()
        r = math.hypot(sx, sy)
        nx, ny = sx / r, sy / r
        self.normal = np.array([nx, ny])
        self.direction = np.array([-ny, nx])  # wall_model.direction, in floats
        # The same as plain floats, and the extent's span along the line, for _near's hot loop.
        self.frame = LineFrame(fx, fy, -ny, nx, nx, ny)
        self.span = self.span_of(self.ends.tolist())

    def span_of(self, points: list[list[float]]) -> tuple[float, float]:
        """Lowest and highest position of map points along the wall (plain floats)."""
        fx, fy, dx, dy, _, _ = self.frame
        t = [(x - fx) * dx + (y - fy) * dy for x, y in points]
        return min(t), max(t)

    def along(self, points: Array) -> Array:
        """Positions of map points along the wall, from its foot point."""
        return (points - self.foot) @ self.direction

    def on_line(self, t: Array) -> Array:
        """Map points at positions ``t`` along the wall."""
        return self.foot + np.outer(t, self.direction)

    def extend(self, points: Array) -> None:
        """Grow ``ends`` to cover ``points`` (their projections onto the current line)."""
        self.span = self.span_of(self.ends.tolist() + points.tolist())
        fx, fy, dx, dy, _, _ = self.frame
        low, high = self.span  # on_line's sums, in floats: the same numbers
        self.ends = np.array([[fx + low * dx, fy + low * dy], [fx + high * dx, fy + high * dy]])

    def segments(self) -> Array:
        """The served segments (k x 2 x 2), from the extent counts, on the current line.

        Kept until the line or the counts change (every change to the counts comes with one to
        ``n_obs``), so replies on a large map redo only the walls that changed. Read-only.
        """
        key = (self.n_obs, self.extent.revision, self.s.tobytes())
        if self._segments is None or self._segments[0] != key:
            intervals = self.extent.intervals()
            axis = self.extent.origin + np.outer(np.ravel(intervals), self.extent.direction)
            pieces = self.on_line(self.along(axis)).reshape(-1, 2, 2)
            pieces.flags.writeable = False
            self._segments = (key, pieces)
        return self._segments[1]

    def confirmed(self, config: MapperConfig) -> bool:
        """Seen often enough, from enough viewpoints, to be served as a wall."""
        return self.n_obs >= config.confirm_obs and self.views >= config.confirm_views
