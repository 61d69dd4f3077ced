"""What a pose source is worth, learnt from the walls' corrections: noise, drift, jumps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallmap.common.pose_trust import JumpDetector, NoiseScale, Trust, TrustLearner

ASSUMED = Trust(noise=(0.02, math.radians(1.0)), drift=(0.001, math.radians(0.02)))
FLOOR = Trust(noise=(0.002, math.radians(0.05)), drift=(0.0002, math.radians(0.005)))


@pytest.mark.parametrize("true_deg", [0.2, 0.5, 3.0])
def test_the_heading_noise_is_learnt_from_the_corrections(true_deg: float) -> None:
    """A filter whose walls see the heading to 0.1 degrees, its source noisy by ``true_deg``."""
    rng = np.random.default_rng(2)
    learner = TrustLearner(ASSUMED, FLOOR)
    walls = math.radians(0.1) ** 2
    for _ in range(800):
        prior = learner.trust.noise[1] ** 2
        innovation = rng.normal(0.0, math.sqrt(math.radians(true_deg) ** 2 + walls))
        gain = prior / (prior + walls)
        predicted = prior - prior * walls / (prior + walls)
        learner.add(np.array([0.0, 0.0, gain * innovation]), np.array([1e-4, 1e-4, predicted]))
    assert math.degrees(learner.trust.noise[1]) == pytest.approx(true_deg, rel=0.3)


def test_white_corrections_teach_no_drift() -> None:
    rng = np.random.default_rng(3)
    learner = TrustLearner(ASSUMED, FLOOR)
    for _ in range(400):
        learner.add(rng.normal(0.0, 0.01, 3), np.full(3, 1e-4))
    assert learner.trust.drift[1] < ASSUMED.drift[1]


def test_the_observation_noise_scale_is_the_ratio_to_a_chi_square() -> None:
    rng = np.random.default_rng(4)
    scale = NoiseScale()
    for _ in range(100):
        scale.add(3.0 * rng.chisquare(2, 10) / scale.scale)  # as the scaled covariances give
    assert scale.scale == pytest.approx(3.0, rel=0.15)


def test_a_source_that_jumps_is_caught_and_one_that_jitters_is_not() -> None:
    rng = np.random.default_rng(5)
    jumps = JumpDetector()
    velocity = np.array([0.4, 0.0, 0.3])
    said = []
    for k in range(100):
        t = k / 15.0
        pose = velocity * t + rng.normal(0.0, [0.002, 0.002, math.radians(0.5)])
        if 60 <= k < 80:
            pose = pose + np.array([0.1, 0.0, math.radians(12.0)])  # a tracker's wrong solution
        said.append(jumps.add(t, pose))
    flagged = {k for k, jumped in enumerate(said) if jumped}
    # The jump in and out, and the frame after each (predicted from the jump itself).
    assert {60, 80} <= flagged <= {60, 61, 80, 81}
