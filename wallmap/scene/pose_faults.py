"""Poses as real sources give them: late, noisy, and now and then wrong.

A generated bag states every pose at the very instant of each frame and exactly right; a
motion-capture system, a SLAM or a localiser does not. These faults turn the true trajectory
into what such a source would have published, so the pose judge is tested on what it meets:

- latency: the pose stamped ``t`` describes the robot at ``t - latency``;
- noise: each pose's heading and position off by white Gaussian noise;
- glitches: stretches where the source is wrong by a fixed heading and position (a tracker that
  jumps to a wrong solution, a scan matcher that slipped), then right again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wallmap.common import se2
from wallmap.scene.trajectory import Trajectory


@dataclass(frozen=True)
class Glitch:
    """A stretch of wrong poses.

    Attributes:
        start: When it starts, seconds after the trajectory's first stamp.
        duration: How long it lasts (s).
        yaw_deg: The heading error (degrees).
        offset_m: The position error (m), along a direction drawn from the faults' seed.
    """

    start: float
    duration: float
    yaw_deg: float
    offset_m: float

    @classmethod
    def parse(cls, text: str) -> Glitch:
        """``START:DURATION:DEG:M``, e.g. ``12:3:12:0.1``; ValueError says what is wrong."""
        try:
            start, duration, yaw, offset = (float(v) for v in text.split(":"))
        except ValueError:
            msg = f"a glitch is START:DURATION:DEG:M (s, s, degrees, metres), not {text!r}"
            raise ValueError(msg) from None
        if duration <= 0 or not all(map(math.isfinite, (start, duration, yaw, offset))):
            msg = f"a glitch needs a positive duration and finite numbers, not {text!r}"
            raise ValueError(msg)
        return cls(start, duration, yaw, offset)


@dataclass(frozen=True)
class PoseFaults:
    """How a pose source errs.

    Attributes:
        latency: Seconds: the pose stamped ``t`` is the robot's at ``t - latency``.
        heading_sd_deg: White noise of each pose's heading (degrees).
        position_sd: White noise of each pose's position (m, per axis).
        glitches: Stretches of wrong poses.
        seed: Of the noise and the glitches' directions.
    """

    latency: float = 0.0
    heading_sd_deg: float = 0.0
    position_sd: float = 0.0
    glitches: tuple[Glitch, ...] = ()
    seed: int = 0

    @property
    def any(self) -> bool:
        """Whether these faults change anything."""
        return bool(self.latency or self.heading_sd_deg or self.position_sd or self.glitches)

    def apply(self, trajectory: Trajectory) -> Trajectory:
        """``trajectory`` (true poses, increasing stamps) as the faulty source gives it.

        Same stamps; each pose is the true one ``latency`` earlier (interpolated, the first
        pose held before the start), plus noise, plus the glitch under way.
        """
        stamps = trajectory.stamps
        yaw = np.unwrap(trajectory.yaw)
        then = stamps - self.latency
        x = np.interp(then, stamps, trajectory.x)
        y = np.interp(then, stamps, trajectory.y)
        heading = np.interp(then, stamps, yaw)
        rng = np.random.default_rng(self.seed)
        n = len(stamps)
        heading = heading + np.radians(self.heading_sd_deg) * rng.standard_normal(n)
        x = x + self.position_sd * rng.standard_normal(n)
        y = y + self.position_sd * rng.standard_normal(n)
        elapsed = stamps - stamps[0]
        for glitch in self.glitches:
            on = (elapsed >= glitch.start) & (elapsed < glitch.start + glitch.duration)
            direction = rng.uniform(0.0, 2.0 * math.pi)
            heading[on] += math.radians(glitch.yaw_deg)
            x[on] += glitch.offset_m * math.cos(direction)
            y[on] += glitch.offset_m * math.sin(direction)
        return Trajectory(stamps.copy(), x, y, se2.wrap(heading))
