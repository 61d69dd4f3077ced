"""Robot poses by time, interpolated at observation stamps, like a tf2 buffer.

Observations travel through the detector and so arrive after the pose of their stamp; but a pose
source may also lag (a SLAM node). :meth:`PoseBuffer.lookup` therefore says one of three things:
the pose (interpolated), *wait* (the stamp is newer than every pose so far), or *missing* (the
stamp falls before the buffer, or in a gap too long to interpolate across).
"""

from __future__ import annotations

import bisect
import enum
import logging
import math
from dataclasses import dataclass

from wallmap.common import se2
from wallmap.common.messages import Pose

log = logging.getLogger("wallmap.mapper")


class Lookup(enum.Enum):
    """Outcome of a lookup that found no pose."""

    WAIT = "wait"
    MISSING = "missing"


@dataclass(frozen=True)
class PoseBufferConfig:
    """Limits of the buffer.

    Attributes:
        max_age: poses older than the newest by more than this are forgotten (s).
        max_gap: longest time between two poses that is interpolated across (s).
        tolerance: how far beyond the first or last pose a stamp may be and still take it (s).
        jump_distance: a move this far (m) between consecutive poses is logged as a jump...
        jump_angle: ...and so is a turn this large (rad): a localiser may jump (REP-105), but a
            user should see it when walls come out doubled.
    """

    max_age: float = 120.0
    max_gap: float = 0.5
    tolerance: float = 0.02
    jump_distance: float = 0.5
    jump_angle: float = 0.5


def _interpolate(a: Pose, b: Pose, stamp: float) -> Pose:
    f = (stamp - a.stamp) / (b.stamp - a.stamp)
    dyaw = se2.wrap(b.yaw - a.yaw)
    nearest = a if f < 0.5 else b
    return Pose(
        stamp=stamp,
        x=a.x + f * (b.x - a.x),
        y=a.y + f * (b.y - a.y),
        yaw=se2.wrap(a.yaw + f * dyaw),
        cov=nearest.cov,
        frame=a.frame,
        child=a.child,
    )


class PoseBuffer:
    """Poses sorted by stamp. Not thread-safe: the mapper guards it with its lock."""

    def __init__(self, config: PoseBufferConfig | None = None) -> None:
        self.config = config or PoseBufferConfig()
        self._stamps: list[float] = []
        self._poses: list[Pose] = []

    def __len__(self) -> int:
        return len(self._poses)

    def add(self, pose: Pose) -> None:
        """Insert a pose; a jump back in time beyond ``max_age`` starts the buffer afresh."""
        if self._stamps and pose.stamp < self._stamps[-1] - self.config.max_age:
            log.warning(
                "pose time jumped back by %.1f s (a new run?): starting the pose buffer afresh",
                self._stamps[-1] - pose.stamp,
            )
            self._stamps.clear()
            self._poses.clear()
        i = bisect.bisect_left(self._stamps, pose.stamp)
        if i == len(self._stamps) and self._poses:
            self._warn_jump(self._poses[-1], pose)
        if i < len(self._stamps) and self._stamps[i] == pose.stamp:
            self._poses[i] = pose
        else:
            self._stamps.insert(i, pose.stamp)
            self._poses.insert(i, pose)
        cut = bisect.bisect_left(self._stamps, self._stamps[-1] - self.config.max_age)
        if cut:
            del self._stamps[:cut]
            del self._poses[:cut]

    def _warn_jump(self, last: Pose, pose: Pose) -> None:
        distance = math.hypot(pose.x - last.x, pose.y - last.y)
        turn = abs(se2.wrap(pose.yaw - last.yaw))
        if distance > self.config.jump_distance or turn > self.config.jump_angle:
            log.warning(
                "pose jumped by %.2f m and %.1f deg in %.3f s at %.3f",
                distance,
                math.degrees(turn),
                pose.stamp - last.stamp,
                pose.stamp,
            )

    def lookup(self, stamp: float) -> Pose | Lookup:
        """The pose at ``stamp``, or why there is none."""
        tol = self.config.tolerance
        if not self._stamps or stamp > self._stamps[-1] + tol:
            return Lookup.WAIT
        if stamp < self._stamps[0] - tol:
            return Lookup.MISSING
        i = bisect.bisect_left(self._stamps, stamp)
        if i == len(self._stamps):
            return self._poses[-1]
        if i == 0 or self._stamps[i] == stamp:
            return self._poses[i]
        before, after = self._poses[i - 1], self._poses[i]
        if after.stamp - before.stamp > self.config.max_gap:
            near = min((before, after), key=lambda p: abs(p.stamp - stamp))
            return near if abs(near.stamp - stamp) <= tol else Lookup.MISSING
        return _interpolate(before, after, stamp)
