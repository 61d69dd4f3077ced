"""A whole recording through the pipeline in one process, without Zenoh.

For benchmarks, tuning, tests and scripts: ``map_bag`` reads a recording as the player does and
runs each frame through ``services.pipeline.Pipeline``, the code the services run, on the same
configuration (``wallmap.config.Config``), so a map made here is the map ``wallmap up`` makes.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import WallRecord
from wallmap.common.messages import Frame, Pose
from wallmap.common.scan_row import RowSelection, finite_scan
from wallmap.common.se2 import transform_points
from wallmap.config import Config, with_odometry_poses
from wallmap.services.mapper import serving
from wallmap.services.mapper.room_map import RoomsReply
from wallmap.services.mapper.wall_map import WallMap
from wallmap.services.pipeline import Pipeline
from wallmap.services.player.bag_contents import LASERSCAN
from wallmap.services.player.pose_stream import stream_of
from wallmap.services.player.sources import SourceSettings, open_source

Array = NDArray[np.float64]


def pipeline_for(config: Config) -> Pipeline:
    """The pipeline a configuration makes (``up.odometry``: poses from the scans)."""
    config = with_odometry_poses(config)
    return Pipeline(
        config.detector,
        config.mapper.map,
        config.mapper.slam,
        config.odometry if config.up.odometry else None,
        config.mapper.judge,
        config.mapper.poses,
    )


def map_bag(bag: Path, config: Config | None = None, poses: list[Pose] | None = None) -> WallMap:
    """Map a whole recording as ``config`` says; frames without a pose are skipped.

    ``poses``: if given, every pose a frame was mapped from is appended to it.
    """
    return run_bag(bag, config, poses).map


def judged_source(
    bag: Path, config: Config | None = None, frames: int = 400
) -> dict[str, Any] | None:
    """What the pose judge finds of a recording's pose source over its first ``frames``.

    The map reply's ``pose_source`` (latency, noise, frames corrected and refused), as the
    mapper would have it after those frames; None when the poses are not judged.
    """
    judge = run_bag(bag, config, frames=frames).mapping.judge
    return None if judge is None else judge.summary()


def run_bag(
    bag: Path,
    config: Config | None = None,
    poses: list[Pose] | None = None,
    frames: int | None = None,
) -> Pipeline:
    """A recording (its first ``frames``, or all) through the pipeline; the pipeline after it."""
    config = config or Config()
    pipeline = pipeline_for(config)
    for seq, message in enumerate(played(bag, config, pipeline)):
        if frames is not None and seq >= frames:
            break
        step = pipeline.step(message)
        if step is not None and step.pose is not None and poses is not None:
            poses.append(step.pose)
    return pipeline


def played(bag: Path, config: Config, pipeline: Pipeline) -> Iterator[Frame]:
    """The recording's frames as the player sends them, each once its poses are in ``pipeline``.

    The source's poses up to a little past each frame, as the player streams them ahead.
    """
    source = config.player.source
    if config.up.odometry:  # the scans make the poses: the recording's are not read
        source = replace(source, pose_source="none")
    with open_source(bag, source) as recording:
        sensor = "scan" if recording.sensor_type == LASERSCAN else "depth"
        stream = stream_of(recording)
        for seq, (frame, _) in enumerate(recording.frames(pipeline.rows)):
            for pose in stream.until(frame.stamp):
                pipeline.add_pose(pose)
            yield frame.to_frame(run="offline", seq=seq, sensor=sensor)


def scan_rows(bag: Path, rows: RowSelection | None = None) -> Iterator[tuple[float, Array]]:
    """Every frame's stamp and finite scan points (N x 2, base frame).

    What the detector and the odometry see of a bag, for checking poses and maps against it.
    """
    how = rows or RowSelection()
    with open_source(bag, SourceSettings(pose_source="none")) as recording:
        for frame, _ in recording.frames(how):
            yield frame.stamp, finite_scan(frame, how)


def rooms(pipeline: Pipeline) -> RoomsReply:
    """The rooms and doors of a pipeline's map as it stands, as the mapper serves them."""
    wall_map = pipeline.map
    return pipeline.mapping.rooms.update(serving.reply(wall_map).walls, wall_map.stamp)


def walls(wall_map: WallMap, min_obs: int = 1) -> tuple[WallRecord, ...]:
    """The served (confirmed) walls, as the map reply has them."""
    return serving.reply(wall_map, MapQuery(min_obs=min_obs)).walls


def points_at_heights(
    path: Path,
    heights: tuple[float, float] = (0.9, 1.6),
    source: SourceSettings | None = None,
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
            placed.append(transform_points(keep, (pose.x, pose.y, pose.yaw)))
    return np.vstack(placed) if placed else np.zeros((0, 2))
