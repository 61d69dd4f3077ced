"""The pose judge's compiled algebra, against the wall model and the numpy fit it stands for."""

from __future__ import annotations

import numpy as np
import pytest

from wallmap.common import ekf, pose_fit, pose_kernels, se2, wall_model

Array = np.ndarray


def _random_walls(rng: np.random.Generator, n: int) -> tuple[Array, Array, Array]:
    s, anchor = rng.uniform(-4, 4, (n, 2)), rng.uniform(-2, 2, (n, 2))
    a = rng.normal(0, 0.05, (n, 2, 2))
    return s, anchor, a @ a.transpose(0, 2, 1) + 1e-6 * np.eye(2)


def test_the_compiled_wall_model_is_the_wall_model() -> None:
    """Each wall's prediction and Jacobians (tested against numeric differentiation there)."""
    rng = np.random.default_rng(4)
    s, anchor, _ = _random_walls(rng, 20)
    pose = rng.normal(0, 1, 3)
    predicted, by_state, by_pose = pose_kernels.linearized(s, anchor, pose)
    for i in range(20):
        np.testing.assert_allclose(predicted[i], wall_model.predict(s[i], anchor[i], pose))
        np.testing.assert_allclose(by_state[i], wall_model.jacobian_state(s[i], anchor[i], pose))
        np.testing.assert_allclose(by_pose[i], wall_model.jacobian_pose(s[i], anchor[i], pose))


def test_the_scores_are_each_wall_s_innovation() -> None:
    rng = np.random.default_rng(9)
    n = 12
    s, anchor, p = _random_walls(rng, n)
    pose, pose_cov = rng.normal(0, 1, 3), np.diag([1e-3, 2e-3, 1e-4])
    z, r = rng.uniform(-4, 4, (n, 2)), np.tile(np.diag([1e-3, 4e-3]), (n, 1, 1))
    m2, log_likelihood = pose_kernels.scores(s, p, anchor, z, r, pose, pose_cov)
    for k in range(n):
        one = ekf.innovation(s[k], p[k], anchor[k], z[k], r[k], pose, pose_cov)
        assert m2[k] == pytest.approx(one.mahalanobis2, rel=1e-9)
        assert log_likelihood[k] == pytest.approx(one.log_likelihood, rel=1e-9, abs=1e-9)


def test_the_compiled_frame_pose_is_the_frame_pose() -> None:
    """``pose_fit.frame_pose``'s Jacobian is tested against numeric differentiation."""
    rng = np.random.default_rng(5)
    for _ in range(10):
        xi, source = rng.normal(0, 0.3, 6), rng.normal(0, 2.0, 3)
        x, jac = pose_kernels.frame_pose(xi, source)
        want_x, want_jac = pose_fit.frame_pose(xi, source)
        np.testing.assert_allclose(x, want_x, atol=1e-14)
        np.testing.assert_allclose(jac, want_jac, atol=1e-14)


def _numpy_fit(
    mean: Array, cov: Array, source: Array, pairs: pose_fit.Pairs, active: Array
) -> tuple[Array, ...]:
    """``pose_fit.fit`` as it was in numpy, before it was compiled: the reference."""
    index = np.flatnonzero(active)
    info = np.linalg.inv(cov[np.ix_(index, index)])
    xi = mean.copy()

    def linearized() -> tuple[Array, Array, Array, Array, Array]:
        x, jx = pose_fit.frame_pose(xi, source)
        walls = list(zip(pairs.s, pairs.anchor, strict=True))
        predicted = np.array([wall_model.predict(a, b, x) for a, b in walls]).reshape(-1, 2)
        hw = [wall_model.jacobian_state(a, b, x) for a, b in walls]
        hp = [wall_model.jacobian_pose(a, b, x) for a, b in walls]
        noise = zip(pairs.r, hw, pairs.p, strict=True)
        s_inv = np.array([np.linalg.inv(r + h @ p @ h.T) for r, h, p in noise]).reshape(-1, 2, 2)
        h = np.array([j @ jx[:, active] for j in hp]).reshape(-1, 2, len(index))
        residual = pairs.z - predicted
        ht_s = np.einsum("nik,nij->nkj", h, s_inv)
        normal = info + np.einsum("nkj,njl->kl", ht_s, h)
        to_mean = pose_fit.difference(mean, xi)[index]
        gradient = info @ to_mean + np.einsum("nkj,nj->k", ht_s, residual)
        return normal, gradient, residual, h, s_inv

    normal, gradient, residual, h, s_inv = linearized()
    for _ in range(5 if len(pairs) else 0):
        step = np.linalg.solve(normal, gradient)
        xi[index] += step
        for i in pose_fit.ANGLES:
            xi[i] = se2.wrap(float(xi[i]))
        if float(np.abs(step).max()) < pose_fit.STEP_TOLERANCE:
            residual = residual - h @ step
            break
        normal, gradient, residual, h, s_inv = linearized()
    posterior = np.zeros((6, 6))
    posterior[np.ix_(index, index)] = np.linalg.inv(normal)
    posterior = 0.5 * (posterior + posterior.T)
    x, jx = pose_fit.frame_pose(xi, source)
    m2 = np.einsum("ni,nij,nj->n", residual, s_inv, residual)
    return xi, posterior, x, jx @ posterior @ jx.T, m2


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("held", [False, True])
def test_the_compiled_fit_is_the_numpy_fit(seed: int, held: bool) -> None:
    """Poses up to 20 degrees and 0.3 m off, 0-6 walls, all states fitted or the offset held."""
    rng = np.random.default_rng(seed)
    n = seed % 7
    truth = rng.normal(0, 1.0, 3)
    s, anchor, p = _random_walls(rng, n)
    z = np.array([wall_model.predict(a, b, truth) for a, b in zip(s, anchor, strict=True)]).reshape(
        -1, 2
    )
    z += rng.normal(0, 0.01, z.shape)
    r = np.tile(np.diag([1e-4, 4e-4]), (n, 1, 1))
    pairs = pose_fit.Pairs(z, r, s, anchor, p)
    source = se2.compose(truth, np.array([*rng.normal(0, 0.3, 2), rng.normal(0, 0.35)]))
    mean = np.concatenate([rng.normal(0, 0.01, 3), np.zeros(3)])
    cov = np.diag(np.square([0.02, 0.02, 0.01, 0.3, 0.3, 0.4]))
    active = np.array([not held] * 3 + [True] * 3)
    fitted = pose_fit.fit(mean, cov, source, pairs, active)
    want = _numpy_fit(mean, cov, source, pairs, active)
    for got, expected in zip(
        (fitted.xi, fitted.cov, fitted.pose, fitted.pose_cov), want[:4], strict=True
    ):
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fitted.m2, want[4], rtol=1e-7, atol=1e-9)


def test_each_observation_gets_the_candidate_numpy_picked() -> None:
    """The best candidate of each observation in the gate, as numpy picked it from the scores."""
    rng = np.random.default_rng(21)
    some_outside = False
    for _ in range(100):
        n = int(rng.integers(1, 10))
        s, anchor, p = _random_walls(rng, n)
        pose, pose_cov = rng.normal(0, 1, 3), np.diag([1e-3, 2e-3, 1e-4])
        obs = np.sort(rng.integers(0, 4, n))
        predicted, _, _ = pose_kernels.linearized(s, anchor, pose)
        z, r = predicted + rng.normal(0, 0.08, (n, 2)), np.tile(np.diag([1e-3, 4e-3]), (n, 1, 1))
        m2, log_likelihood = pose_kernels.scores(s, p, anchor, z, r, pose, pose_cov)
        score = np.where(m2 <= ekf.CHI2_2DOF_999, log_likelihood, -np.inf)
        best: dict[int, int] = {}
        for k in np.flatnonzero(np.isfinite(score)):
            if obs[k] not in best or score[k] > score[best[obs[k]]]:
                best[obs[k]] = int(k)
        want = [best[i] for i in sorted(best)]
        got = pose_kernels.best_pairs(s, p, anchor, z, r, pose, pose_cov, obs, ekf.CHI2_2DOF_999)
        assert got.tolist() == want
        some_outside |= len(set(obs[want].tolist())) < len(set(obs.tolist()))
    assert some_outside  # observations with no candidate in the gate were among them


def _numpy_line_turns(before: Array, after: Array, angle: float, offset: float) -> Array:
    """``latency.line_turn``'s matching as it was in numpy, before it was compiled."""
    a0, a1 = np.arctan2(before[:, 1], before[:, 0]), np.arctan2(after[:, 1], after[:, 0])
    d0, d1 = np.hypot(before[:, 0], before[:, 1]), np.hypot(after[:, 0], after[:, 1])
    turn = (a1[:, None] - a0[None, :] + np.pi) % (2 * np.pi) - np.pi
    close = (np.abs(turn) <= angle) & (np.abs(d1[:, None] - d0[None, :]) <= offset)
    nearest = np.argmin(np.where(close, np.abs(turn), np.inf), axis=1)
    return turn[np.arange(len(after)), nearest][close.any(axis=1)]


def test_the_lines_turn_as_numpy_matched_them() -> None:
    """Frames of a few lines turned a little, with lines that match none and equal matches."""
    rng = np.random.default_rng(13)
    matched = 0
    for _ in range(200):
        before = rng.uniform(-4, 4, (int(rng.integers(1, 6)), 2))
        c, q = np.cos(0.05), np.sin(0.05)
        after = before[rng.permutation(len(before))] @ np.array([[c, q], [-q, c]])
        after = np.vstack([after + rng.normal(0, 0.02, after.shape), rng.uniform(-4, 4, (2, 2))])
        want = _numpy_line_turns(before, after, np.radians(10.0), 0.3)
        got = pose_kernels.line_turns(before, after, np.radians(10.0), 0.3)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
        matched += len(want)
    assert matched > 300
    twin = np.array([[1.0, 1.0], [1.0, 1.0]])  # two equal lines: the first is taken
    assert pose_kernels.line_turns(twin, np.array([[1.0, 1.0]]), 0.2, 0.3).tolist() == [0.0]


def test_the_distance_from_the_prior_is_numpy_s() -> None:
    rng = np.random.default_rng(17)
    for _ in range(50):
        a = rng.normal(0, 1, (6, 6))
        cov, d = a @ a.T + 0.1 * np.eye(6), rng.normal(0, 1, 6)
        want = float(d @ np.linalg.solve(cov, d))
        assert pose_kernels.mahalanobis2(cov, d) == pytest.approx(want, rel=1e-12)


def test_interpolation_on_an_even_grid_is_numpy_s_to_the_bit() -> None:
    """Inside, on the grid's points, at and past both ends."""
    grid = np.arange(10.0, 25.0, 0.01)
    values = np.cumsum(np.random.default_rng(2).normal(0, 0.01, len(grid)))
    xs = np.concatenate([np.random.default_rng(3).uniform(9.0, 26.0, 2000), grid, [grid[-1]]])
    want = np.interp(xs, grid, values)
    for per_step in (1 / (grid[1] - grid[0]), 0.9 / (grid[1] - grid[0]), 0.0):  # or a bad guess
        got = [pose_kernels._interp(x, grid, values, per_step) for x in xs]
        assert np.array_equal(got, want)


def test_the_least_median_is_numpy_s_to_the_bit() -> None:
    """Rows of few distinct values (ties at the middle), even and odd, ordered every way."""
    rng = np.random.default_rng(8)
    for _ in range(300):
        rows, width = int(rng.integers(1, 12)), int(rng.integers(1, 9))
        r = rng.integers(0, 4, (rows, width)) + rng.choice([0.0, 0.5], (rows, width))
        if rng.random() < 0.5:
            r = r[np.argsort(-np.median(r, axis=1))]  # each row's median lower than the last
        assert pose_kernels.least_median(r) == np.median(r, axis=1).min()


def _numpy_turn_costs(
    t0: Array, t1: Array, seen: Array, shifts: Array, grid: Array, smooth: Array
) -> Array:
    """``LatencyEstimator.estimate``'s cost as it was in numpy, before it was compiled."""
    shifted = shifts[:, None]
    source = np.interp(t1 + shifted, grid, smooth) - np.interp(t0 + shifted, grid, smooth)
    r = np.abs(source - seen)
    r = r / max(1.4826 * np.median(r, axis=1).min(), 3e-4)
    return (0.5 * np.minimum(r, 3.0) ** 2).sum(axis=1)


@pytest.mark.parametrize("turns", [300, 301])
def test_the_latency_costs_are_numpy_s(turns: int) -> None:
    """Turns of a source 40 ms late, with outliers: the same costs, the same best latency.

    An even and an odd number of turns: the medians left out must be none the smallest.
    """
    rng = np.random.default_rng(6)
    grid = np.arange(0.0, 30.0, 0.01)
    heading = np.cumsum(rng.normal(0, 0.004, len(grid)))
    t0 = np.sort(rng.uniform(1.0, 28.0, turns))
    t1 = t0 + 0.25
    seen = np.interp(t1 + 0.04, grid, heading) - np.interp(t0 + 0.04, grid, heading)
    seen = seen + rng.normal(0, 0.002, turns)
    seen[::17] += 0.3  # mismatched lines
    shifts = np.arange(-0.25, 0.2525, 0.005)
    got = pose_kernels.turn_costs(t0, t1, seen, shifts, grid, heading, 3e-4, 3.0)
    want = _numpy_turn_costs(t0, t1, seen, shifts, grid, heading)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert shifts[np.argmin(got)] == pytest.approx(0.04)
