"""``wallmap mapper --slam``: the poses received are odometry, the walls correct them.

Wall-landmark EKF-SLAM (``common.slam_ekf``) over the robot's pose and a window of the walls seen
lately, with their correlations; the rest of the map keeps each wall's own EKF, as without
``--slam``. Each frame: the odometry's motion since the last frame moves the pose and grows its
covariance; each wall observation is associated by maximum likelihood on the innovation
covariance, which now holds the pose's uncertainty and its correlation with the wall; a match
updates the pose and every wall of the window at once, a new wall joins the window with its
correlations to the pose that saw it. A wall seen again after a loop comes back into the window
and pulls the trajectory, and the walls seen since, back; its id stays.

The window holds the walls seen in the last ``window_frames`` frames, at most ``window_walls`` of
them; a wall that leaves it keeps its marginal in the map. Where no mapped wall is matched (a
blank stretch, a corridor seen only along its length) the pose runs on odometry alone: its
covariance grows in the directions the walls do not fix, and the mapper says so (``alone``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wallmap.common import ekf, se2, slam_ekf
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.common.se2 import Array
from wallmap.common.slam_ekf import OdometryNoise
from wallmap.services.mapper.wall import Wall
from wallmap.services.mapper.wall_map import WallMap

START_COV = np.diag([1e-6, 1e-6, 1e-8])  # the first pose defines the map frame
MOVED = 1e-4  # m or rad: a wall of the window moved this much is a change of the map


@dataclass(frozen=True)
class SlamConfig:
    """Tuning of the pose correction.

    Attributes:
        enabled: Correct the poses with the walls (``wallmap mapper --slam``); off, the poses
            are used as they come and nothing below matters.
        noise: How uncertain the odometry is per step, once calibrated.
        calibration_sd: How far off the odometry's scale (a share) and heading (rad per metre)
            may be at the start: 5 % and 3 degrees per metre.
        calibration_drift: How fast each may change, per square root of a metre driven.
        ambiguity: A match whose wall is not this much more log-likely than the next wall in
            the gate (log 20: twenty times) is ambiguous: it updates its wall, not the pose.
        end_sd: Beyond its fit, a line's direction is taken as this much (m) over its length
            less sure (one standard deviation), turned about its foot, the point (u, v) is:
            the seen piece's offset is then as much less sure times its distance from the
            foot over its length. A short line's fit is surer than its direction is (a
            corner's points, a depth camera's steps), a wall a few degrees off the path turns
            every error of its direction into one along the path (tenfold at 6 degrees), and
            a piece far ahead along a side wall says less about where that wall lies than one
            at its foot. Turned about the piece's middle instead (its direction alone less
            sure), corridors lose up to 0.13 of precision (docs/slam.md).
        min_obs: Walls seen this often (and more) steer the pose; younger ones are updated
            alone, keeping their correlations. A frame with such a match is one where walls
            fixed the pose (``fixes``); frames without are counted ``alone``.
        window_frames: A wall not seen for this many frames leaves the joint state.
        window_walls: At most this many walls in the joint state (the least recently seen
            leave first): its cost grows with their square.
    """

    enabled: bool = False
    noise: OdometryNoise = field(default_factory=OdometryNoise)
    calibration_sd: tuple[float, float] = (0.05, math.radians(3.0))
    calibration_drift: tuple[float, float] = (0.005, math.radians(0.2))
    min_obs: int = 6
    ambiguity: float = math.log(20.0)
    end_sd: float = 0.01
    window_frames: int = 300
    window_walls: int = 48


@dataclass
class PoseCorrector:
    """The joint state of the pose and a window of walls, carried from frame to frame."""

    config: SlamConfig = field(default_factory=SlamConfig)
    x: Array | None = None  # the pose, then the window's walls
    p: Array = field(default_factory=lambda: np.zeros((0, 0)))
    odom: Array | None = None  # the odometry pose of the last frame
    fixes: int = 0  # wall observations that corrected the pose
    alone: int = 0  # frames with no wall to correct the pose
    streak: int = 0  # of them, the last ones in a row
    ids: list[int] = field(default_factory=list)  # the wall id of each slot of the window
    seen: list[int] = field(default_factory=list)  # the frame each slot was last observed in
    frame: int = 0  # frames integrated

    def integrate(self, frame: Observations, odom: Pose, wall_map: WallMap) -> Pose:
        """Correct the odometry's pose of ``frame`` with its walls and map the frame from it."""
        self._predict(odom.vector)
        self.frame += 1
        depth = frame.sensor == "depth"
        fixed = 0
        for seen in frame.walls:
            obs = self._softened(seen)
            wall, ambiguous = self._associate(obs, wall_map)
            if wall is None:
                self._start(obs, wall_map, frame.stamp, depth=depth)
                continue
            steer = wall.n_obs >= self.config.min_obs and not ambiguous
            fixed += int(steer)
            self._update(wall, obs, wall_map, frame.stamp, depth=depth, steer=steer)
        self._write_back(wall_map)
        self._shrink_window()
        self.fixes += fixed
        self.alone += int(fixed == 0)
        self.streak = 0 if fixed else self.streak + 1
        x, y, yaw = (float(v) for v in self.pose)
        corrected = replace(odom, x=x, y=y, yaw=yaw, cov=self.p[:3, :3].copy(), frame="map")
        wall_map.finish_frame(frame, corrected)
        return corrected

    @property
    def pose(self) -> Array:
        """The corrected pose (x, y, yaw) now."""
        if self.x is None:
            msg = "no frame integrated yet"
            raise ValueError(msg)
        return self.x[:3]

    def _predict(self, seen: Array) -> None:
        cfg = self.config
        if self.x is None or self.odom is None:
            self.x, self.p = slam_ekf.start(seen, START_COV, cfg.calibration_sd)
        else:
            step = se2.between(self.odom, seen)
            self.x, self.p = slam_ekf.predict(
                self.x, self.p, step, cfg.noise, cfg.calibration_drift
            )
        self.odom = seen

    def _softened(self, obs: WallObservation) -> WallObservation:
        """``obs`` turned about its foot by ``end_sd`` over its length, one standard deviation."""
        length = max(float(np.linalg.norm(obs.p1 - obs.p0)), 0.05)
        extra = ekf.line_spread(obs.closest, (0.0, self.config.end_sd / length))
        return replace(obs, cov=obs.cov + extra)

    def _associate(self, obs: WallObservation, wall_map: WallMap) -> tuple[Wall | None, bool]:
        """The most likely wall within the gate, and whether another was nearly as likely.

        Likelihoods are on the innovation covariance, the pose's uncertainty in it. An ambiguous
        match still updates its wall, as the map would, but does not steer the pose: where the
        pose is unsure along a corridor, a door's jamb or a side room's wall can pass for the
        next one, and the pose would jump to agree.
        """
        assert self.x is not None
        pose, pose_cov = self.x[:3], self.p[:3, :3]
        slots = {wall_id: slot for slot, wall_id in enumerate(self.ids)}
        scores: list[tuple[float, int, Wall]] = []
        for wall in wall_map.near_observation(obs, pose):
            slot = slots.get(wall.id)
            if slot is None:
                innov = ekf.innovation(
                    wall.s, wall.p, wall.anchor, obs.closest, obs.cov, pose, pose_cov
                )
                m2, likelihood = innov.mahalanobis2, innov.log_likelihood
            else:
                joint = slam_ekf.innovation(self.x, self.p, slot, wall.anchor, obs.closest, obs.cov)
                m2, likelihood = joint.mahalanobis2, joint.log_likelihood
            if m2 <= wall_map.config.gate:
                scores.append((likelihood, -wall.id, wall))
        if not scores:
            return None, False
        scores.sort(reverse=True)
        ambiguous = len(scores) > 1 and scores[0][0] - scores[1][0] < self.config.ambiguity
        return scores[0][2], ambiguous

    def _start(self, obs: WallObservation, wall_map: WallMap, stamp: float, *, depth: bool) -> None:
        assert self.x is not None
        pose = self.x[:3].copy()
        self.x, self.p, anchor = slam_ekf.augment(self.x, self.p, obs.closest, obs.cov)
        slot = len(self.ids)
        window = slam_ekf.wall_slice(slot)
        wall = wall_map.add_wall(
            obs,
            self.x[window].copy(),
            self.p[window, window].copy(),
            anchor,
            pose,
            stamp,
            depth=depth,
        )
        self.ids.append(wall.id)
        self.seen.append(self.frame)

    def _update(
        self,
        wall: Wall,
        obs: WallObservation,
        wall_map: WallMap,
        stamp: float,
        *,
        depth: bool,
        steer: bool,
    ) -> None:
        self._joint_update(wall, obs, steer=steer)
        merges = len(wall_map.merges)
        wall_map.observed(wall, obs, self.x[:3].copy(), stamp, depth=depth)
        # A merge fused two walls outside the joint state: both leave the window (the one that
        # stays comes back, uncorrelated, when seen again).
        for gone, keep, _ in wall_map.merges[merges:]:
            self._drop([s for s, i in enumerate(self.ids) if i in (gone, keep)])

    def _joint_update(self, wall: Wall, obs: WallObservation, *, steer: bool) -> None:
        """Update the window with ``obs`` of ``wall``, bringing the wall in if it is out.

        ``steer``: the wall is settled enough (``min_obs``) to correct the pose; a younger one
        is updated alone, keeping its correlations (``slam_ekf.update_wall_only``).
        """
        assert self.x is not None
        if wall.id not in self.ids:
            self.x, self.p = slam_ekf.insert(self.x, self.p, wall.s, wall.p)
            self.ids.append(wall.id)
            self.seen.append(self.frame)
        slot = self.ids.index(wall.id)
        innov = slam_ekf.innovation(self.x, self.p, slot, wall.anchor, obs.closest, obs.cov)
        update = slam_ekf.update if steer else slam_ekf.update_wall_only
        self.x, self.p = update(self.x, self.p, innov)
        self.seen[slot] = self.frame
        window = slam_ekf.wall_slice(slot)
        wall.set_state(self.x[window].copy(), self.p[window, window].copy())

    def _write_back(self, wall_map: WallMap) -> None:
        """The window's walls as the joint state has them now, into the map."""
        assert self.x is not None
        for slot, wall_id in enumerate(self.ids):
            window = slam_ekf.wall_slice(slot)
            wall = wall_map.walls[wall_id]
            s = self.x[window]
            moved = float(np.abs(s - wall.s).max()) > MOVED
            wall.set_state(s.copy(), self.p[window, window].copy())
            if moved:
                wall_map.changed.add(wall_id)

    def _shrink_window(self) -> None:
        cfg = self.config
        old = [s for s, last in enumerate(self.seen) if self.frame - last > cfg.window_frames]
        self._drop(old)
        excess = len(self.ids) - cfg.window_walls
        if excess > 0:
            self._drop(sorted(range(len(self.ids)), key=self.seen.__getitem__)[:excess])

    def _drop(self, slots: list[int]) -> None:
        if not slots:
            return
        assert self.x is not None
        self.x, self.p = slam_ekf.remove(self.x, self.p, slots)
        self.ids = [i for s, i in enumerate(self.ids) if s not in slots]
        self.seen = [f for s, f in enumerate(self.seen) if s not in slots]

    def correction(self, stamp: float, odom_frame: str = "odom") -> Pose | None:
        """The map -> odom transform that takes the odometry's pose to the corrected one."""
        if self.x is None or self.odom is None:
            return None
        c = se2.compose(self.x[:3], se2.inverse(self.odom))
        return Pose(stamp, float(c[0]), float(c[1]), float(c[2]), frame="map", child=odom_frame)

    def to_json(self) -> dict[str, Any]:
        """What a state file keeps, so a restarted mapper goes on from here."""
        return {
            "x": None if self.x is None else self.x.tolist(),
            "p": None if self.x is None else self.p.tolist(),
            "odom": None if self.odom is None else self.odom.tolist(),
            "fixes": self.fixes,
            "alone": self.alone,
            "window": list(self.ids),  # a copy: the state file is written after the lock
            "seen": [self.frame - f for f in self.seen],
        }

    @classmethod
    def from_json(cls, data: dict[str, Any], config: SlamConfig) -> PoseCorrector:
        """The corrector a state file kept (``to_json``); ValueError says what is wrong."""
        fixes, alone = int(data["fixes"]), int(data["alone"])
        if data.get("x") is None:
            return cls(config, fixes=fixes, alone=alone)
        ids = [int(i) for i in data.get("window", [])]
        ages = [int(a) for a in data.get("seen", [0] * len(ids))]
        n = slam_ekf.ROBOT + 2 * len(ids)
        x = np.asarray(data["x"], dtype=float)
        p = np.asarray(data["p"], dtype=float)
        odom = np.asarray(data["odom"], dtype=float)
        shapes = (x.shape, p.shape, odom.shape) == ((n,), (n, n), (3,))
        if not shapes or len(ages) != len(ids):
            msg = f"the joint state must hold {n} numbers, its covariance {n}x{n}, the odometry 3"
            raise ValueError(msg)
        if not (np.isfinite(x).all() and np.isfinite(p).all() and np.isfinite(odom).all()):
            msg = "the joint state must be finite"
            raise ValueError(msg)
        return cls(config, x, p, odom, fixes, alone, ids=ids, seen=[-a for a in ages])

    def check(self, wall_map: WallMap) -> None:
        """Drop from the window the walls the map no longer has (a state saved between the two)."""
        self._drop([s for s, i in enumerate(self.ids) if i not in wall_map.walls])

    def summary(self) -> dict[str, Any]:
        """For the map reply: the pose now, its standard deviations, how often walls fixed it."""
        if self.x is None:
            return {"pose": None, "sd": None, "fixes": self.fixes, "alone": self.alone}
        sd = np.sqrt(np.clip(np.diag(self.p[:3, :3]), 0.0, None))
        return {
            "pose": [round(float(v), 6) for v in self.x[:3]],
            "calibration": {
                "scale": round(float(self.x[3]), 5),
                "heading_deg_per_m": round(math.degrees(self.x[4]), 4),
            },
            "sd": [round(float(sd[0]), 4), round(float(sd[1]), 4), round(math.degrees(sd[2]), 3)],
            "fixes": self.fixes,
            "alone": self.alone,
            "window": len(self.ids),
        }
