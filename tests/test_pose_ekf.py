"""Planar poses and odometry: composition and its Jacobians against numeric differentiation."""

from __future__ import annotations

import math

import numpy as np

from wallmap.common import pose_ekf


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
