"""The compiled line-search loops against plain numpy statements of the same maths."""

import itertools
import math

import numpy as np
import pytest

from wallmap.common import line_kernels
from wallmap.common.line_fit import bend_split, fit_line


def noisy_line(rng: np.random.Generator, n: int = 40) -> tuple[np.ndarray, np.ndarray]:
    t = rng.uniform(-2, 2, n)
    points = np.column_stack([t, 0.3 * t - 1.5]) + rng.normal(0, 0.01, (n, 2))
    return points, rng.uniform(0.005, 0.03, n)


def test_weighted_line_is_the_weighted_scatter_s_minor_axis() -> None:
    rng = np.random.default_rng(8)
    for _ in range(50):
        points, sigmas = noisy_line(rng)
        w = 1.0 / sigmas**2
        centroid = w @ points / w.sum()
        centred = points - centroid
        _, vectors = np.linalg.eigh((centred * w[:, None]).T @ centred)
        normal = vectors[:, 0] * np.sign(vectors[:, 0] @ centroid)
        nx, ny, offset, cx, cy, total = line_kernels.weighted_line(points, w)
        np.testing.assert_allclose([nx, ny], normal, atol=1e-9)
        np.testing.assert_allclose([cx, cy], centroid, atol=1e-12)
        assert offset == pytest.approx(normal @ centroid, abs=1e-12)
        assert total == pytest.approx(w.sum())


def two_line_residual(points: np.ndarray, w: np.ndarray) -> float:
    """Weighted TLS residual of one line through ``points`` (the scatter's least eigenvalue)."""
    centred = points - w @ points / w.sum()
    return float(np.linalg.eigvalsh((centred * w[:, None]).T @ centred)[0])


@pytest.mark.parametrize("kink_deg", [0.0, 4.0, 20.0])
def test_bend_cut_is_the_best_cut_by_an_f_test_over_every_cut(kink_deg: float) -> None:
    rng = np.random.default_rng(int(kink_deg))
    t = np.linspace(0, 3, 90)
    bend = np.where(t > 1.7, (t - 1.7) * math.tan(math.radians(kink_deg)), 0.0)
    points = np.column_stack([t, 2.0 + bend + rng.normal(0, 0.004, t.size)])
    sigmas = np.full(t.size, 0.004)
    w, m = 1.0 / sigmas**2, 12
    two = [
        two_line_residual(points[:k], w[:k]) + two_line_residual(points[k:], w[k:])
        for k in range(m, len(points) - m + 1)
    ]
    best = int(np.argmin(two))
    one = two_line_residual(points, w)
    f = ((one - two[best]) / 3.0) / (two[best] / (len(points) - 5))
    expected = m + best if f > 6.0 else None
    assert bend_split(points, sigmas, m, 6.0) == expected
    assert (expected is not None) == (kink_deg >= 4.0)


def test_line_inliers_takes_the_line_and_leaves_the_clutter() -> None:
    rng = np.random.default_rng(3)
    wall = np.column_stack([np.linspace(-1, 1, 60), np.full(60, 2.0)])
    clutter = rng.uniform([-1, 0.5], [1, 1.5], (20, 2))
    points = np.vstack([wall, clutter])
    sigmas = np.full(len(points), 0.005)
    first = rng.integers(0, len(points), 64)
    second = (first + rng.integers(1, len(points), 64)) % len(points)
    taken = line_kernels.line_inliers(points, sigmas, 3 * sigmas, first, second, 1, 12)
    assert set(taken.tolist()) == set(range(60))
    # Too few inliers for min_points: nothing.
    none = line_kernels.line_inliers(points, sigmas, 3 * sigmas, first, second, 1, 61)
    assert none.size == 0


def test_segment_ranges_cut_at_gaps_and_order_along_the_line() -> None:
    x = np.concatenate([np.linspace(0, 1, 30), np.linspace(1.5, 2.5, 30)])
    points = np.column_stack([x, np.full(60, 2.0)])[::-1].copy()
    fit = fit_line(points)
    along = points @ np.array([-fit.normal[1], fit.normal[0]])
    order = np.argsort(along)
    pieces = line_kernels.segment_ranges(points, np.full(60, 0.005), along, order, 0.3, 12, 6.0)
    runs = sorted((points[order[a:b], 0].tolist() for a, b in pieces.tolist()), key=min)
    assert [len(r) for r in runs] == [30, 30]
    assert all(np.all(np.diff(r) < 0) or np.all(np.diff(r) > 0) for r in runs)  # in order
    assert max(runs[0]) < 1.1 < min(runs[1])


@pytest.mark.parametrize("nan_run", [0, 2])
def test_cluster_bounds_are_numpy_s_split(nan_run: int) -> None:
    rng = np.random.default_rng(nan_run)
    for _ in range(30):
        scan = rng.normal(0, 1, (80, 2)).cumsum(axis=0) * 0.05
        scan[rng.random(80) < 0.15] = np.nan
        index = np.flatnonzero(np.isfinite(scan).all(axis=1))
        jumps = np.hypot(*np.diff(scan[index], axis=0).T)
        cut = (np.diff(index) - 1 > nan_run) | (jumps > 0.08)
        expected = np.split(index, np.flatnonzero(cut) + 1) if len(index) else []
        found, starts = line_kernels.cluster_bounds(scan, nan_run, 0.08)
        assert [found[a:b].tolist() for a, b in itertools.pairwise(starts)] == [
            e.tolist() for e in expected
        ]
