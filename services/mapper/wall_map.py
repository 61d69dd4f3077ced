"""The wall map: one small EKF per wall, gated maximum-likelihood association. Pure, no Zenoh.

For each observed wall, every mapped wall whose extent lies near the observed segment is scored
by the log-likelihood of the innovation under the innovation covariance; the best one that passes
the chi-square gate takes the observation, otherwise the observation starts a new wall. The extent
check is what keeps two collinear walls in different rooms apart: on the line alone they are the
same wall.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common import ekf, wall_model
from wallmap.common.messages import Observations, Pose, WallObservation

Array = NDArray[np.float64]


def _default_pose_cov() -> Array:
    return np.diag([0.02**2, 0.02**2, np.radians(0.5) ** 2])


@dataclass(frozen=True)
class MapperConfig:
    """Everything that tunes the map.

    Attributes:
        gate: chi-square gate on the squared Mahalanobis distance of the innovation.
        max_extent_gap: an observed segment farther than this along the wall from the wall's
            extent is another wall on the same line (m).
        pose_cov: x/y/yaw covariance assumed for poses that carry none: no pose source is exact,
            and without it a wall seen a hundred times would refuse the next good observation.
        merge_angle: two walls whose lines differ by less than this angle (rad)...
        merge_offset: ...and lie closer than this (m) where their extents overlap are one wall:
            they merge, and the older id survives. 5 cm keeps the two faces of a real wall apart.
        keyframe_distance: the trajectory kept with the map has a pose every this far (m)...
        keyframe_angle: ...or every this much turn (rad).
    """

    gate: float = ekf.CHI2_2DOF_999
    max_extent_gap: float = 1.0
    pose_cov: Array = field(default_factory=_default_pose_cov)
    merge_angle: float = np.radians(2.0)
    merge_offset: float = 0.05
    keyframe_distance: float = 0.1
    keyframe_angle: float = np.radians(5.0)


@dataclass
class Wall:
    """One mapped wall: its EKF state (anchored closest point), covariance and extent."""

    id: int
    s: Array
    p: Array
    anchor: Array
    ends: Array  # 2x2, the extent's end points in the map frame, on the line
    n_obs: int
    first_seen: float
    last_seen: float

    def along(self, points: Array) -> Array:
        """Positions of map points along the wall, from its foot point."""
        return (points - wall_model.foot(self.s, self.anchor)) @ wall_model.direction(self.s)

    def extend(self, points: Array) -> None:
        """Grow the extent to cover ``points`` (their projections onto the current line)."""
        t = self.along(np.vstack([self.ends, points]))
        foot, d = wall_model.foot(self.s, self.anchor), wall_model.direction(self.s)
        self.ends = np.array([foot + t.min() * d, foot + t.max() * d])

    def to_reply(self) -> dict[str, Any]:
        """The contract's wall record, in the map frame."""
        uv, jac = wall_model.to_map_frame(self.s, self.anchor)
        t = self.along(self.ends)
        foot, d = wall_model.foot(self.s, self.anchor), wall_model.direction(self.s)
        return {
            "id": self.id,
            "u": float(uv[0]),
            "v": float(uv[1]),
            "cov": (jac @ self.p @ jac.T).tolist(),
            "p0": (foot + t.min() * d).tolist(),
            "p1": (foot + t.max() * d).tolist(),
            "n_obs": self.n_obs,
            "first_seen": self.first_seen,
            "last_seen": self.last_seen,
        }


class WallMap:
    """All walls, with the counters the map reply carries. Not thread-safe: callers lock."""

    def __init__(self, config: MapperConfig | None = None) -> None:
        self.config = config or MapperConfig()
        self.walls: dict[int, Wall] = {}
        self.next_id = 0
        self.frames = 0
        self.observations = 0
        self.stamp: float | None = None
        self.trajectory: list[tuple[float, float, float, float]] = []  # stamp, x, y, yaw
        self.merges: list[tuple[int, int, float]] = []  # (merged id, surviving id, stamp)

    def integrate(self, frame: Observations, pose: Pose) -> list[int]:
        """Fold one frame's observations in; returns the wall id each observation went to."""
        pose_vec = pose.vector
        pose_cov = pose.cov if pose.cov is not None else self.config.pose_cov
        ids = [self._integrate_one(obs, pose_vec, pose_cov, frame.stamp) for obs in frame.walls]
        self.frames += 1
        self.observations += len(ids)
        self.stamp = frame.stamp if self.stamp is None else max(self.stamp, frame.stamp)
        self._keep_keyframe(pose)
        return ids

    def _keep_keyframe(self, pose: Pose) -> None:
        if self.trajectory:
            _, x, y, yaw = self.trajectory[-1]
            moved = np.hypot(pose.x - x, pose.y - y) >= self.config.keyframe_distance
            turned = abs(np.remainder(pose.yaw - yaw + np.pi, 2 * np.pi) - np.pi)
            if not moved and turned < self.config.keyframe_angle:
                return
        self.trajectory.append((pose.stamp, pose.x, pose.y, pose.yaw))

    def _integrate_one(
        self, obs: WallObservation, pose: Array, pose_cov: Array, stamp: float
    ) -> int:
        rot = wall_model.rotation(pose[2])
        seg = np.array([pose[:2] + rot @ obs.p0, pose[:2] + rot @ obs.p1])
        best: tuple[float, Wall, ekf.Innovation] | None = None
        for wall in self._near(seg):
            innov = ekf.innovation(
                wall.s, wall.p, wall.anchor, obs.closest, obs.cov, pose, pose_cov
            )
            if innov.mahalanobis2 <= self.config.gate and (
                best is None or innov.log_likelihood > best[0]
            ):
                best = (innov.log_likelihood, wall, innov)
        if best is None:
            return self._new_wall(obs, pose, pose_cov, seg, stamp)
        _, wall, innov = best
        wall.s, wall.p = ekf.update(wall.s, wall.p, innov)
        wall.extend(seg)
        wall.n_obs += 1
        wall.last_seen = max(wall.last_seen, stamp)
        return self._merge_duplicates(wall, stamp).id

    def _merge_duplicates(self, wall: Wall, stamp: float) -> Wall:
        """Merge walls that have converged onto ``wall``'s line over a shared extent."""
        for other in self._near(wall.ends, max_gap=0.0):
            if other.id in self.walls and other is not wall and self._same_wall(wall, other):
                keep, gone = (wall, other) if wall.id < other.id else (other, wall)
                keep.s, keep.p = ekf.fuse(keep.s, keep.p, keep.anchor, gone.s, gone.p, gone.anchor)
                keep.extend(gone.ends)
                keep.n_obs += gone.n_obs
                keep.first_seen = min(keep.first_seen, gone.first_seen)
                keep.last_seen = max(keep.last_seen, gone.last_seen)
                del self.walls[gone.id]
                self.merges.append((gone.id, keep.id, stamp))
                wall = keep
        return wall

    def _same_wall(self, a: Wall, b: Wall) -> bool:
        """Lines within ``merge_angle`` and ``merge_offset`` where the extents overlap."""
        na, nb = a.s / np.linalg.norm(a.s), b.s / np.linalg.norm(b.s)
        if np.arccos(min(abs(float(na @ nb)), 1.0)) > self.config.merge_angle:
            return False
        ta, tb = a.along(a.ends), a.along(b.ends)
        middle = 0.5 * (max(ta.min(), tb.min()) + min(ta.max(), tb.max()))
        point = wall_model.foot(a.s, a.anchor) + middle * wall_model.direction(a.s)
        offset = abs(float(nb @ (point - wall_model.foot(b.s, b.anchor))))
        return offset <= self.config.merge_offset

    def _near(self, seg: Array, max_gap: float | None = None) -> list[Wall]:
        """Walls whose extent comes within ``max_gap`` (default ``max_extent_gap``) of a segment."""
        limit = self.config.max_extent_gap if max_gap is None else max_gap
        near = []
        for wall in list(self.walls.values()):
            t_obs, t_wall = wall.along(seg), wall.along(wall.ends)
            gap = max(t_obs.min() - t_wall.max(), t_wall.min() - t_obs.max())
            if gap <= limit:
                near.append(wall)
        return near

    def _new_wall(
        self, obs: WallObservation, pose: Array, pose_cov: Array, seg: Array, stamp: float
    ) -> int:
        s, p, anchor = ekf.initial_state(obs.closest, obs.cov, pose, pose_cov)
        wall = Wall(self.next_id, s, p, anchor, seg.copy(), 1, stamp, stamp)
        wall.extend(seg)  # puts the end points on the line
        self.walls[wall.id] = wall
        self.next_id += 1
        return wall.id

    def reply(self, *, min_obs: int = 1, trajectory: bool = False) -> dict[str, Any]:
        """The contract's map reply (without the schema version, which the codec adds)."""
        body: dict[str, Any] = {
            "frame": "map",
            "frames": self.frames,
            "observations": self.observations,
            "stamp": self.stamp,
            "walls": [w.to_reply() for w in self.walls.values() if w.n_obs >= min_obs],
            "merges": [list(m) for m in self.merges],
        }
        if trajectory:
            body["trajectory"] = [list(p) for p in self.trajectory]
        return body
