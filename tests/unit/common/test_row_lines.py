"""The compiled line search of a whole row against the same search written out step by step.

``line_kernels.row_lines`` runs sequential RANSAC over every cluster of a row in one call. Here
the search is spelt out in Python over the building blocks the other kernel tests check
(``line_inliers``, ``fit_line``, ``segment_ranges``), drawing from its own copy of the random
generator: the two must give the same lines to the bit, turn down the same candidates, leave
the same pieces unsure, and leave the generators in the same state.
"""

import itertools
import math

import numpy as np
import pytest

from wallmap.common import line_kernels
from wallmap.common.line_fit import LineFit, fit_line
from wallmap.common.ransac import SCORED_POINTS, RansacConfig, RowReport, detect_lines


def searched(points, sigmas, band, rng, p: RansacConfig):
    """Sequential RANSAC over one cluster, step by step: lines, rejections, unsure pieces."""
    lines, rejected, unsure = [], [0, 0, 0, 0], []
    remaining = np.arange(len(points))
    while len(remaining) >= p.min_points and len(lines) < p.max_lines:
        pts, sig, near = points[remaining], sigmas[remaining], band[remaining]
        n = len(pts)
        first = rng.integers(0, n, p.iterations)
        second = (first + rng.integers(1, n, p.iterations)) % n
        step = -(-n // SCORED_POINTS)
        taken = line_kernels.line_inliers(pts, sig, near, first, second, step, p.min_points)
        if not len(taken):
            rejected[0] += 1
            break
        fit = fit_line(pts[taken], sig[taken], cov_scale=p.cov_scale)
        along = pts[taken, 0] * -fit.normal[1] + pts[taken, 1] * fit.normal[0]
        order = np.argsort(along)
        ranges = line_kernels.segment_ranges(
            pts[taken], sig[taken], along, order, p.max_gap, p.min_points, p.split_f
        )
        out = []
        for a, b in ranges.tolist():
            if b - a < p.min_points:
                rejected[1] += 1
                continue
            idx = taken[order[a:b]]
            piece = (
                fit if b - a == len(taken) else fit_line(pts[idx], sig[idx], cov_scale=p.cov_scale)
            )
            lone = (b - a) / len(points) >= p.lone_share and piece.length >= p.lone_length
            limit = max(p.max_angle_sd, p.lone_angle_sd) if lone else p.max_angle_sd
            if piece.length < p.min_length:
                rejected[2] += 1
            elif piece.angle_sd > limit:
                rejected[3] += 1
                unsure.append(remaining[idx])
            else:
                lines.append(piece)
            out.append(idx)
        if not out:
            break
        remaining = np.delete(remaining, np.concatenate(out))
    return lines, rejected, unsure


def scene(rng: np.random.Generator, kind: int) -> np.ndarray:
    """A row: one wall, a corner, a far noisy wall with a gap, scattered points, or a near wall
    then a far one (once the near one is taken, the far one is all that is left, but not all
    of its cluster: ``lone_share`` is of the cluster)."""
    n = int(rng.integers(5, 500))
    t = np.sort(rng.uniform(-3, 3, n))
    if kind == 0:
        return np.column_stack([t, 2 + 0.3 * t]) + rng.normal(0, 0.01, (n, 2))
    if kind == 1:
        y = np.where(t < 0.5, 2.5, 2.5 - (t - 0.5))
        x = np.where(t < 0.5, t, 0.5)
        return np.column_stack([x, y]) + rng.normal(0, 0.015, (n, 2))
    if kind == 2:
        row = np.column_stack([t, 4 + 0.05 * t]) + rng.normal(0, 0.04, (n, 2))
        return row[(t < -0.5) | (t > 0.2)]
    if kind == 3:
        return rng.normal(0, 1.5, (n, 2)) + np.array([0.0, 3.0])
    near = np.column_stack([np.linspace(-1, 0, 60), np.full(60, 1.5)])
    far = np.column_stack([np.linspace(0.5, 1.7, 40), np.full(40, 6.0)])
    return np.vstack([near + rng.normal(0, 0.005, (60, 2)), far + rng.normal(0, 0.05, (40, 2))])


@pytest.mark.parametrize("lidar", [False, True], ids=["depth", "lidar"])
def test_row_lines_is_the_search_written_out(lidar: bool) -> None:
    p = RansacConfig(noise_k=0.0, nan_run=2, max_jump=0.5) if lidar else RansacConfig()
    make = np.random.default_rng(11)
    lines_seen = unsure_seen = 0
    for k in range(400):
        row = scene(make, k % 5)
        if k % 3 == 0 and len(row) > 30:
            row[:: int(make.integers(13, 40))] = np.nan  # clusters, or gaps a lidar bridges
        index, starts = line_kernels.cluster_bounds(row, p.nan_run, p.max_jump)
        points = np.ascontiguousarray(row[index])
        sigmas = p.noise_scale * np.maximum(p.sigma_floor, p.noise_k * (points**2).sum(axis=1))
        band = np.maximum(p.inlier_min, p.inlier_sigmas * sigmas)
        ours, theirs = np.random.default_rng((3, k)), np.random.default_rng((3, k))
        fits, fit_cluster, rejected, unsure, unsure_starts, unsure_cluster = line_kernels.row_lines(
            points,
            sigmas,
            band,
            starts,
            ours,
            *p.searched_by(),
        )
        expected_lines, expected_unsure, expected_rejected = [], [], np.zeros(4, int)
        for c, (a, b) in enumerate(itertools.pairwise(starts.tolist())):
            if b - a < p.min_points:
                continue
            found, refused, pieces = searched(points[a:b], sigmas[a:b], band[a:b], theirs, p)
            expected_lines += [(c, line) for line in found]
            expected_unsure += [(c, piece.tolist()) for piece in pieces]
            expected_rejected += refused
        got = [LineFit.from_values(v) for v in fits.tolist()]
        assert fit_cluster.tolist() == [c for c, _ in expected_lines]
        for line, (_, expected) in zip(got, expected_lines, strict=True):
            for name in ("normal", "centroid", "closest", "cov", "p0", "p1"):
                np.testing.assert_array_equal(getattr(line, name), getattr(expected, name))
            assert (line.offset, line.n_points, line.rms, line.angle_sd) == (
                expected.offset,
                expected.n_points,
                expected.rms,
                expected.angle_sd,
            )
            assert line.noise_ratio == expected.noise_ratio
        pieces = [unsure[a:b].tolist() for a, b in itertools.pairwise(unsure_starts.tolist())]
        assert list(zip(unsure_cluster.tolist(), pieces, strict=True)) == expected_unsure
        assert rejected.tolist() == expected_rejected.tolist()
        assert ours.integers(1 << 40) == theirs.integers(1 << 40)  # as many draws, in order
        lines_seen += len(got)
        unsure_seen += len(pieces)
    assert lines_seen > 300  # the rows exercise every outcome
    assert unsure_seen > 0


def test_fit_line_without_noise_estimates_it_from_the_residuals() -> None:
    t = np.linspace(-1, 1, 50)
    wiggle = 0.02 * np.where(np.arange(50) % 2, 1.0, -1.0)
    points = np.column_stack([t, 2.0 + wiggle])
    fit = fit_line(points)
    assert math.isnan(fit.noise_ratio)
    assert fit.rms == pytest.approx(0.02, rel=0.01)
    # Residuals of 0.02 against points said to be good to 0.001: the ratio says so, and the
    # covariance follows the residuals. Said to be good to 0.1 only: it is never tighter.
    strict, loose = fit_line(points, np.full(50, 0.001)), fit_line(points, np.full(50, 0.1))
    assert strict.noise_ratio == pytest.approx(20.0, rel=0.05)
    assert strict.angle_sd == pytest.approx(fit.angle_sd)
    assert loose.noise_ratio == pytest.approx(0.2, rel=0.05)
    assert loose.angle_sd == pytest.approx(5.0 * fit.angle_sd, rel=0.05)


def test_a_row_s_report_counts_each_cluster_and_why_candidates_were_turned_down() -> None:
    wall = np.column_stack([np.linspace(-1, 1, 80), np.full(80, 2.0)])
    row = np.vstack([wall, [[np.nan, np.nan]], [[0.0, 1.0], [0.1, 1.0]], [[np.nan, np.nan]]])
    report = RowReport()
    lines = detect_lines(row, RansacConfig(), np.random.default_rng(0), report)
    assert len(lines) == 1
    assert report.points == 82
    assert report.clusters == [80, 2]
    assert report.rejected == {"cluster below min_points": 1}
    assert report.lines[0]["points"] == 80
