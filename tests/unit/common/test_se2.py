"""Planar poses: composition, inversion, frames and points, and the Jacobians of composition
against numeric differentiation."""

from __future__ import annotations

import math

import numpy as np
from numeric import numeric_jacobian

from wallmap.common import se2


def _poses(seed: int, n: int = 50) -> np.ndarray:
    return np.random.default_rng(seed).uniform([-5, -5, -math.pi], [5, 5, math.pi], (n, 3))


def test_wrap_keeps_angles_in_half_open_range_for_floats_and_arrays() -> None:
    angles = np.array([-7.0, -math.pi, 0.0, 0.5, math.pi, 3 * math.pi + 0.25])
    wrapped = se2.wrap(angles)
    assert np.all((wrapped >= -math.pi) & (wrapped < math.pi))
    assert np.allclose(np.cos(wrapped), np.cos(angles))
    assert np.allclose(np.sin(wrapped), np.sin(angles))
    assert se2.wrap(math.pi) == -math.pi
    assert [se2.wrap(float(a)) for a in angles] == wrapped.tolist()


def test_compose_and_between_are_inverse() -> None:
    for a, b in zip(_poses(3), _poses(13), strict=True):
        back = se2.compose(a, se2.between(a, b))
        assert np.allclose(back[:2], b[:2])
        assert abs(se2.wrap(back[2] - b[2])) < 1e-12


def test_inverse_undoes_a_pose() -> None:
    for a in _poses(5):
        assert np.allclose(se2.compose(a, se2.inverse(a)), 0.0, atol=1e-12)
        assert np.allclose(se2.compose(se2.inverse(a), a), 0.0, atol=1e-12)


def test_matrix_form_agrees_with_the_vector_form() -> None:
    for a, b in zip(_poses(6), _poses(16), strict=True):
        ta, tb = se2.matrix(a), se2.matrix(b)
        assert np.allclose(se2.from_matrix(ta @ tb), se2.compose(a, b))
        assert np.allclose(se2.invert_matrix(ta), np.linalg.inv(ta))
        assert np.allclose(se2.from_matrix(se2.invert_matrix(ta) @ tb), se2.between(a, b))
        assert np.allclose(se2.matrix(se2.from_matrix(ta)), ta)


def test_points_vectors_and_covariances_turn_with_the_pose() -> None:
    rng = np.random.default_rng(7)
    points = rng.normal(size=(20, 2))
    for pose in _poses(8, 10):
        t = se2.matrix(pose)
        placed = se2.transform_points(points, pose)
        assert np.allclose(placed, (t[:2, :2] @ points.T).T + t[:2, 2])
        assert np.allclose(se2.rotate_points(points, pose[2]), points @ se2.rotation(pose[2]).T)
        assert np.allclose(se2.rotate(points[0], pose[2]), se2.rotation(pose[2]) @ points[0])
        assert np.allclose(se2.unrotate(se2.rotate(points[0], pose[2]), pose[2]), points[0])
        cov = np.diag([0.04, 0.01, 0.002])
        turned = se2.rotate_covariance(cov, pose[2])
        assert np.allclose(turned[:2, :2], t[:2, :2] @ cov[:2, :2] @ t[:2, :2].T)
        assert turned[2, 2] == cov[2, 2]
    yaws = rng.uniform(-3, 3, 20)
    columns = se2.rotate(points.T, yaws)
    one_by_one = [se2.rotation(y) @ p for y, p in zip(yaws, points, strict=True)]
    assert np.allclose(columns.T, one_by_one)


def test_compose_jacobians_match_numeric_differentiation() -> None:
    rng = np.random.default_rng(4)
    for _ in range(50):
        a = rng.uniform([-5, -5, -math.pi], [5, 5, math.pi])
        b = rng.uniform([-2, -2, -1], [2, 2, 1])
        ja, jb = se2.compose_jacobians(a, b)
        wraps = slice(2, None)  # a heading difference wraps
        by_a = numeric_jacobian(lambda v, b=b: se2.compose(v, b), a, angles=wraps)
        by_b = numeric_jacobian(lambda v, a=a: se2.compose(a, v), b, angles=wraps)
        assert np.allclose(ja, by_a, atol=1e-6)
        assert np.allclose(jb, by_b, atol=1e-6)


def test_inverse_jacobian_is_the_derivative_of_inverse() -> None:
    rng = np.random.default_rng(11)
    wraps = slice(2, None)  # a heading wraps
    for _ in range(20):
        a = np.array([*rng.normal(0, 5, 2), rng.uniform(-math.pi, math.pi)])
        numeric = numeric_jacobian(se2.inverse, a, angles=wraps)
        assert np.allclose(se2.inverse_jacobian(a), numeric, atol=1e-6)
