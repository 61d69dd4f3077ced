"""``wallmap mapper --slam``: the poses received are odometry, the walls correct them.

Each frame: the odometry's motion since the last frame moves the pose estimate and grows its
covariance (``common.pose_ekf.predict``); each wall observation that the map associates, by
maximum likelihood on the innovation covariance with the pose's uncertainty in it, with a wall
seen ``min_obs`` times or more, corrects the pose; then the frame is mapped from the corrected
pose, with its covariance. A wall seen again after a loop is associated through the grown
covariance and pulls the trajectory back; its id stays.

Where no wall is matched (a blank stretch, a corridor seen only along its length) the pose runs
on odometry alone: its covariance grows in the directions the walls do not fix, and the mapper
says so (``alone`` counted, logged once per stretch).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wallmap.common import pose_ekf, wall_model
from wallmap.common.messages import Observations, Pose
from wallmap.common.pose_ekf import Array, OdometryNoise
from wallmap.services.mapper.wall_map import WallMap

START_COV = np.diag([1e-6, 1e-6, 1e-8])  # the first pose defines the map frame


@dataclass(frozen=True)
class SlamConfig:
    """Tuning of the pose correction.

    Attributes:
        noise: How uncertain the odometry is per step.
        min_obs: Walls seen this often (and more) correct the pose; newer ones only follow it.
    """

    noise: OdometryNoise = field(default_factory=OdometryNoise)
    min_obs: int = 6


@dataclass
class PoseCorrector:
    """The pose estimate (x, y, yaw) and its covariance, carried from frame to frame."""

    config: SlamConfig = field(default_factory=SlamConfig)
    x: Array | None = None  # the corrected pose
    p: Array = field(default_factory=START_COV.copy)
    odom: Array | None = None  # the odometry pose of the last frame
    fixes: int = 0  # wall observations that corrected the pose
    alone: int = 0  # frames with no wall to correct the pose
    streak: int = 0  # of them, the last ones in a row

    def step(self, frame: Observations, odom: Pose, wall_map: WallMap) -> Pose:
        """The corrected pose of ``frame``, given the odometry's pose at its stamp."""
        seen = odom.vector
        if self.x is None or self.odom is None:
            self.x = seen.copy()
        else:
            step = pose_ekf.between(self.odom, seen)
            self.x, self.p = pose_ekf.predict(self.x, self.p, step, self.config.noise)
        self.odom = seen
        fixed = 0
        for obs in frame.walls:
            match = wall_map.match(obs, self.x, self.p, min_obs=self.config.min_obs)
            if match is None:
                continue
            wall, innov = match
            jacobian = wall_model.jacobian_pose(wall.s, wall.anchor, self.x)
            self.x, self.p = pose_ekf.correct(self.x, self.p, innov.residual, innov.cov, jacobian)
            fixed += 1
        self.fixes += fixed
        self.alone += int(fixed == 0)
        self.streak = 0 if fixed else self.streak + 1
        x, y, yaw = (float(v) for v in self.x)
        return replace(odom, x=x, y=y, yaw=yaw, cov=self.p.copy(), frame="map")

    def correction(self, stamp: float, odom_frame: str = "odom") -> Pose | None:
        """The map -> odom transform that takes the odometry's pose to the corrected one."""
        if self.x is None or self.odom is None:
            return None
        c = pose_ekf.compose(self.x, _inverse(self.odom))
        return Pose(stamp, float(c[0]), float(c[1]), float(c[2]), frame="map", child=odom_frame)

    def to_json(self) -> dict[str, Any]:
        """What a state file keeps, so a restarted mapper goes on from here."""
        return {
            "x": None if self.x is None else self.x.tolist(),
            "p": self.p.tolist(),
            "odom": None if self.odom is None else self.odom.tolist(),
            "fixes": self.fixes,
            "alone": self.alone,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any], config: SlamConfig) -> PoseCorrector:
        """The corrector a state file kept (``to_json``)."""
        p = np.asarray(data["p"], dtype=float)
        if p.shape != (3, 3) or not np.isfinite(p).all():
            msg = "the pose covariance must be 3x3 and finite"
            raise ValueError(msg)

        def vector(key: str) -> Array | None:
            value = data.get(key)
            if value is None:
                return None
            v = np.asarray(value, dtype=float)
            if v.shape != (3,) or not np.isfinite(v).all():
                msg = f"{key!r} must be 3 finite numbers"
                raise ValueError(msg)
            return v

        return cls(config, vector("x"), p, vector("odom"), int(data["fixes"]), int(data["alone"]))

    def summary(self) -> dict[str, Any]:
        """For the map reply: the pose now, its standard deviations, how often walls fixed it."""
        sd = np.sqrt(np.clip(np.diag(self.p), 0.0, None))
        return {
            "pose": None if self.x is None else [round(float(v), 6) for v in self.x],
            "sd": [round(float(sd[0]), 4), round(float(sd[1]), 4), round(math.degrees(sd[2]), 3)],
            "fixes": self.fixes,
            "alone": self.alone,
        }


def _inverse(a: Array) -> Array:
    return pose_ekf.between(a, np.zeros(3))
