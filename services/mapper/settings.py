"""The ``[mapper]`` section: how the mapper service runs. Plain values, no Zenoh imported."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from wallmap.common.config_file import require
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.pose_buffer import PoseBufferConfig
from wallmap.services.mapper.pose_correction import SlamConfig
from wallmap.services.mapper.pose_judge import JudgeConfig


@dataclass(frozen=True)
class MapperSettings:
    """How the mapper service runs (the map's own tuning is in ``MapperConfig``).

    Attributes:
        state: file the map is kept in across restarts, or None.
        pose_key: key expression the poses come from (default: the prefix's pose key).
        pose_format: ``wallmap`` or ``ros2:<type>`` (CDR from a ROS 2 system, see pose_input).
        pose_frames: ``PARENT>CHILD`` of the pose, for ``ros2:tf2_msgs/msg/TFMessage``.
        pose_wait: longest an observation waits for its pose (s, wall clock).
        gap_wait: longest a frame waits for earlier ones of its run (s, wall clock): missing
            frames come back from the history meanwhile, or are given up and counted as lost.
        save_every: seconds between state saves while the map changes.
        slam: take the poses as odometry and correct them with the walls (``--slam``).
        judge: how every pose is judged against the walls (``--trust-poses``, ``--pose-latency``).
        ros2_out: publish the map as ROS 2 markers and a path (``services.mapper.ros2_out``).
        map: how the map associates, merges and serves walls.
        poses: how long poses are kept and how far they are interpolated.
    """

    state: Path | None = None
    pose_key: str | None = None
    pose_format: str = "wallmap"
    pose_frames: str = "map>base_link"
    pose_wait: float = 5.0
    gap_wait: float = 10.0
    save_every: float = 2.0
    slam: SlamConfig = field(default_factory=SlamConfig)
    judge: JudgeConfig = field(default_factory=JudgeConfig)
    ros2_out: bool = True
    map: MapperConfig = field(default_factory=MapperConfig)
    poses: PoseBufferConfig = field(default_factory=PoseBufferConfig)

    def __post_init__(self) -> None:
        require(self.pose_wait >= 0, "pose_wait", ">= 0", self.pose_wait)
        require(self.gap_wait >= 0, "gap_wait", ">= 0", self.gap_wait)
        require(self.save_every > 0, "save_every", "positive", self.save_every)
        parent, _, child = self.pose_frames.partition(">")
        require(bool(parent and child), "pose_frames", "PARENT>CHILD", self.pose_frames)
