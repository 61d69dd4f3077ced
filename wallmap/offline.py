"""The pipeline in one process, without Zenoh: for benchmarks, tuning and scripts.

It runs exactly the code the services run (the detector and the wall map), frame by frame.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common.map_consistency import place_scan
from wallmap.common.messages import Frame, Pose
from wallmap.common.scan_row import RowSelection, select_scan
from wallmap.services.detector.detector import DetectorConfig, WallDetector
from wallmap.services.mapper.pose_correction import PoseCorrector, SlamConfig
from wallmap.services.mapper.wall_map import MapperConfig, MapQuery, WallMap
from wallmap.services.odometry.tracker import OdometryConfig, PoseTracker
from wallmap.services.player.bag_contents import LASERSCAN
from wallmap.services.player.sources import SourceOptions, open_source

Array = NDArray[np.float64]


def map_bag(
    bag: Path,
    *,
    detector: DetectorConfig | None = None,
    mapper: MapperConfig | None = None,
    pose_source: str | None = None,
    odometry: OdometryConfig | None = None,
    poses: list[Pose] | None = None,
    source: SourceOptions | None = None,
    slam: SlamConfig | None = None,
) -> WallMap:
    """Map a whole bag; frames without a pose are skipped.

    Args:
        bag: The bag.
        detector: The detector's tuning.
        mapper: The mapper's tuning.
        pose_source: Where poses come from (``--pose-source``; None: the recording's default);
            ignored with ``odometry``.
        odometry: Estimate the poses from the scans instead, as ``wallmap odometry`` does, with
            the walls fed back after every frame (the service gets them twice a second).
        poses: If given, every pose used is appended to it.
        source: How to read the recording (levelling, a TUM folder's camera).
        slam: Take the poses as odometry and correct them with the walls (``mapper --slam``).
    """
    wall_detector = WallDetector(detector or DetectorConfig())
    wall_map = WallMap(mapper)
    tracker = PoseTracker(odometry) if odometry is not None else None
    corrector = PoseCorrector(slam) if slam is not None else None
    rows = wall_detector.config.rows
    source_poses = "none" if tracker is not None else pose_source
    options = dataclasses.replace(source or SourceOptions(), pose_source=source_poses)
    with open_source(bag, options) as recording:
        sensor = "scan" if recording.sensor_type == LASERSCAN else "depth"
        for seq, (frame, bag_pose) in enumerate(recording.frames(rows)):
            pose = bag_pose
            if tracker is not None:
                stacked = frame.band is not None
                scan = select_scan(frame.points, frame.T_base_sensor, rows, stacked)
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
                band=frame.band,
            )
            observations = wall_detector.detect(message)
            if corrector is not None:
                pose = corrector.integrate(observations, pose, wall_map)
            else:
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
    with open_source(bag, SourceOptions(pose_source="none")) as recording:
        for frame, _ in recording.frames(how):
            scan = select_scan(frame.points, frame.T_base_sensor, how, frame.band is not None)
            yield frame.stamp, scan[np.isfinite(scan).all(axis=1)]


def walls(wall_map: WallMap, min_obs: int = 1) -> list[dict[str, Any]]:
    """The served (confirmed) walls, as the map reply has them."""
    return wall_map.reply(MapQuery(min_obs=min_obs))["walls"]


def points_at_heights(
    path: Path,
    heights: tuple[float, float] = (0.9, 1.6),
    source: SourceOptions | None = None,
    every: int = 8,
) -> Array:
    """The points a depth recording saw between two heights above the floor, in the map (N x 2).

    Each frame's pixels (every ``every``-th row and column) are placed with the frame's
    levelled pose and tilted mount, as the pipeline places them: what a map of walls should
    cover (docs/real-data.md, the RGB-D section). Frames without a pose are left out.
    """
    low, high = heights
    placed = []
    with open_source(path, source) as recording:
        for frame, pose in recording.frames():
            if pose is None:
                continue
            points = frame.points[::every, ::every].reshape(-1, 3).astype(np.float64)
            points = points[np.isfinite(points).all(axis=1)]
            base = points @ frame.T_base_sensor[:3, :3].T + frame.T_base_sensor[:3, 3]
            keep = base[(base[:, 2] >= low) & (base[:, 2] <= high), :2]
            placed.append(place_scan(keep, (pose.x, pose.y, pose.yaw)))
    return np.vstack(placed) if placed else np.zeros((0, 2))
