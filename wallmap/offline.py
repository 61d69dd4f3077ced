"""The pipeline in one process, without Zenoh: for benchmarks, tuning and scripts.

It runs exactly the code the services run (the detector and the wall map), frame by frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wallmap.common.messages import Frame
from wallmap.services.detector.detector import DetectorConfig, WallDetector
from wallmap.services.mapper.wall_map import MapperConfig, MapQuery, WallMap
from wallmap.services.player.bag_source import LASERSCAN, BagSource


def map_bag(
    bag: Path,
    *,
    detector: DetectorConfig | None = None,
    mapper: MapperConfig | None = None,
    pose_source: str = "tf",
) -> WallMap:
    """Map a whole bag; frames without a pose are skipped."""
    wall_detector = WallDetector(detector or DetectorConfig())
    wall_map = WallMap(mapper)
    with BagSource(bag, pose_source=pose_source) as source:
        sensor = "scan" if source.sensor_type == LASERSCAN else "depth"
        for seq, (frame, pose) in enumerate(source.frames()):
            if pose is None:
                continue
            message = Frame(
                "offline",
                seq,
                frame.stamp,
                frame.frame_id,
                frame.points,
                frame.T_base_sensor,
                sensor,
            )
            observations = wall_detector.detect(message)
            wall_map.integrate(observations, pose)
    return wall_map


def walls(wall_map: WallMap, min_obs: int = 1) -> list[dict[str, Any]]:
    """The served (confirmed) walls, as the map reply has them."""
    return wall_map.reply(MapQuery(min_obs=min_obs))["walls"]
