"""Open what the player plays: a ROS 1 or ROS 2 bag, or a TUM RGB-D folder."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.placement import LevelMode
from wallmap.services.player.pose_sources import BAG_DEFAULT
from wallmap.services.player.tum_folder import (
    TUM_INTRINSICS,
    TumFolder,
    is_tum_folder,
)

FrameSource = BagSource | TumFolder


@dataclass(frozen=True)
class SourceSettings:
    """How to read a recording, whichever kind it is.

    Attributes:
        sensor_topic: The sensor topic of a bag with several (None: the only one).
        pose_source: A ``--pose-source`` spec; None for the default (``tf`` for a bag, the
            folder's ``groundtruth.txt`` for a TUM folder).
        topics: Read only these topics of a bag.
        level: ``auto`` levels a fixed frame that is not level; ``none`` takes it as it is.
        floor_z: The floor's height in the fixed frame, instead of the one found.
        intrinsics: A TUM folder's camera (fx, fy, cx, cy), pixels.
        depth_scale: A TUM folder's depth units per metre; None: what the folder says
            (``tum_folder.folder_depth_scale``).
    """

    sensor_topic: str | None = None
    pose_source: str | None = None
    topics: tuple[str, ...] | None = None
    level: LevelMode = "auto"
    floor_z: float | None = None
    intrinsics: tuple[float, float, float, float] = TUM_INTRINSICS
    depth_scale: float | None = None


def open_source(path: Path, options: SourceSettings | None = None) -> FrameSource:
    """The recording at ``path``, opened and checked; PlayerError says what is wrong."""
    how = options or SourceSettings()
    if is_tum_folder(Path(path)):
        return TumFolder(
            Path(path),
            pose_source=how.pose_source,
            intrinsics=how.intrinsics,
            depth_scale=how.depth_scale,
            level=how.level,
            floor_z=how.floor_z,
        )
    topics: Iterable[str] | None = how.topics
    return BagSource(
        Path(path),
        sensor_topic=how.sensor_topic,
        pose_source=how.pose_source or BAG_DEFAULT,
        topics=topics,
        level=how.level,
        floor_z=how.floor_z,
    )
