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


def _turns_and_poses(latency: float, sd: float = 0.0, rate: float = 15.0, turning: bool = True):
    """An estimator given 40 s of frames, and the late source's poses from -1 to 41 s."""
    rng = np.random.default_rng(1)
    estimator = LatencyEstimator(max_latency=0.25)
    frames = np.arange(0.0, 40.0, 1.0 / rate)
    true = heading if turning else (lambda t: np.zeros_like(np.asarray(t, float)))
    for t in frames:
        estimator.add(float(t), lines_at(float(true(np.array([t]))[0]), rng, math.radians(0.05)))
    # The source is late: its pose stamped s is the robot's at s - latency.
    stamps = np.arange(-1.0, 41.0, 0.01)
    yaw = true(stamps - latency) + rng.normal(0.0, math.radians(sd), len(stamps))
    return estimator, stamps, yaw


def _estimate(latency: float, sd: float = 0.0, rate: float = 15.0, turning: bool = True):
    estimator, stamps, yaw = _turns_and_poses(latency, sd, rate, turning)
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


def test_turns_newer_than_the_poses_are_not_read() -> None:
    """Frames the source has not yet sent poses for (as in real time, the newest) wait: read
    off the poses' clamped end, they would pull the estimate towards no turn."""
    estimator, stamps, yaw = _turns_and_poses(0.08, sd=0.3)
    older = LatencyEstimator(max_latency=0.25)
    older.restore(
        {**estimator.to_json(), "turns": [t for t in estimator.to_json()["turns"] if t[1] <= 30.0]}
    )
    sent = stamps <= 30.0
    mine, theirs = (
        estimator.estimate(stamps[sent], yaw[sent]),
        older.estimate(stamps[sent], yaw[sent]),
    )
    assert mine is not None
    assert theirs is not None
    assert (mine.latency, mine.sd) == (theirs.latency, theirs.sd)
    assert mine.latency == pytest.approx(0.08, abs=0.01)


def test_turns_that_fit_two_latencies_say_neither() -> None:
    """A robot that turns back and forth with one period: its turns match the source's shifted
    by a whole period as well as unshifted, and the estimate says nothing rather than pick."""
    rng = np.random.default_rng(2)
    estimator = LatencyEstimator(max_latency=0.25)
    period = 0.2  # s: 20 ms late fits as well as 180 ms early, both within what is looked for
    for t in np.arange(0.0, 40.0, 1.0 / 30.0):
        yaw = 0.1 * math.sin(2 * math.pi * t / period)
        estimator.add(float(t), lines_at(yaw, rng, math.radians(0.05)))
    stamps = np.arange(-1.0, 41.0, 0.01)
    assert estimator.estimate(stamps, 0.1 * np.sin(2 * np.pi * (stamps - 0.02) / period)) is None
