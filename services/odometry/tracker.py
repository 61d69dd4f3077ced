"""Where the robot is, from its own scans: scan matching, held onto the map by its walls. Pure.

Recordings without poses (a lidar or camera and nothing else) still make a map: the scan matcher
(``wallmap.common.scan_matching``) registers each scan against a local map of recent scans, in
its own odometry frame, which drifts slowly. Beyond that, the walls the mapper has already
confirmed are landmarks that do not drift: each scan is also registered against them, with the
matcher's pose as a prior, and the difference becomes the correction ``map <- odom`` applied to
the poses that follow. Where the walls say nothing (along a corridor), the prior keeps its word.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from wallmap.common import se2
from wallmap.common.codec import decode
from wallmap.common.map_records import MapUpdate, WallRecord
from wallmap.common.messages import Pose
from wallmap.common.scan_matching import (
    MatcherConfig,
    Registration,
    ScanMatcher,
    WallLine,
    register_to_walls,
)
from wallmap.common.se2 import Array

# What a malformed wall record raises on the way in (a field missing, of a wrong type or size).


@dataclass(frozen=True)
class OdometryConfig:
    """Everything that tunes the pose service, in one place.

    Attributes:
        matcher: The scan matcher's tuning (also the wall registration's cut-offs).
        initial_pose: (x, y, yaw) of the first scan in the map frame; the odometry frame starts
            there (the origin, unless the start is known).
        use_walls: Refine each pose against the walls already mapped.
        wall_min_obs: Walls seen fewer times are not used (new walls are still settling).
        min_wall_points: A wall registration matching fewer scan points is not used.
        wall_prior_sigma: Smallest standard deviation (x, y in m, yaw in rad) given to the
            matcher's pose as the walls' prior: the matcher's own covariance is that of one
            registration, far tighter than the drift the walls are there to remove.
    """

    matcher: MatcherConfig = field(default_factory=MatcherConfig)
    initial_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    use_walls: bool = True
    wall_min_obs: int = 5
    min_wall_points: int = 20
    wall_prior_sigma: tuple[float, float, float] = (0.02, 0.02, math.radians(0.5))


@dataclass(frozen=True, eq=False)
class Estimate:
    """One scan's outcome: the pose to publish and how it was reached."""

    pose: Pose
    registration: Registration
    wall_points: int  # scan points matched to mapped walls (0: walls not used)


def wall_lines(record: WallRecord) -> list[WallLine]:
    """The lines of one wall of a map reply or update: one per served segment."""
    segments = np.asarray(record.segments, dtype=float).reshape(-1, 2, 2)
    return [WallLine.from_points(a, b) for a, b in segments if float(np.linalg.norm(b - a)) > 1e-3]


class PoseTracker:
    """Scan matching in an odometry frame, corrected onto the map by the mapped walls."""

    def __init__(self, config: OdometryConfig | None = None) -> None:
        self.config = config or OdometryConfig()
        self.restart()
        self._walls: dict[int, list[WallLine]] = {}

    def restart(self) -> None:
        """Start scan matching afresh at the initial pose (a new run), keeping the walls.

        A bag played again starts where it started before, and its first scan is older than
        the last one matched: without this, no scan of the new run would be matched.
        """
        self.matcher = ScanMatcher(self.config.matcher)
        self.map_from_odom = se2.matrix(self.config.initial_pose)

    @property
    def wall_count(self) -> int:
        """Walls currently used as landmarks."""
        return len(self._walls)

    def set_walls(self, records: Iterable[WallRecord], removed: Iterable[int] = ()) -> None:
        """Take walls from a map reply or update; unsettled and tentative ones are left out."""
        for wall_id in removed:
            self._walls.pop(wall_id, None)
        for record in records:
            usable = record.n_obs >= self.config.wall_min_obs and not record.tentative
            lines = wall_lines(record) if usable else []
            if lines:
                self._walls[record.id] = lines
            else:
                self._walls.pop(record.id, None)

    def take_update(self, payload: bytes) -> None:
        """Take a ``{prefix}/map/updates`` message: the walls that changed, the ids removed.

        Raises:
            MessageError: The message, or a record in it, is malformed.
        """
        update = MapUpdate.from_map(decode(payload))
        self.set_walls(update.walls, update.removed)

    def _walls_near(self, position: Array) -> list[WallLine]:
        """Walls with a part within the matcher's range of a position."""
        reach = self.config.matcher.max_range
        near = []
        for lines in self._walls.values():
            for line in lines:
                d = line.p1 - line.p0
                t = float(np.clip((position - line.p0) @ d / (d @ d), 0.0, 1.0))
                if float(np.linalg.norm(line.p0 + t * d - position)) <= reach:
                    near.append(line)
        return near

    def update(self, points: Array, stamp: float, child: str = "base_link") -> Estimate:
        """The pose of one scan (N x 2 points in the base frame, NaN rows allowed)."""
        registration = self.matcher.update(points, stamp)
        odom_pose = se2.matrix(registration.pose)
        guess = se2.from_matrix(self.map_from_odom @ odom_pose)
        turn = se2.from_matrix(self.map_from_odom)[2]
        cov = se2.rotate_covariance(registration.cov, turn)
        matched = 0
        walls = self._walls_near(guess[:2]) if self.config.use_walls and self._walls else []
        if walls and registration.accepted:
            prior = cov + np.diag(np.square(self.config.wall_prior_sigma))
            refined, refined_cov, matched = register_to_walls(
                points, guess, prior, walls, self.config.matcher
            )
            if matched >= self.config.min_wall_points:
                refined_t = se2.matrix(refined)
                self.map_from_odom = refined_t @ np.linalg.inv(odom_pose)
                guess, cov = se2.from_matrix(refined_t), refined_cov  # yaw wrapped to (-pi, pi]
        pose = Pose(stamp, float(guess[0]), float(guess[1]), float(guess[2]), cov, "map", child)
        return Estimate(pose, registration, matched)
