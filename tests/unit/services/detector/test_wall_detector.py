"""The detector alone, on scans of a room whose walls are known: what it reports, and why not."""

from __future__ import annotations

import math

import numpy as np

from wallmap.common.messages import Frame
from wallmap.services.detector.detector import DetectorConfig, NoiseLevel, WallDetector

HALF = (2.0, 3.0)  # a 4 m x 6 m room, the scanner at its centre


def _scan(seq: int = 0, near_wall: float | None = None, noise: float = 0.005) -> Frame:
    """A 360-beam scan of the room (and of a wall ``near_wall`` m ahead, if given)."""
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        ranges = np.minimum(HALF[0] / np.abs(c), HALF[1] / np.abs(s))
        if near_wall is not None:  # a wall across x = near_wall, 1 m wide
            ahead = np.where((c > 0) & (np.abs(near_wall * s / c) < 0.5), near_wall / c, np.inf)
            ranges = np.minimum(ranges, ahead)
    ranges += np.random.default_rng(seq).normal(0.0, noise, ranges.shape)
    points = np.stack([ranges * c, ranges * s, np.zeros_like(ranges)], axis=1)
    cloud = points[None].astype(np.float32)
    return Frame("run", seq, float(seq), "laser", cloud, np.eye(4), sensor="scan")


def _truth() -> list[np.ndarray]:
    return [np.array(p) for p in ((2.0, 0.0), (-2.0, 0.0), (0.0, 3.0), (0.0, -3.0))]


def test_a_scan_of_a_room_reports_its_four_walls_by_their_closest_points() -> None:
    found = WallDetector(DetectorConfig()).detect(_scan())
    assert len(found.walls) == 4
    for wall in found.walls:
        error = min(np.linalg.norm(np.asarray(wall.closest) - t) for t in _truth())
        assert error < 0.02, wall.closest
        assert np.all(np.linalg.eigvalsh(np.asarray(wall.cov)) > 0)
    assert found.frame == "base_link"
    assert found.rays is not None, "the free rays the mapper draws the floor with"


def test_a_wall_nearer_than_min_distance_is_refused() -> None:
    frame = _scan(near_wall=0.08)
    near = DetectorConfig(min_distance=0.05)
    assert any(
        abs(np.asarray(w.closest)[0] - 0.08) < 0.02 for w in WallDetector(near).detect(frame).walls
    )
    found = WallDetector(DetectorConfig(min_distance=0.1)).detect(frame)
    assert all(np.linalg.norm(w.closest) >= 0.1 for w in found.walls)


def test_a_frame_detected_again_comes_out_the_same() -> None:
    """Seeded by the frame's number: a restarted detector finds what the first one found."""
    first = WallDetector(DetectorConfig()).detect(_scan(seq=7))
    again = WallDetector(DetectorConfig()).detect(_scan(seq=7))
    assert np.array_equal([w.closest for w in first.walls], [w.closest for w in again.walls])


def test_the_noise_level_follows_the_fits_within_its_limits() -> None:
    """Each frame's fits report their residuals over the noise assumed (scaled): a sensor twice
    as noisy as assumed brings the scale to 2; one far quieter stops at the lower limit."""
    level = NoiseLevel()
    for _ in range(200):
        level.learn([_Fit(2.0 / level.scale) for _ in range(5)])
    assert math.isclose(level.scale, 2.0, rel_tol=0.02)
    for _ in range(500):
        level.learn([_Fit(0.01 / level.scale) for _ in range(5)])
    assert level.scale == NoiseLevel.LIMITS[0]
    before = level.scale
    level.learn([])
    assert level.scale == before, "a frame with no line says nothing"


class _Fit:
    """A line fit as ``NoiseLevel`` reads one: its residuals over the noise assumed."""

    def __init__(self, ratio: float) -> None:
        self.noise_ratio = ratio
