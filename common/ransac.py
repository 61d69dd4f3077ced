"""Wall lines in one scan row: clusters split at invalid points, then sequential RANSAC.

This is the paper's detector: the row is cut into clusters at NaN points (no return), and each
cluster yields lines one after another, each time removing the inliers of the best line. Beyond
the paper: hypotheses are scored all at once as a (hypotheses x points) matrix; the inlier band
widens with range, as depth noise does; an accepted line is refitted by least squares and cut at
gaps along it, so one line never bridges two walls that happen to be collinear across a doorway
or an occluder.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wallmap.common.line_fit import LineFit, fit_line

Array = NDArray[np.float64]


@dataclass(frozen=True)
class RansacParams:
    """Tuning of the line search.

    Attributes:
        iterations: hypotheses (point pairs) scored per line.
        inlier_min: inlier distance at short range (m).
        inlier_sigmas: inlier distance in units of the range-dependent noise.
        noise_k: depth noise sigma = noise_k * range^2 (a Kinect's is 1.425e-3; 0 for a lidar).
        min_points: fewest points that make a line.
        min_length: shortest segment reported (m).
        max_gap: largest gap between neighbouring inliers along one line (m).
        max_lines: most lines taken from one cluster.
        sigma_floor: lower bound on the per-point noise used for the covariance (m).
        cov_scale: factor on the fitted covariance (correlated noise along a scan).
    """

    iterations: int = 96
    inlier_min: float = 0.02
    inlier_sigmas: float = 3.0
    noise_k: float = 1.425e-3
    min_points: int = 12
    min_length: float = 0.4
    max_gap: float = 0.3
    max_lines: int = 8
    sigma_floor: float = 0.005
    cov_scale: float = 4.0


def split_at_nans(points: Array) -> list[NDArray[np.intp]]:
    """Indices of the runs of finite points in a scan (N x 2): the paper's clusterByNaN."""
    valid = np.isfinite(points).all(axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], valid.view(np.int8), [0]))))
    return [np.arange(start, stop) for start, stop in zip(edges[::2], edges[1::2], strict=True)]


def inlier_band(points: Array, params: RansacParams) -> Array:
    """Per-point inlier distance: wider for far points, whose depth is noisier."""
    range2 = np.einsum("ij,ij->i", points, points)
    return np.maximum(params.inlier_min, params.inlier_sigmas * params.noise_k * range2)


def _best_hypothesis(
    points: Array, band: Array, rng: np.random.Generator, iterations: int
) -> Array:
    """Inlier mask of the best of ``iterations`` two-point line hypotheses."""
    n = len(points)
    first = rng.integers(0, n, iterations)
    second = (first + rng.integers(1, n, iterations)) % n  # never the same point
    direction = points[second] - points[first]
    length = np.hypot(direction[:, 0], direction[:, 1])
    normals = np.column_stack([-direction[:, 1], direction[:, 0]]) / length[:, None]
    offsets = np.einsum("ij,ij->i", normals, points[first])
    inliers = np.abs(normals @ points.T - offsets[:, None]) <= band[None, :]
    return inliers[np.argmax(inliers.sum(axis=1))]


def _segments(fit: LineFit, points: Array, max_gap: float) -> list[NDArray[np.intp]]:
    """Split the points of one line where consecutive points along it are too far apart."""
    along = np.array([-fit.normal[1], fit.normal[0]])
    order = np.argsort(points @ along)
    gaps = np.diff(points[order] @ along)
    cuts = np.flatnonzero(gaps > max_gap) + 1
    return np.split(order, cuts)


def find_lines(points: Array, params: RansacParams, rng: np.random.Generator) -> list[LineFit]:
    """Sequential RANSAC over one cluster of finite points (N x 2)."""
    lines: list[LineFit] = []
    remaining = np.arange(len(points))
    band_all = inlier_band(points, params)
    while len(remaining) >= params.min_points and len(lines) < params.max_lines:
        pts, band = points[remaining], band_all[remaining]
        mask = _best_hypothesis(pts, band, rng, params.iterations)
        if mask.sum() < params.min_points:
            break
        fit = fit_line(pts[mask])
        # One refinement: the least-squares line picks up inliers the point pair missed.
        mask = np.abs(pts @ fit.normal - fit.offset) <= band
        if mask.sum() < params.min_points:
            break
        taken = np.flatnonzero(mask)
        fit = fit_line(pts[taken])
        accepted = []
        for seg in _segments(fit, pts[taken], params.max_gap):
            if len(seg) < params.min_points:
                continue
            seg_fit = fit_line(
                pts[taken[seg]], sigma_floor=params.sigma_floor, cov_scale=params.cov_scale
            )
            if seg_fit.length >= params.min_length:
                lines.append(seg_fit)
            accepted.append(taken[seg])
        if not accepted:
            break
        remaining = np.delete(remaining, np.concatenate(accepted))
    return lines


def detect_lines(scan: Array, params: RansacParams, rng: np.random.Generator) -> list[LineFit]:
    """All wall lines of one scan row (N x 2, NaN where there is no point)."""
    lines: list[LineFit] = []
    for cluster in split_at_nans(scan):
        if len(cluster) >= params.min_points:
            lines.extend(find_lines(scan[cluster], params, rng))
    return lines
