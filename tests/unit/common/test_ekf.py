"""The per-wall EKF against what it must do: innovations, updates and fusion of two estimates."""

from __future__ import annotations

import math

import numpy as np
from numeric import numeric_jacobian

from wallmap.common import ekf, wall_model


def _line(rho: float, theta: float) -> np.ndarray:
    return rho * np.array([math.cos(theta), math.sin(theta)])


def _closest_from(s: np.ndarray, anchor: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The closest point to ``origin`` of the line whose closest point to ``anchor`` is
    ``anchor + s``, as a vector from ``origin``: brute force, from two points of the line."""
    point = anchor + s
    direction = np.array([-s[1], s[0]]) / np.linalg.norm(s)
    rel = point - origin
    return rel - (rel @ direction) * direction


def test_innovation_scores_under_the_whole_innovation_covariance() -> None:
    s, anchor = _line(3.0, 0.4), np.array([0.5, -0.2])
    p = np.diag([1e-4, 4e-4])
    pose, pose_cov = np.array([1.0, 0.5, 0.3]), np.diag([1e-3, 1e-3, 1e-4])
    r = np.diag([4e-4, 9e-4])
    z = wall_model.predict(s, anchor, pose) + np.array([0.02, -0.01])
    found = ekf.innovation(s, p, anchor, z, r, pose, pose_cov)
    h = wall_model.jacobian_state(s, anchor, pose)
    j = wall_model.jacobian_pose(s, anchor, pose)
    cov = h @ p @ h.T + r + j @ pose_cov @ j.T
    assert np.allclose(found.cov, cov)
    assert np.allclose(found.residual, [0.02, -0.01])
    m2 = found.residual @ np.linalg.solve(cov, found.residual)
    assert math.isclose(found.mahalanobis2, m2, rel_tol=1e-9)
    log_density = -0.5 * (m2 + math.log(np.linalg.det(2 * math.pi * cov)))
    assert math.isclose(found.log_likelihood, log_density, rel_tol=1e-9)


def test_an_update_moves_the_wall_towards_the_observation_and_shrinks_its_covariance() -> None:
    s, anchor, p = _line(2.0, 1.1), np.zeros(2), np.diag([1e-2, 1e-2])
    pose, pose_cov, r = np.array([0.3, 0.1, -0.2]), np.zeros((3, 3)), np.diag([1e-4, 1e-4])
    truth = _line(2.1, 1.12)
    z = wall_model.predict(truth, anchor, pose)
    new_s, new_p = ekf.update(s, p, ekf.innovation(s, p, anchor, z, r, pose, pose_cov))
    assert np.linalg.norm(new_s - truth) < 0.1 * np.linalg.norm(s - truth)
    assert np.all(np.linalg.eigvalsh(p - new_p) > 0), "surer after it"
    assert np.allclose(new_p, new_p.T)


def test_fusing_two_estimates_of_one_wall_is_information_weighted_in_as_parameters() -> None:
    """b is the same line as a, anchored elsewhere: the fused state is a's line, and the fused
    information is the sum of a's and b's carried to a's parameters."""
    anchor_a, anchor_b = np.array([0.0, 0.0]), np.array([1.5, -0.7])
    s_a = _line(3.0, 0.9)
    s_b = _closest_from(s_a, anchor_a, anchor_b)
    p_a, p_b = np.diag([4e-4, 1e-4]), np.array([[2e-4, 5e-5], [5e-5, 3e-4]])
    s, p = ekf.fuse(s_a, p_a, anchor_a, s_b, p_b, anchor_b)
    assert np.allclose(s, s_a, atol=1e-12)
    at_a = np.array([*anchor_a, 0.0])
    j = wall_model.jacobian_state(s_b, anchor_b, at_a)
    expected = np.linalg.inv(np.linalg.inv(p_a) + np.linalg.inv(j @ p_b @ j.T))
    assert np.allclose(p, expected)
    assert np.all(np.linalg.eigvalsh(p_a - p) > 0)


def test_fusing_a_wall_with_itself_halves_its_covariance_and_lands_between_two() -> None:
    anchor = np.array([0.2, 0.3])
    s, p = _line(2.0, -0.5), np.diag([1e-4, 4e-4])
    fused_s, fused_p = ekf.fuse(s, p, anchor, s, p, anchor)
    assert np.allclose(fused_s, s)
    assert np.allclose(fused_p, p / 2)
    other = _line(2.1, -0.5)  # the same direction, 10 cm further, as sure
    between, _ = ekf.fuse(s, p, anchor, other, p, anchor)
    assert np.allclose(between, _line(2.05, -0.5))


def test_the_line_jacobian_is_the_derivative_of_the_closest_point() -> None:
    def closest(polar: np.ndarray) -> np.ndarray:
        return _line(float(polar[0]), float(polar[1]))

    polar = np.array([2.5, 0.7])
    numeric = numeric_jacobian(closest, polar)
    assert np.allclose(ekf.line_jacobian(closest(polar)), numeric, atol=1e-7)


def test_line_agreement_is_small_for_one_line_and_large_for_another() -> None:
    anchor_a, anchor_b = np.zeros(2), np.array([2.0, 1.0])
    s_a = _line(3.0, 0.3)
    p = np.diag([1e-4, 1e-4])
    floor = (0.01, math.radians(0.5))
    same = _closest_from(s_a, anchor_a, anchor_b)
    assert ekf.line_agreement(s_a, p, anchor_a, same, p, anchor_b, floor) < 1e-9
    shifted = _closest_from(_line(3.3, 0.3), anchor_a, anchor_b)
    assert ekf.line_agreement(s_a, p, anchor_a, shifted, p, anchor_b, floor) > ekf.CHI2_2DOF_999
