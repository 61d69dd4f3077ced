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
from dataclasses import dataclass, replace

import numpy as np

from wallmap.common import se2
from wallmap.common.messages import Pose
from wallmap.common.se2 import Array

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
        tolerance: how far before the first pose a stamp may be and still take it (s), and
            how far past the newest it may be carried on once it has waited (``Mapping``):
            at once, the pose it takes would depend on whether the next had come yet.
        jump_distance: a move this far (m) between consecutive poses is logged as a jump...
        jump_angle: ...and so is a turn this large (rad): a localiser may jump (REP-105), but a
            user should see it when walls come out doubled.
    """

    max_age: float = 120.0
    max_gap: float = 1.0
    tolerance: float = 0.02
    jump_distance: float = 0.5
    jump_angle: float = 0.5


@dataclass(frozen=True)
class SourcePose:
    """The source's pose at a stamp, as the pose judge needs it.

    Attributes:
        pose: The pose, interpolated (or extrapolated a little) at the stamp.
        velocity: The source's velocity there (x, y, yaw per second, map frame), from the poses
            either side: a late source's error is this velocity times its latency.
        gap: Seconds between the two poses it was interpolated between (0 at a pose): over a
            tracker's dropout the interpolated pose is a guess, and is judged as one.
    """

    pose: Pose
    velocity: Array
    gap: float


def _velocity(a: Pose, b: Pose) -> Array:
    dt = b.stamp - a.stamp
    if dt <= 0:
        return np.zeros(3)
    return np.array([(b.x - a.x) / dt, (b.y - a.y) / dt, se2.wrap(b.yaw - a.yaw) / dt])


class PoseBuffer:
    """Poses sorted by stamp. Not thread-safe: the mapper guards it with its lock."""

    def __init__(self, config: PoseBufferConfig | None = None) -> None:
        self.config = config or PoseBufferConfig()
        self._stamps: list[float] = []
        self._poses: list[Pose] = []
        self._yaws: list[float] = []  # the poses' headings, for ``headings`` to read at once

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
            self._yaws.clear()
        i = bisect.bisect_left(self._stamps, pose.stamp)
        if i == len(self._stamps) and self._poses:
            self._warn_jump(self._poses[-1], pose)
        if i < len(self._stamps) and self._stamps[i] == pose.stamp:
            self._poses[i] = pose
            self._yaws[i] = pose.yaw
        else:
            self._stamps.insert(i, pose.stamp)
            self._poses.insert(i, pose)
            self._yaws.insert(i, pose.yaw)
        cut = bisect.bisect_left(self._stamps, self._stamps[-1] - self.config.max_age)
        if cut:
            del self._stamps[:cut]
            del self._poses[:cut]
            del self._yaws[:cut]

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
        """The pose at ``stamp``, or why there is none: past the newest, wait for the next."""
        tol = self.config.tolerance
        if not self._stamps or stamp > self._stamps[-1]:
            return Lookup.WAIT
        if stamp < self._stamps[0] - tol:
            return Lookup.MISSING
        i = bisect.bisect_left(self._stamps, stamp)
        if i == 0 or self._stamps[i] == stamp:
            return self._poses[i]
        before, after = self._poses[i - 1], self._poses[i]
        if after.stamp - before.stamp > self.config.max_gap:
            near = min((before, after), key=lambda p: abs(p.stamp - stamp))
            return near if abs(near.stamp - stamp) <= tol else Lookup.MISSING
        return before.towards(after, stamp)

    def sample(self, stamp: float, *, extrapolate: float = 0.0) -> SourcePose | Lookup:
        """The pose at ``stamp`` with the source's velocity there, or why there is none.

        ``extrapolate``: how far (s) beyond the newest pose the pose may be carried on at the
        newest velocity, where a latency estimate asks for a pose the source has not sent yet
        (the end of a run).
        """
        found = self.lookup(stamp)
        newest = self._stamps[-1] if self._stamps else None
        if found is Lookup.WAIT and newest is not None and stamp - newest <= extrapolate:
            last = self._poses[-1]
            velocity = self._velocity_at(len(self._poses) - 1)
            ahead = stamp - newest
            moved = replace(
                last,
                stamp=stamp,
                x=last.x + velocity[0] * ahead,
                y=last.y + velocity[1] * ahead,
                yaw=se2.wrap(last.yaw + velocity[2] * ahead),
            )
            return SourcePose(moved, velocity, ahead)
        if isinstance(found, Lookup):
            return found
        i = bisect.bisect_left(self._stamps, stamp)
        if i == 0 or self._stamps[i] == stamp:
            return SourcePose(found, self._velocity_at(i), 0.0)
        before, after = self._poses[i - 1], self._poses[i]
        return SourcePose(found, _velocity(before, after), after.stamp - before.stamp)

    def _velocity_at(self, i: int) -> Array:
        """The velocity at pose ``i``, from its neighbours."""
        low, high = max(i - 1, 0), min(i + 1, len(self._poses) - 1)
        return _velocity(self._poses[low], self._poses[high])

    def headings(self, start: float, end: float) -> tuple[Array, Array]:
        """The stamps and unwrapped headings of the poses from ``start`` to ``end``.

        One pose before ``start`` is included, none after ``end``: what a latency estimate
        reads the source's turning from, and the poses that came after ``end`` depend on when
        the source sent them.
        """
        low = max(bisect.bisect_left(self._stamps, start) - 1, 0)
        high = bisect.bisect_right(self._stamps, end)
        return np.array(self._stamps[low:high]), np.unwrap(np.array(self._yaws[low:high]))
