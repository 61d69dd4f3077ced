"""The pipeline in one process, without Zenoh: for benchmarks, tuning and scripts.

It runs exactly the code the services run (the detector and the wall map), frame by frame.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common.messages import Frame, Pose
from wallmap.common.scan_row import RowSelection, select_scan
from wallmap.services.detector.detector import DetectorConfig, WallDetector
from wallmap.services.mapper.wall_map import MapperConfig, MapQuery, WallMap
from wallmap.services.odometry.tracker import OdometryConfig, PoseTracker
from wallmap.services.player.bag_source import LASERSCAN, BagSource

Array = NDArray[np.float64]


def map_bag(
    bag: Path,
    *,
    detector: DetectorConfig | None = None,
    mapper: MapperConfig | None = None,
    pose_source: str = "tf",
    odometry: OdometryConfig | None = None,
    poses: list[Pose] | None = None,
) -> WallMap:
    """Map a whole bag; frames without a pose are skipped.

    Args:
        bag: The bag.
        detector: The detector's tuning.
        mapper: The mapper's tuning.
        pose_source: Where poses come from (``--pose-source``); ignored with ``odometry``.
        odometry: Estimate the poses from the scans instead, as ``wallmap odometry`` does, with
            the walls fed back after every frame (the service gets them twice a second).
        poses: If given, every pose used is appended to it.
    """
    wall_detector = WallDetector(detector or DetectorConfig())
    wall_map = WallMap(mapper)
    tracker = PoseTracker(odometry) if odometry is not None else None
    rows = wall_detector.config.rows
    source_poses = "none" if tracker is not None else pose_source
    with BagSource(bag, pose_source=source_poses) as source:
        sensor = "scan" if source.sensor_type == LASERSCAN else "depth"
        for seq, (frame, bag_pose) in enumerate(source.frames()):
            pose = bag_pose
            if tracker is not None:
                scan = select_scan(frame.points, frame.T_base_sensor, rows)
                pose = tracker.update(scan[np.isfinite(scan).all(axis=1)], frame.stamp).pose
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
            if poses is not None:
                poses.append(pose)
            if tracker is not None and tracker.config.use_walls:
                changes = wall_map.take_changes()
                tracker.set_walls(changes["walls"], changes["removed"])
    return wall_map


def scan_rows(bag: Path, rows: RowSelection | None = None) -> Iterator[tuple[float, Array]]:
    """Every frame's stamp and finite scan points (N x 2, base frame).

    What the detector and the odometry see of a bag, for checking poses and maps against it.
    """
    how = rows or RowSelection()
    with BagSource(bag, pose_source="none") as source:
        for frame, _ in source.frames():
            scan = select_scan(frame.points, frame.T_base_sensor, how)
            yield frame.stamp, scan[np.isfinite(scan).all(axis=1)]


def walls(wall_map: WallMap, min_obs: int = 1) -> list[dict[str, Any]]:
    """The served (confirmed) walls, as the map reply has them."""
    return wall_map.reply(MapQuery(min_obs=min_obs))["walls"]
