"""The frame's pose fitted to the walls it saw: its Jacobian, and what the fit recovers."""

from __future__ import annotations

import numpy as np
import pytest
from numeric import numeric_jacobian

from wallmap.common import pose_fit, se2, wall_model

RNG = np.random.default_rng(11)


@pytest.mark.parametrize("seed", range(10))
def test_the_frame_pose_jacobian_matches_numeric_differentiation(seed: int) -> None:
    rng = np.random.default_rng(seed)
    xi, source = rng.normal(0, 0.3, pose_fit.STATE), rng.normal(0, 2.0, 3)
    _, jac = pose_fit.frame_pose(xi, source)
    numeric = numeric_jacobian(lambda q: pose_fit.frame_pose(q, source)[0], xi, angles=slice(2, 3))
    np.testing.assert_allclose(jac, numeric, atol=1e-7)


def test_the_vectorised_wall_model_is_the_wall_model() -> None:
    s, anchor, pose = RNG.uniform(-3, 3, (20, 2)), RNG.uniform(-3, 3, (20, 2)), RNG.normal(0, 1, 3)
    predicted = wall_model.predict_many(s, anchor, pose)
    by_pose = wall_model.jacobian_pose_many(s, anchor, pose)
    for i in range(20):
        np.testing.assert_allclose(predicted[i], wall_model.predict(s[i], anchor[i], pose))
        np.testing.assert_allclose(by_pose[i], wall_model.jacobian_pose(s[i], anchor[i], pose))


def _room(true_pose: np.ndarray) -> pose_fit.Pairs:
    """Four walls of a room seen exactly from ``true_pose``, known to a millimetre."""
    feet = np.array([[3.0, 0.5], [-0.4, 2.5], [-2.0, -0.3], [0.2, -1.8]])  # map-frame feet
    anchor = np.zeros((4, 2))
    s = feet - anchor
    z = wall_model.predict_many(s, anchor, true_pose)
    r = np.tile(np.eye(2) * 1e-6, (4, 1, 1))
    return pose_fit.Pairs(z, r, s, anchor, np.tile(np.eye(2) * 1e-6, (4, 1, 1)))


def test_the_walls_put_a_pose_15_degrees_off_back_where_it_was() -> None:
    true_pose = np.array([0.4, -0.2, 0.3])
    source = se2.compose(true_pose, np.array([0.12, -0.08, np.radians(15.0)]))
    cov = np.diag(np.square([0.01, 0.01, 0.01, 0.3, 0.3, 0.5]))
    fitted = pose_fit.fit(np.zeros(pose_fit.STATE), cov, source, _room(true_pose))
    np.testing.assert_allclose(fitted.pose, true_pose, atol=1e-5)
    assert np.all(fitted.m2 < 1e-4)  # the prior pulls a little: it weighs in
    assert np.all(np.linalg.eigvalsh(fitted.pose_cov) > 0)
    assert np.sqrt(fitted.pose_cov[2, 2]) < np.radians(0.1)  # four walls fix the heading


def test_without_walls_the_prior_is_the_answer() -> None:
    source = np.array([1.0, 2.0, 0.5])
    mean = np.array([0.01, 0.0, 0.002, 0.0, 0.0, 0.0])
    cov = np.eye(pose_fit.STATE) * 1e-4
    empty = pose_fit.Pairs(
        *(np.zeros((0, 2)),) * 1,
        np.zeros((0, 2, 2)),
        np.zeros((0, 2)),
        np.zeros((0, 2)),
        np.zeros((0, 2, 2)),
    )
    fitted = pose_fit.fit(mean, cov, source, empty)
    np.testing.assert_allclose(fitted.pose, pose_fit.frame_pose(mean, source)[0])
    np.testing.assert_allclose(fitted.cov, cov)


def test_a_held_state_stays_at_its_mean() -> None:
    true_pose = np.array([0.0, 0.0, 0.1])
    source = se2.compose(true_pose, np.array([0.05, 0.0, 0.02]))
    active = np.array([False, False, False, True, True, True])
    fitted = pose_fit.fit(
        np.zeros(pose_fit.STATE), np.eye(pose_fit.STATE), source, _room(true_pose), active
    )
    np.testing.assert_allclose(fitted.xi[pose_fit.OFFSET], 0.0)
    np.testing.assert_allclose(fitted.pose, true_pose, atol=1e-5)
    assert np.all(fitted.cov[pose_fit.OFFSET, :] == 0.0)
