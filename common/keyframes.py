"""Which poses a keyframe trajectory keeps so that it still says where every frame was. Pure.

The map keeps its trajectory as keyframes, not every frame's pose, so that a long run stays
small. Between two keyframes a user (or a check of the map against the scans) interpolates. Where
the poses the mapper used move smoothly, keyframes a step of travel apart interpolate to them;
where they do not (a judged pose corrected by a degree one frame and not the next), a frame
whose pose the interpolation would misplace must be a keyframe too.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from wallmap.common import se2


class Keyframe(NamedTuple):
    """A pose of the trajectory, where the robot was at ``stamp`` (s): x, y (m), yaw (rad)."""

    stamp: float
    x: float
    y: float
    yaw: float


def interpolates(
    first: Keyframe, last: Keyframe, between: Sequence[Keyframe], max_xy: float, max_yaw: float
) -> bool:
    """Whether the poses ``between`` are where interpolating from ``first`` to ``last`` puts them.

    Within ``max_xy`` (m) and ``max_yaw`` (rad) of the straight interpolation by stamp.
    """
    if not between:
        return True
    (t0, *p0), (t1, *p1) = first, last
    poses = np.asarray(between, dtype=float)
    share = ((poses[:, 0] - t0) / (t1 - t0))[:, None] if t1 > t0 else np.zeros((len(poses), 1))
    start, step = np.asarray(p0), np.asarray(p1) - np.asarray(p0)
    step[2] = se2.wrap(step[2])
    line = start + share * step
    xy = np.hypot(*(poses[:, 1:3] - line[:, :2]).T)
    yaw = np.abs(se2.wrap(poses[:, 3] - line[:, 2]))
    return bool((xy <= max_xy).all() and (yaw <= max_yaw).all())
