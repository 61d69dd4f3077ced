"""The joint pose-and-walls EKF of --slam: Jacobians against numeric differentiation, and what
keeping the correlations buys (a correction reaches the walls started from the drifted pose)."""

from __future__ import annotations

import math

import numpy as np
from numeric import numeric_jacobian

from wallmap.common import se2, slam_ekf, wall_model
from wallmap.common.slam_ekf import OdometryNoise

NOISE = OdometryNoise()
DRIFT = (0.005, math.radians(0.2))


def _state(rng: np.random.Generator, walls: int = 2) -> tuple[np.ndarray, np.ndarray]:
    x = np.concatenate([rng.uniform([-3, -3, -3], [3, 3, 3]), rng.normal(0, [0.03, 0.01])])
    x = np.concatenate([x, *(rng.uniform(1, 4, 2) * rng.choice([-1, 1], 2) for _ in range(walls))])
    a = rng.normal(0, 0.05, (len(x), len(x)))
    return x, a @ a.T + 1e-6 * np.eye(len(x))


def test_odometry_noise_grows_with_distance_and_turn() -> None:
    still = NOISE.covariance(np.zeros(3))
    driven = NOISE.covariance(np.array([1.0, 0.0, 0.0]))
    turned = NOISE.covariance(np.array([0.0, 0.0, 1.0]))
    assert np.all(np.diag(driven) > np.diag(still))
    assert turned[2, 2] > still[2, 2]
    assert still[0, 0] > 0, "a robot standing still is never certain"


def test_calibrated_step_jacobian_matches_numeric_differentiation() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        step = rng.uniform([-0.2, -0.2, -0.3], [0.2, 0.2, 0.3])
        cal = rng.normal(0, [0.03, 0.02])
        numeric = numeric_jacobian(lambda c, step=step: slam_ekf.calibrated(step, c), cal)
        assert np.allclose(slam_ekf.calibrated_jacobian(step), numeric, atol=1e-7)


def test_prediction_moves_the_covariance_with_the_jacobian_of_the_motion() -> None:
    """P' = F P F^T + Q, F the Jacobian of the calibrated motion, checked numerically."""
    rng = np.random.default_rng(6)
    for _ in range(10):
        x, p = _state(rng)
        step = rng.uniform([-0.1, -0.05, -0.2], [0.1, 0.05, 0.2])

        def move(v: np.ndarray, step=step) -> np.ndarray:
            out = v.copy()
            out[:3] = se2.compose(v[:3], slam_ekf.calibrated(step, v[3:5]))
            return out

        f = numeric_jacobian(move, x)
        x_new, p_new = slam_ekf.predict(x, p, step, NOISE, DRIFT)
        assert np.allclose(x_new, move(x))
        q = p_new - f @ p @ f.T
        assert np.allclose(q[5:, :], 0.0, atol=1e-9), "the walls do not move"
        assert np.all(np.linalg.eigvalsh(q[:5, :5]) > -1e-10), "only noise is added"


def test_a_new_wall_carries_the_correlations_of_the_pose_that_saw_it() -> None:
    """augment() is the linearised map (x, z) -> (x, s(x, z)): P' = J blockdiag(P, R) J^T."""
    rng = np.random.default_rng(7)
    x, p = _state(rng, walls=1)
    z, r = np.array([2.0, -0.5]), np.diag([1e-3, 2e-3])
    x_new, p_new, anchor = slam_ekf.augment(x, p, z, r)

    def grown(v: np.ndarray) -> np.ndarray:
        pose, zz = v[:3], v[-2:]
        t, rot = pose[:2], se2.rotation(pose[2])
        n = rot @ zz / np.linalg.norm(zz)
        s = (n @ (t - anchor) + np.linalg.norm(zz)) * n  # the line, from the fixed anchor
        return np.concatenate([v[:-2], s])

    j = numeric_jacobian(grown, np.concatenate([x, z]))
    joint = np.zeros((len(x) + 2, len(x) + 2))
    joint[: len(x), : len(x)], joint[len(x) :, len(x) :] = p, r
    assert np.allclose(x_new, grown(np.concatenate([x, z])))
    assert np.allclose(p_new, j @ joint @ j.T, atol=1e-10)


def test_the_innovation_jacobian_matches_numeric_differentiation() -> None:
    rng = np.random.default_rng(8)
    x, p = _state(rng)
    anchor = np.array([0.5, -0.2])
    innov = slam_ekf.innovation(x, p, 1, anchor, np.array([1.0, 1.0]), np.eye(2) * 1e-3)
    sub = np.concatenate([x[:3], x[slam_ekf.wall_slice(1)]])
    numeric = numeric_jacobian(lambda v: wall_model.predict(v[3:], anchor, v[:3]), sub)
    assert np.allclose(innov.jacobian, numeric, atol=1e-6)


def test_walls_leave_and_come_back_with_their_marginals() -> None:
    rng = np.random.default_rng(9)
    x, p = _state(rng, walls=3)
    small_x, small_p = slam_ekf.remove(x, p, [1])
    assert np.allclose(small_x, np.delete(x, [7, 8]))
    assert np.allclose(small_p, np.delete(np.delete(p, [7, 8], 0), [7, 8], 1))
    back_x, back_p = slam_ekf.insert(small_x, small_p, x[7:9], p[7:9, 7:9])
    assert np.allclose(back_p[-2:, -2:], p[7:9, 7:9])
    assert np.allclose(back_p[-2:, :-2], 0.0), "back uncorrelated"
    assert np.allclose(back_x[-2:], x[7:9])


def test_a_wall_fixes_the_pose_across_it_and_not_along_it() -> None:
    """A wall at x = 3, known exactly, seen from a pose drifted 0.2 m: x pulled back, y stays."""
    x, p = slam_ekf.start(np.array([0.2, 0.2, 0.0]), np.diag([0.1, 0.1, 1e-6]), (0.01, 0.01))
    x, p = slam_ekf.insert(x, p, np.array([3.0, 0.0]), np.eye(2) * 1e-9)
    z = wall_model.predict(np.array([3.0, 0.0]), np.zeros(2), np.zeros(3))
    innov = slam_ekf.innovation(x, p, 0, np.zeros(2), z, np.eye(2) * 1e-4)
    x_new, p_new = slam_ekf.update(x, p, innov)
    assert abs(x_new[0]) < 0.01, "across the wall: fixed"
    assert abs(x_new[1] - 0.2) < 1e-6, "along the wall: the drift stays"
    assert p_new[0, 0] < 0.01 * p[0, 0]
    assert math.isclose(p_new[1, 1], p[1, 1], rel_tol=1e-6), "and its uncertainty shows"


def test_a_correction_of_the_pose_moves_the_walls_started_from_it() -> None:
    """The reason for the joint state: the heading drifts 3 degrees, a new wall is started from
    the drifted pose, then a wall known from before pulls the heading back: the new wall turns
    back with it. Filtered apart, the new wall would keep the drift for good."""
    truth = np.zeros(3)
    drifted = np.array([0.0, 0.0, math.radians(3.0)])
    x, p = slam_ekf.start(drifted, np.diag([1e-6, 1e-6, math.radians(4.0) ** 2]), (0.01, 0.01))
    new_wall = np.array([0.0, 2.5])  # the wall y = 2.5, not seen before
    z_new = wall_model.predict(new_wall, np.zeros(2), truth)
    x, p, anchor = slam_ekf.augment(x, p, z_new, np.eye(2) * 1e-6)
    assert abs(math.degrees(math.atan2(-x[5], x[6]))) > 2.5, "started with the drift"
    x, p = slam_ekf.insert(x, p, np.array([3.0, 0.0]), np.eye(2) * 1e-9)  # x = 3, known
    for _ in range(3):
        z_old = wall_model.predict(np.array([3.0, 0.0]), np.zeros(2), truth)
        innov = slam_ekf.innovation(x, p, 1, np.zeros(2), z_old, np.eye(2) * 1e-6)
        x, p = slam_ekf.update(x, p, innov)
    assert abs(math.degrees(x[2])) < 0.05, "the heading is back"
    assert abs(math.degrees(math.atan2(-x[5], x[6]))) < 0.05, "and the new wall with it"
    assert abs(np.linalg.norm(x[5:7]) - 2.5) < 5e-3
    assert np.allclose(anchor, truth[:2])
    assert np.all(np.linalg.eigvalsh(p) > -1e-12)


def test_a_young_wall_updates_alone_and_keeps_its_correlations_exact() -> None:
    """update_wall_only: the wall moves, nothing else does; P is the Joseph form of its gain."""
    rng = np.random.default_rng(11)
    x, p = _state(rng, walls=2)
    anchor = np.array([0.3, 0.1])
    innov = slam_ekf.innovation(x, p, 1, anchor, np.array([1.5, -2.0]), np.eye(2) * 1e-3)
    x_new, p_new = slam_ekf.update_wall_only(x, p, innov)
    moved = np.flatnonzero(np.abs(x_new - x) > 0)
    assert set(moved) <= {7, 8}, "only wall 1's entries change"
    assert len(moved) > 0
    cols = [0, 1, 2, 7, 8]
    pht = p[:, cols] @ innov.jacobian.T
    gain = np.zeros_like(pht)
    gain[[7, 8]] = pht[[7, 8]] @ np.linalg.inv(innov.cov)
    h = np.zeros((2, len(x)))
    h[:, cols] = innov.jacobian
    r = innov.cov - h @ p @ h.T
    i_kh = np.eye(len(x)) - gain @ h
    assert np.allclose(p_new, i_kh @ p @ i_kh.T + gain @ r @ gain.T, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(p_new) > -1e-12)
    assert np.trace(p_new[7:9, 7:9]) < np.trace(p[7:9, 7:9]), "the wall is surer"
    assert np.allclose(p_new[:5, :5], p[:5, :5]), "the pose is neither moved nor surer"
