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

from wallmap.common.messages import Frame, Observations, Pose
from wallmap.common.scan_row import RowSelection, finite_scan
from wallmap.services.detector.detector import DetectorConfig, WallDetector
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.mapping import Mapping
from wallmap.services.mapper.pose_buffer import Lookup, PoseBuffer, PoseBufferConfig
from wallmap.services.mapper.pose_correction import SlamConfig
from wallmap.services.mapper.pose_judge import JudgeConfig
from wallmap.services.mapper.wall_map import WallMap
from wallmap.services.odometry.tracker import OdometryConfig, PoseTracker


@dataclass(frozen=True)
class Step:
    """What one frame did: the walls seen in it and the pose they were mapped from.

    The pose is None where the pose judge refused the frame.
    """

    observations: Observations
    pose: Pose | None


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
        judge: JudgeConfig | None = None,
        poses: PoseBufferConfig | None = None,
    ) -> None:
        self.detector = WallDetector(detector or DetectorConfig())
        self.mapping = Mapping(mapper, slam, judge, poses=PoseBuffer(poses))
        self.tracker = PoseTracker(odometry) if odometry is not None else None
        self.poses = self.mapping.poses

    @property
    def rows(self) -> RowSelection:
        """The rows the detector searches: all a source needs to decode of a frame."""
        return self.detector.config.rows

    @property
    def map(self) -> WallMap:
        """The wall map as it stands."""
        return self.mapping.map

    def add_pose(self, pose: Pose) -> None:
        """A pose of the source, as the mapper takes them from ``{prefix}/pose``."""
        self.poses.add(pose)

    def step(self, frame: Frame, pose: Pose | None = None) -> Step | None:
        """Detect the frame's walls and map them; None when the frame has no pose.

        The pose comes from the poses added so far (``add_pose``), looked up as the mapper
        looks it up (at the stamp its source's latency says); ``pose``, if given, is added
        first. With a tracker, the frame's own scan makes its pose.
        """
        if self.tracker is not None:
            pose = self._track(frame)
        if pose is not None:
            self.poses.add(pose)
        mapping = self.mapping
        source = mapping.source_pose(frame.stamp)
        if isinstance(source, Lookup):
            return None
        observations = self.detector.detect(frame)
        used = mapping.integrate(observations, source)
        if self.tracker is not None and self.tracker.config.use_walls:
            changes = mapping.changes()
            self.tracker.set_walls(changes.walls, changes.removed)
        return Step(observations, used)

    def _track(self, frame: Frame) -> Pose:
        assert self.tracker is not None
        return self.tracker.update(finite_scan(frame, self.rows), frame.stamp).pose
