"""The pose EKF of --slam: composition, its Jacobians against numeric differentiation, updates."""

from __future__ import annotations

import math

import numpy as np

from wallmap.common import ekf, pose_ekf, wall_model


def _numeric(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    cols = []
    for i in range(len(x)):
        d = np.zeros_like(x)
        d[i] = eps
        diff = f(x + d) - f(x - d)
        diff[2:] = [pose_ekf.wrap(v) for v in diff[2:]]  # a heading difference wraps
        cols.append(diff / (2 * eps))
    return np.column_stack(cols)


def test_compose_and_between_are_inverse() -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        a = rng.uniform([-5, -5, -math.pi], [5, 5, math.pi])
        b = rng.uniform([-5, -5, -math.pi], [5, 5, math.pi])
        back = pose_ekf.compose(a, pose_ekf.between(a, b))
        assert np.allclose(back[:2], b[:2])
        assert abs(pose_ekf.wrap(back[2] - b[2])) < 1e-12


def test_compose_jacobians_match_numeric_differentiation() -> None:
    rng = np.random.default_rng(4)
    for _ in range(50):
        a = rng.uniform([-5, -5, -math.pi], [5, 5, math.pi])
        b = rng.uniform([-2, -2, -1], [2, 2, 1])
        ja, jb = pose_ekf.compose_jacobians(a, b)
        assert np.allclose(ja, _numeric(lambda v, b=b: pose_ekf.compose(v, b), a), atol=1e-6)
        assert np.allclose(jb, _numeric(lambda v, a=a: pose_ekf.compose(a, v), b), atol=1e-6)


def test_odometry_noise_grows_with_distance_and_turn() -> None:
    noise = pose_ekf.OdometryNoise()
    still = noise.covariance(np.zeros(3))
    driven = noise.covariance(np.array([1.0, 0.0, 0.0]))
    turned = noise.covariance(np.array([0.0, 0.0, 1.0]))
    assert np.all(np.diag(driven) > np.diag(still))
    assert turned[2, 2] > still[2, 2]
    assert still[0, 0] > 0, "a robot standing still is never certain"


def test_predicting_grows_the_covariance() -> None:
    x, p = np.zeros(3), np.diag([1e-4, 1e-4, 1e-6])
    for _ in range(10):
        x, p = pose_ekf.predict(x, p, np.array([0.1, 0.0, 0.05]), pose_ekf.OdometryNoise())
    assert np.linalg.det(p) > 1e-4 * 1e-4 * 1e-6
    assert np.all(np.linalg.eigvalsh(p) > 0)


def test_a_wall_fixes_the_pose_across_it_and_not_along_it() -> None:
    """A wall at x = 3 seen from a pose that drifted 0.2 m in x and y: x is pulled back, y stays."""
    true = np.array([0.0, 0.0, 0.0])
    s, anchor = np.array([3.0, 0.0]), np.zeros(2)  # the wall x = 3, seen from the origin
    s_cov = np.eye(2) * 1e-6
    z = wall_model.predict(s, anchor, true)
    r = np.eye(2) * 1e-4
    x, p = np.array([0.2, 0.2, 0.0]), np.diag([0.1, 0.1, 1e-6])
    innov = ekf.innovation(s, s_cov, anchor, z, r, x, p)
    jacobian = wall_model.jacobian_pose(s, anchor, x)
    x_new, p_new = pose_ekf.correct(x, p, innov.residual, innov.cov, jacobian)
    assert abs(x_new[0]) < 0.01, "across the wall: fixed"
    assert abs(x_new[1] - 0.2) < 1e-6, "along the wall: the drift stays"
    assert p_new[0, 0] < 0.01 * p[0, 0]
    assert math.isclose(p_new[1, 1], p[1, 1], rel_tol=1e-6), "and its uncertainty shows"
