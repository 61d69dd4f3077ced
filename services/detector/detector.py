"""The wall detector: one organized cloud in, the walls it sees out. Pure, no Zenoh."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wallmap.common.messages import Frame, Observations, WallObservation
from wallmap.common.ransac import RansacParams, detect_lines
from wallmap.services.detector.scan_row import RowSelection, select_scan


@dataclass(frozen=True)
class DetectorConfig:
    """Everything that tunes the detector, in one place.

    Attributes:
        rows: how the scan row is chosen from the cloud.
        ransac: the line search.
        min_distance: walls whose line passes closer than this to the robot are refused (m):
            nothing real is that close, and (u, v) degenerates there.
        seed: seed of the RANSAC sampler, so a run can be repeated exactly.
    """

    rows: RowSelection = field(default_factory=RowSelection)
    ransac: RansacParams = field(default_factory=RansacParams)
    min_distance: float = 0.1
    seed: int = 0


class WallDetector:
    """Turns sensor frames into wall observations in the robot's base frame."""

    def __init__(self, config: DetectorConfig) -> None:
        self.config = config
        self._rng = np.random.default_rng(config.seed)

    def detect(self, frame: Frame) -> Observations:
        """All walls seen in one frame (an empty list when there are none)."""
        scan = select_scan(frame.points, frame.base_from_sensor, self.config.rows)
        walls = [
            WallObservation(
                closest=line.closest,
                cov=line.cov,
                p0=line.p0,
                p1=line.p1,
                n_points=line.n_points,
                rms=line.rms,
            )
            for line in detect_lines(scan, self.config.ransac, self._rng)
            if line.offset >= self.config.min_distance
        ]
        return Observations(
            run=frame.run, seq=frame.seq, stamp=frame.stamp, frame="base_link", walls=walls
        )
