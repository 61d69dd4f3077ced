"""Where each frame stands: the levelled fixed frame, the planar pose and the tilted mount.

A source (a bag, a TUM folder) gives, per frame, the 6-DoF pose of a robot or sensor frame in
some fixed frame, and the sensor's mount on it. Before the first frame is played, a survey of a
few frames finds which way is up in the fixed frame and where its floor is (``common.level``),
and what heights the sensor sees (for the band). Then each frame's pose is levelled and split:
the planar pose goes to the mapper, the height, roll and pitch go into the frame's mount, where
the detector needs them to find the band.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from wallmap.common.level import Level, level_from_frames
from wallmap.common.messages import Pose
from wallmap.common.pixel_rays import PixelRays, fit_pixel_rays
from wallmap.common.pose3d import FORWARD_Z, forward_axis, split_planar
from wallmap.common.pose3d_batch import headings
from wallmap.common.scan_row import DEFAULT_BAND, auto_band

Array = NDArray[np.float64]
LevelMode = Literal["auto", "none"]
SURVEY_FRAMES = 24  # frames spread over the recording that the survey looks at
SURVEY_POINTS = 4000  # points per surveyed frame


@dataclass(frozen=True)
class Sample:
    """One surveyed frame: its points (sensor frame), T_fixed_sensor, the sensor frame's name.

    ``rows``: the image rows ``points`` holds (all of them, or every k-th: a live survey's).
    """

    points: NDArray[np.float32]
    T_fixed_sensor: Array
    sensor_frame: str
    rows: slice = field(default_factory=lambda: slice(None))

    def up(self) -> Array:
        """The sensor's own up axis in the fixed frame: -y of an optical frame, z of a body one."""
        rotation = self.T_fixed_sensor[:3, :3]
        return -rotation[:, 1] if forward_axis(self.sensor_frame) == FORWARD_Z else rotation[:, 2]


@dataclass(frozen=True)
class Placement:
    """How a source's frames are placed.

    Attributes:
        levelling: T_level_fixed: up onto z, the floor at z = 0.
        forward: The robot (or sensor) frame's forward axis, whose heading is the planar yaw.
        level: What the survey found (None when there was nothing to survey).
        band: The height band the sensor sees (None: unknown, the detector's default holds).
        rays: The sensor's pixel rays, so that the rows which never see the band are not read
            (None: not a pinhole camera, or nothing surveyed; every searched row is read).
    """

    levelling: Array
    forward: int
    level: Level | None = None
    band: tuple[float, float] | None = None
    rays: PixelRays | None = None

    def place(self, pose: Pose | None, mount: Array) -> tuple[Pose | None, Array]:
        """A frame's planar pose and its mount (T_base_sensor) with the pose's tilt in it.

        Args:
            pose: The 6-DoF pose of the robot (or sensor) frame in the fixed frame, or None.
            mount: T_base_sensor.
        """
        if pose is None:
            return None, mount
        x, y, yaw, tilt = split_planar(self.levelling @ pose.matrix, self.forward)
        planar = Pose(pose.stamp, x, y, yaw, pose.cov, pose.frame, pose.child)
        return planar, tilt @ mount

    def planar_each(
        self, pose_at: Callable[[float], Pose | None], stamps: Array
    ) -> list[Pose | None]:
        """The planar poses of a source's 6-DoF ones at ``stamps``, one ``place`` at a time."""
        identity = np.eye(4)
        return [self.place(pose_at(stamp), identity)[0] for stamp in stamps.tolist()]

    def planar_many(
        self, stamps: Array, matrices: Array, found: NDArray[np.bool_], frame: str, child: str
    ) -> list[Pose | None]:
        """The planar poses of (n, 4, 4) 6-DoF ones at once (``place``'s, without the tilt).

        ``found`` says which stamps have a pose; the others are None. ``frame`` and ``child``
        name the poses' frames.
        """
        levelled = self.levelling @ matrices
        yaws = headings(levelled[:, :3, :3], self.forward).tolist()
        xs, ys = levelled[:, 0, 3].tolist(), levelled[:, 1, 3].tolist()
        return [
            Pose(stamp, x, y, yaw, None, frame, child) if ok else None
            for stamp, x, y, yaw, ok in zip(
                stamps.tolist(), xs, ys, yaws, found.tolist(), strict=True
            )
        ]

    def describe(self) -> str:
        """One line for people: the level found, the band, and whether rows are left unread."""
        parts = [self.level.describe()] if self.level is not None else []
        if self.band is not None:
            parts.append(f"the sensor sees {self.band[0]:.2f}-{self.band[1]:.2f} m above the floor")
            parts.append(
                "a pinhole: the rows that cannot see the band are not read"
                if self.rays is not None
                else "no pinhole fits its points: every searched row is read"
            )
        return "; ".join(parts)


def survey(
    samples: list[Sample],
    robot_frame: str,
    *,
    mode: LevelMode = "auto",
    floor_z: float | None = None,
    seed: int = 0,
) -> Placement:
    """Level the fixed frame from some frames and find the band their sensor sees.

    Args:
        samples: A few frames spread over the recording, with their poses.
        robot_frame: The frame the poses describe (its forward axis gives the yaw).
        mode: ``auto`` finds up and the floor; ``none`` takes the fixed frame as level with its
            floor at z = 0 (or ``floor_z``).
        floor_z: The floor's height in the fixed frame (along up), overriding what is found.
        seed: For RANSAC, so a run repeats exactly.
    """
    forward = forward_axis(robot_frame)
    clouds = [_in_fixed_frame(sample) for sample in samples]
    if mode == "none" or not samples:
        levelling = np.eye(4)
        levelling[2, 3] = -(floor_z or 0.0)
        level = None
    else:
        ups = np.array([s.up() for s in samples])
        positions = np.array([s.T_fixed_sensor[:3, 3] for s in samples])
        level = level_from_frames(clouds, ups, positions, np.random.default_rng(seed))
        levelling = level.matrix(floor_z)
    band, rays = None, None
    if samples:
        heights = np.concatenate([c @ levelling[2, :3] + levelling[2, 3] for c in clouds])
        band = auto_band(heights, DEFAULT_BAND)
        rays = fit_pixel_rays([(s.points, s.rows) for s in samples])
    return Placement(levelling, forward, level, band, rays)


def _in_fixed_frame(sample: Sample) -> Array:
    """Up to SURVEY_POINTS of a frame's finite points, in the fixed frame."""
    points = sample.points.reshape(-1, 3).astype(np.float64)
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) > SURVEY_POINTS:
        points = points[:: len(points) // SURVEY_POINTS]
    transform = sample.T_fixed_sensor
    return points @ transform[:3, :3].T + transform[:3, 3]


def unlevelled(robot_frame: str) -> Placement:
    """The placement of a source without poses: nothing to level, mounts as they are."""
    return Placement(np.eye(4), forward_axis(robot_frame))
