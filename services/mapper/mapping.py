"""The mapper's estimation: a frame's observations and its source's pose in, the map updated.

The mapper service runs one ``Mapping`` behind its lock; ``services.pipeline.Pipeline`` runs one
after a ``WallDetector`` in one process. Pure: no Zenoh, no files.
"""

from __future__ import annotations

from dataclasses import replace

from wallmap.common.map_records import MapUpdate
from wallmap.common.messages import Observations, Pose
from wallmap.services.mapper import serving
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.pose_buffer import Lookup, PoseBuffer, SourcePose
from wallmap.services.mapper.pose_correction import PoseCorrector, SlamConfig
from wallmap.services.mapper.pose_judge import JudgeConfig, PoseJudge, sweep_widened
from wallmap.services.mapper.room_map import RoomMap
from wallmap.services.mapper.wall_map import WallMap

EARLY_FRAMES = 600  # frames kept for a remap, at most: the latency is known by then, or never


class Mapping:
    """Observations and their source's pose in, the map updated: the mapper's estimation.

    By default every pose is judged against the walls (``services.mapper.pose_judge``): the
    source's pose is the prior, the walls correct it, and a frame the walls contradict is
    placed where they say or refused. With ``judge.enabled`` off it is used as it comes; with
    ``slam.enabled`` it is taken as odometry and corrected jointly with the walls
    (``services.mapper.pose_correction``).
    """

    def __init__(
        self,
        config: MapperConfig | None = None,
        slam: SlamConfig | None = None,
        judge: JudgeConfig | None = None,
        wall_map: WallMap | None = None,
        corrector: PoseCorrector | None = None,
        judged: PoseJudge | None = None,
        poses: PoseBuffer | None = None,
    ) -> None:
        self.map = wall_map if wall_map is not None else WallMap(config)
        self.poses = poses if poses is not None else PoseBuffer()  # the source's, by time
        slam = slam or SlamConfig()
        judge = judge or JudgeConfig()
        if corrector is None and slam.enabled:
            corrector = PoseCorrector(slam)
        self.corrector = corrector
        if judged is None and judge.enabled and corrector is None:
            judged = PoseJudge(judge)
        self.judge = judged
        self.rooms = RoomMap()  # the floor each integrated frame saw, segmented on demand
        self.latency = judge.latency or 0.0  # of poses taken as they come
        # How far past the newest pose a frame's pose may be carried on (s).
        self.lookahead = max(judge.lookahead(), self.poses.config.tolerance)
        # The first frames' observations, kept until the latency is known (PoseJudge.settled);
        # never for a map restored from a state file: a remap would lose its walls.
        remappable = judged is not None and not judged.settled and not self.map.walls
        self._early: list[Observations] | None = [] if remappable else None

    def source_stamp(self, stamp: float) -> float:
        """The stamp of the source's pose that describes the instant ``stamp``."""
        return self.judge.source_stamp(stamp) if self.judge is not None else stamp + self.latency

    def source_pose(self, stamp: float, *, carry: bool = True) -> SourcePose | Lookup:
        """The source's pose for the instant ``stamp``, at the stamp its latency says.

        ``carry``: past the newest pose, carry it on by up to ``lookahead`` (a frame that has
        waited for the next pose long enough, or one mapped offline); else wait for the next.
        """
        ahead = self.lookahead if carry else 0.0
        return self.poses.sample(self.source_stamp(stamp), extrapolate=ahead)

    def integrate(self, observations: Observations, source: SourcePose) -> Pose | None:
        """Fold a frame's observations in; the pose they were mapped from (None: refused).

        The first frames are mapped again once the pose source's latency is first estimated,
        if it is far from the guess they were mapped with (``_remap``).
        """
        pose = self._integrate(observations, source)
        if pose is not None:
            self.rooms.add_frame(pose.vector, observations.ray_origin, observations.rays)
        if self._early is not None and self.judge is not None:
            self._early.append(observations)
            if self.judge.remap_due:
                self._remap()
            elif self.judge.settled or len(self._early) >= EARLY_FRAMES:
                self._early = None
        return pose

    def _remap(self) -> None:
        """The frames so far mapped again, from the latency now known.

        Walls started from poses off by the latency's error would otherwise hold the map
        there: every later frame is judged against them. Their ids are given up (removed in
        the next update) and the new walls' ids follow them, so an id is never reused.
        """
        if self.judge is None or self._early is None:
            return
        early, self._early = self._early, None
        old = self.map
        self.map = WallMap(old.config)
        self.map.next_id = old.next_id
        self.map.removed = set(old.walls) | old.removed
        self.judge.restart()
        for observations in early:
            source = self.source_pose(observations.stamp)
            if isinstance(source, Lookup):
                self.map.skip_frame(observations)
            else:
                self._integrate(observations, source)

    def _integrate(self, observations: Observations, source: SourcePose) -> Pose | None:
        if self.judge is not None:
            observations = self.judge.prepare(observations, source)
        else:
            observations = sweep_widened(observations, source)
        given = replace(source.pose, stamp=observations.stamp)  # the source's, at the frame
        if self.corrector is not None:
            return self.corrector.integrate(observations, given, self.map)
        if self.judge is None:
            self.map.integrate(observations, given)
            return given
        verdict = self.judge.judge(observations, source, self.map, self.poses)
        if verdict.pose is None:
            self.map.skip_frame(observations)
            return None
        self.map.integrate(observations, verdict.pose, start_walls=verdict.start_walls)
        return verdict.pose

    def changes(self) -> MapUpdate:
        """The walls changed and the ids removed since the last call (a map update)."""
        return serving.take_changes(self.map)
