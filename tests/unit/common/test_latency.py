"""The pose source's latency from how the sensor's lines and the source turn."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallmap.common import se2
from wallmap.common.latency import LatencyEstimator, line_turn

# Three walls of a room as feet of perpendiculars from the origin (map frame).
FEET = np.array([[3.0, 0.4], [-0.5, 2.6], [-2.2, -0.6]])


def heading(t: np.ndarray) -> np.ndarray:
    """A robot sweeping its heading back and forth, as the generated scenes' do."""
    return 0.9 * np.sin(2 * np.pi * t / 7.0) + 0.4 * np.sin(2 * np.pi * t / 2.9)


def lines_at(yaw: float, rng: np.random.Generator, sd: float = 0.0) -> np.ndarray:
    """The closest points of the walls seen from the origin at heading ``yaw``."""
    turned = se2.rotation(yaw + rng.normal(0.0, sd)).T @ FEET.T
    return turned.T


def test_a_line_turns_against_the_robot() -> None:
    rng = np.random.default_rng(0)
    before, after = lines_at(0.2, rng), lines_at(0.25, rng)
    assert line_turn(before, after) == pytest.approx(0.05, abs=1e-9)
    assert line_turn(before, np.zeros((0, 2))) is None


def _estimate(latency: float, sd: float = 0.0, rate: float = 15.0, turning: bool = True):
    rng = np.random.default_rng(1)
    estimator = LatencyEstimator(max_latency=0.25)
    frames = np.arange(0.0, 40.0, 1.0 / rate)
    true = heading if turning else (lambda t: np.zeros_like(np.asarray(t, float)))
    for t in frames:
        estimator.add(float(t), lines_at(float(true(np.array([t]))[0]), rng, math.radians(0.05)))
    # The source is late: its pose stamped s is the robot's at s - latency.
    stamps = np.arange(-1.0, 41.0, 0.01)
    yaw = true(stamps - latency) + rng.normal(0.0, math.radians(sd), len(stamps))
    return estimator.estimate(stamps, yaw)


@pytest.mark.parametrize("latency", [-0.04, 0.0, 0.03, 0.08, 0.15])
def test_the_latency_is_found_within_5_ms(latency: float) -> None:
    found = _estimate(latency)
    assert found is not None
    assert found.latency == pytest.approx(latency, abs=0.005)
    assert 0 < found.sd < 0.01


def test_a_noisy_source_still_gives_it_within_10_ms() -> None:
    found = _estimate(0.08, sd=0.5)
    assert found is not None
    assert found.latency == pytest.approx(0.08, abs=0.01)


def test_a_robot_that_never_turns_says_nothing() -> None:
    assert _estimate(0.08, turning=False) is None
