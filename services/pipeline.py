"""The method, top to bottom: a frame and its pose in, observations and map changes out.

    frame ──► WallDetector ──observations──► Mapping ──► the wall map
                                               ▲            (each wall an EKF, association by
                                              pose           maximum likelihood; the pose
                                                             corrected by the walls with --slam)

The services run these stages apart, over Zenoh (the detector service a ``WallDetector``, the
mapper service a ``Mapping``); ``Pipeline`` runs them one after the other in one process, for
the offline runner (``wallmap.offline``), the benchmarks and the tests. Either way it is the
same code on the same configuration sections, so a map made offline is the map the services
make. Pure: no Zenoh, no files.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wallmap.common.map_records import MapUpdate
from wallmap.common.messages import Frame, Observations, Pose
from wallmap.common.scan_row import RowSelection, select_scan
from wallmap.services.detector.detector import DetectorConfig, WallDetector
from wallmap.services.mapper import serving
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.pose_correction import PoseCorrector, SlamConfig
from wallmap.services.mapper.wall_map import WallMap
from wallmap.services.odometry.tracker import OdometryConfig, PoseTracker


class Mapping:
    """Observations and their pose in, the map updated: the mapper's estimation.

    The pose is used as it comes, or (``slam.enabled``) taken as odometry and corrected with
    the walls, jointly with them (``services.mapper.pose_correction``).
    """

    def __init__(
        self,
        config: MapperConfig | None = None,
        slam: SlamConfig | None = None,
        wall_map: WallMap | None = None,
        corrector: PoseCorrector | None = None,
    ) -> None:
        self.map = wall_map if wall_map is not None else WallMap(config)
        slam = slam or SlamConfig()
        if corrector is None and slam.enabled:
            corrector = PoseCorrector(slam)
        self.corrector = corrector

    def integrate(self, observations: Observations, pose: Pose) -> Pose:
        """Fold a frame's observations in; returns the pose they were mapped from."""
        if self.corrector is not None:
            return self.corrector.integrate(observations, pose, self.map)
        self.map.integrate(observations, pose)
        return pose

    def changes(self) -> MapUpdate:
        """The walls changed and the ids removed since the last call (a map update)."""
        return serving.take_changes(self.map)


@dataclass(frozen=True)
class Step:
    """What one frame did: the walls seen in it and the pose they were mapped from."""

    observations: Observations
    pose: Pose


class Pipeline:
    """Detection, then mapping, of each frame, as the services run them.

    ``odometry``: estimate each frame's pose from its scan (as ``wallmap odometry`` does), held
    onto the walls mapped so far, instead of taking the pose given.
    """

    def __init__(
        self,
        detector: DetectorConfig | None = None,
        mapper: MapperConfig | None = None,
        slam: SlamConfig | None = None,
        odometry: OdometryConfig | None = None,
    ) -> None:
        self.detector = WallDetector(detector or DetectorConfig())
        self.mapping = Mapping(mapper, slam)
        self.tracker = PoseTracker(odometry) if odometry is not None else None

    @property
    def rows(self) -> RowSelection:
        """The rows the detector searches: all a source needs to decode of a frame."""
        return self.detector.config.rows

    @property
    def map(self) -> WallMap:
        """The wall map as it stands."""
        return self.mapping.map

    def step(self, frame: Frame, pose: Pose | None) -> Step | None:
        """Detect the frame's walls and map them; None when the frame has no pose."""
        if self.tracker is not None:
            pose = self._track(frame)
        if pose is None:
            return None
        observations = self.detector.detect(frame)
        used = self.mapping.integrate(observations, pose)
        if self.tracker is not None and self.tracker.config.use_walls:
            changes = self.mapping.changes()
            self.tracker.set_walls(changes.walls, changes.removed)
        return Step(observations, used)

    def _track(self, frame: Frame) -> Pose:
        assert self.tracker is not None
        scan = select_scan(frame.points, frame.T_base_sensor, self.rows, frame.band is not None)
        return self.tracker.update(scan[np.isfinite(scan).all(axis=1)], frame.stamp).pose
