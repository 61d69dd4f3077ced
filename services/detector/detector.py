"""The wall detector: one organized cloud in, the walls it sees out. Pure, no Zenoh."""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field

import numpy as np

from wallmap.common.line_fit import LineFit
from wallmap.common.messages import Frame, Observations, WallObservation
from wallmap.common.ransac import RansacConfig, RowReport, detect_lines
from wallmap.common.scan_row import (
    RowSelection,
    frame_stack,
    free_rays,
    scan_free_rays,
    to_base_xy,
    upright_points,
)

# A 2-D lidar: ~1 cm noise, constant with range; single dropped returns do not split a wall.
SCANNER = RansacConfig(noise_k=0.0, sigma_floor=0.01, inlier_min=0.03, nan_run=4, max_jump=0.3)


@dataclass(frozen=True)
class DetectorConfig:
    """Everything that tunes the detector, in one place.

    Attributes:
        rows: how the scan row is chosen from the cloud.
        ransac: the line search in a depth camera's row (noise growing with range squared).
        scan_ransac: the line search in a 2-D scanner's row: a lidar's noise is about
            constant with range.
        min_distance: walls whose line passes closer than this to the robot are refused (m):
            nothing real is that close, and (u, v) degenerates there.
        seed: seed of the RANSAC sampler, with each frame's number, so a run can be repeated
            exactly, and a frame detected again (a restarted detector) comes out the same.
    """

    rows: RowSelection = field(default_factory=RowSelection)
    ransac: RansacConfig = field(default_factory=RansacConfig)
    scan_ransac: RansacConfig = SCANNER
    min_distance: float = 0.1
    seed: int = 0


class NoiseLevel:
    """How noisy the sensor really is, relative to the assumed model, learnt from the fits.

    The inlier band, the kink test and the covariance all rest on the per-point noise. A sensor
    twice as noisy as assumed loses inliers and breaks lines apart; one quieter keeps needless
    slack. The median residual ratio of each frame's lines nudges a scale factor (an
    exponential average in log space), kept within ``LIMITS``.
    """

    RATE = 0.1
    LIMITS = (0.5, 4.0)

    def __init__(self) -> None:
        self.scale = 1.0

    def learn(self, lines: list[LineFit]) -> None:
        """Update the scale from one frame's lines."""
        ratios = [line.noise_ratio for line in lines if math.isfinite(line.noise_ratio)]
        if ratios:
            step = self.RATE * math.log(statistics.median(ratios))  # numpy's is slow on a few
            self.scale = min(max(self.scale * math.exp(step), self.LIMITS[0]), self.LIMITS[1])


class WallDetector:
    """Turns sensor frames into wall observations in the robot's base frame."""

    def __init__(self, config: DetectorConfig) -> None:
        self.config = config
        self.noise = {"depth": NoiseLevel(), "scan": NoiseLevel()}

    def detect(self, frame: Frame, report: RowReport | None = None) -> Observations:
        """All walls seen in one frame (an empty list when there are none).

        ``report``, when given, is filled with why (see ``RowReport``).
        """
        T_base_sensor = frame.T_base_sensor
        is_scanner = frame.sensor == "scan"
        stack = frame_stack(
            frame.points, T_base_sensor, self.config.rows, stacked=frame.band is not None
        )
        row = stack[0] if stack.shape[0] == 1 else upright_points(stack, T_base_sensor)
        scan = to_base_xy(row, T_base_sensor)
        # A depth camera's clutter needs telling from walls; a lidar's scan, one height only,
        # does not, and its path stays as it was: its returns are its free rays as they are
        # (the mapper draws the floor seen with them, and tests no wall against them).
        if is_scanner:
            origin, rays = scan_free_rays(scan, T_base_sensor)
        else:
            origin, rays = free_rays(stack, T_base_sensor)
        noise = self.noise[frame.sensor]
        base = self.config.scan_ransac if is_scanner else self.config.ransac
        params = base.scaled(noise.scale)
        # Sampled afresh for each frame from the seed and the frame's number: a detector that
        # restarts and takes a frame again finds exactly what the first one found.
        rng = np.random.default_rng((self.config.seed, frame.seq))
        lines = detect_lines(scan, params, rng, report)
        noise.learn(lines)
        if report is not None:
            near = sum(1 for line in lines if line.offset < self.config.min_distance)
            if near:
                report.rejected["closer than min_distance"] += near
        walls = [
            WallObservation.from_fit(line)
            for line in lines
            if line.offset >= self.config.min_distance
        ]
        return Observations(
            run=frame.run,
            seq=frame.seq,
            stamp=frame.stamp,
            frame="base_link",
            walls=walls,
            lossless=frame.lossless,
            ray_origin=origin,
            rays=rays,
            sensor=frame.sensor,
            sweep=frame.sweep,
        )
