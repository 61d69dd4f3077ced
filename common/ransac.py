"""Wall lines in one scan row: clusters split at invalid points, then sequential RANSAC.

This is the paper's detector: the row is cut into clusters at NaN points (no return), and each
cluster yields lines one after another, each time removing the inliers of the best line. Beyond
the paper: the inlier band widens with range, as depth noise does; an accepted line is refitted
by least squares and cut at gaps along it and at kinks, so one line never bridges two walls that
happen to be collinear across a doorway or an occluder. The search's loops are compiled
(``line_kernels``); this module holds its settings and what is done with the lines it finds.
"""

from __future__ import annotations

import copy
import itertools
import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common.compiled import line_kernels, plain
from wallmap.common.config_file import require
from wallmap.common.line_fit import LineFit, bend_split, fit_line

if TYPE_CHECKING:  # the kernels' module imports numba: loaded where it runs, not here
    from wallmap.common.line_kernels import Counts, Limits

Array = NDArray[np.float64]
SCORED_POINTS = 256  # hypotheses are scored on about this many points of a cluster


# The rule each tuning value is held to, from a flag, --set or a file alike.
_RULES = [
    *(
        (name, "positive", lambda x: x > 0)
        for name in (
            "inlier_min",
            "inlier_sigmas",
            "noise_scale",
            "max_gap",
            "sigma_floor",
            "cov_scale",
            "split_f",
            "max_angle_sd",
            "lone_angle_sd",
            "max_jump",
        )
    ),
    *(
        (name, ">= 0", lambda x: x >= 0)
        for name in (
            "noise_k",
            "min_length",
            "lone_length",
            "corner_reach",
            "corner_angle",
            "nan_run",
        )
    ),
    *((name, ">= 1", lambda x: x >= 1) for name in ("iterations", "max_lines")),
    ("min_points", ">= 2", lambda x: x >= 2),
]


@dataclass(frozen=True)
class RansacConfig:
    """Tuning of the line search.

    Attributes:
        iterations: hypotheses (point pairs) scored per line.
        inlier_min: inlier distance at short range (m).
        inlier_sigmas: inlier distance in units of the range-dependent noise.
        noise_k: depth noise sigma = noise_k * range^2 (a Kinect's is 1.425e-3; 0 for a lidar).
        noise_scale: factor on the per-point noise, which the detector adapts to what the
            residuals show (a sensor noisier or quieter than assumed).
        min_points: fewest points that make a line.
        min_length: shortest segment reported (m).
        max_gap: largest gap between neighbouring inliers along one line (m).
        max_lines: most lines taken from one cluster.
        sigma_floor: lower bound on the per-point noise (m).
        cov_scale: factor on the fitted covariance (correlated noise along a scan).
        split_f: F statistic above which a line is cut in two at a kink.
        max_angle_sd: lines less sure of their direction than this are dropped (rad): a short,
            far, noisy segment cannot tell two walls meeting at a shallow angle apart, and fed
            to the map it blends them into a wall that is neither.
        lone_angle_sd: ...but a line that holds ``lone_share`` of its cluster's points and is
            at least ``lone_length`` (m) long is kept up to this (rad): it has no neighbour in
            the cluster to blend with, and a far wall glimpsed a few times is often seen no
            better. The map's shadow rule catches the rare blend that gets through.
        lone_share: see above.
        lone_length: see above.
        corner_reach: two lines of one cluster whose ends lie this close to their intersection
            (m) meet there: near a corner the inlier band takes in the other wall's points and
            would carry each line past the corner.
        corner_angle: lines closer to parallel than this (rad) have no corner.
        nan_run: runs of at most this many invalid points do not split a cluster (0: any does,
            as in the paper; a lidar's dropouts need more).
        max_jump: neighbouring points farther apart than this (m) split a cluster.
    """

    iterations: int = 96
    inlier_min: float = 0.02
    inlier_sigmas: float = 3.0
    noise_k: float = 1.425e-3
    noise_scale: float = 1.0
    min_points: int = 12
    min_length: float = 0.25
    max_gap: float = 0.3
    max_lines: int = 8
    sigma_floor: float = 0.005
    cov_scale: float = 4.0
    split_f: float = 6.0
    max_angle_sd: float = 0.04
    lone_angle_sd: float = 0.1
    lone_share: float = 0.9
    lone_length: float = 0.5
    corner_reach: float = 0.4
    corner_angle: float = np.radians(3.0)
    nan_run: int = 0
    max_jump: float = math.inf

    def searched_by(self) -> tuple[Counts, Limits]:
        """What ``line_kernels.row_lines`` takes: counts and limits, in its order.

        The counts: iterations, min_points, max_lines and the points a hypothesis is scored on;
        the limits: max_gap, split_f, cov_scale, min_length, max_angle_sd, lone_share,
        lone_length and lone_angle_sd.
        """
        counts = (self.iterations, self.min_points, self.max_lines, SCORED_POINTS)
        limits = (self.max_gap, self.split_f, self.cov_scale, self.min_length)
        lone = (self.max_angle_sd, self.lone_share, self.lone_length, self.lone_angle_sd)
        return counts, (*limits, *lone)

    def scaled(self, factor: float) -> RansacConfig:
        """These, with the per-point noise scaled by ``factor`` (> 0): the noise learnt.

        Made for every frame, so not checked again: a positive factor keeps them valid.
        """
        out = copy.copy(self)
        object.__setattr__(out, "noise_scale", self.noise_scale * factor)
        return out

    def __post_init__(self) -> None:
        for name, rule, ok in _RULES:
            require(ok(getattr(self, name)), name, rule, getattr(self, name))
        require(0 < self.lone_share <= 1, "lone_share", "within (0, 1]", self.lone_share)


def split_at_nans(
    points: Array, nan_run: int = 0, max_jump: float = math.inf
) -> list[NDArray[np.intp]]:
    """Indices of the clusters of finite points in a scan (N x 2): the paper's clusterByNaN.

    ``detect_lines`` says how ``nan_run`` and ``max_jump`` cut, and cuts its rows so.
    """
    index, starts = line_kernels().cluster_bounds(plain(points, np.float64), nan_run, max_jump)
    return [index[a:b] for a, b in itertools.pairwise(starts.tolist())]


def _grouped(order: list[int], items: list[Any], groups: int) -> list[list[Any]]:
    """``items`` in lists by their group (``order``: each one's, ascending), ``groups`` lists."""
    out: list[list[Any]] = [[] for _ in range(groups)]
    for group, item in zip(order, items, strict=True):
        out[group].append(item)
    return out


def point_sigmas(points: Array, params: RansacConfig) -> Array:
    """Per-point noise: a depth camera's grows with the square of the range."""
    range2 = np.einsum("ij,ij->i", points, points)
    return params.noise_scale * np.maximum(params.sigma_floor, params.noise_k * range2)


@dataclass
class RowReport:
    """Why a row gave the lines it gave: what the detector's diagnostics publish.

    Attributes:
        points: valid points in the row.
        clusters: sizes of the clusters it was split into.
        lines: per accepted line: points, length (m), direction sd (rad).
        rejected: candidates turned down, by the threshold that turned them down.
    """

    points: int = 0
    clusters: list[int] = field(default_factory=list)
    lines: list[dict[str, float]] = field(default_factory=list)
    rejected: Counter[str] = field(default_factory=Counter)

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding."""
        return {
            "points": self.points,
            "clusters": self.clusters,
            "lines": self.lines,
            "rejected": dict(self.rejected),
        }


def _joined(
    points: Array, sigmas: Array, pieces: list[NDArray[np.intp]], params: RansacConfig
) -> list[LineFit]:
    """Lines from pairs of unsure pieces that are neighbours along the scan and one wall.

    At a corner the neighbour's line takes in the end of a wall, the kink test cuts that end
    off, and what is left of the wall is another piece: each too short to be sure of, together
    the wall. Two pieces join when no other point lies between them in the scan (whose order
    runs along a wall), one line fits them without a kink, and its direction is sure enough.
    """
    out = []
    ordered = sorted(pieces, key=lambda piece: int(piece.min()))
    joined = None  # the piece last joined: it is not joined twice
    for a, b in itertools.pairwise(ordered):
        if a is joined or b.min() > a.max() + 1:
            continue
        both = np.sort(np.concatenate([a, b]))
        if bend_split(points[both], sigmas[both], params.min_points, params.split_f) is not None:
            continue
        fit = fit_line(points[both], sigmas[both], cov_scale=params.cov_scale)
        if fit.angle_sd <= params.max_angle_sd and fit.length >= params.min_length:
            out.append(fit)
            joined = b
    return out


def meet_at_corners(lines: list[LineFit], params: RansacConfig) -> list[LineFit]:
    """End lines that nearly meet at an angle at their intersection, both of them."""
    lines = list(lines)
    for i, j in itertools.combinations(range(len(lines)), 2):
        a, b = lines[i], lines[j]
        (ax, ay), (bx, by) = a.normal.tolist(), b.normal.tolist()
        cross = ax * by - ay * bx
        if abs(cross) < math.sin(params.corner_angle):
            continue
        # Where n_a . p = offset_a and n_b . p = offset_b (Cramer's rule).
        cx = (a.offset * by - b.offset * ay) / cross
        cy = (b.offset * ax - a.offset * bx) / cross
        ends = []
        for line in (a, b):
            d0 = math.hypot(line.p0[0] - cx, line.p0[1] - cy)
            d1 = math.hypot(line.p1[0] - cx, line.p1[1] - cy)
            ends.append(int(d1 < d0) if min(d0, d1) <= params.corner_reach else None)
        corner = np.array([cx, cy])
        if None not in ends:
            lines[i], lines[j] = (
                replace(line, **{("p0", "p1")[end]: corner})
                for line, end in zip((a, b), ends, strict=True)
            )
    return lines


def detect_lines(
    scan: Array,
    params: RansacConfig,
    rng: np.random.Generator,
    report: RowReport | None = None,
) -> list[LineFit]:
    """All wall lines of one scan row (N x 2, NaN where there is no point).

    The row is cut into clusters of finite points (the paper's clusterByNaN). With the default
    settings every invalid point cuts, as in the paper: a depth camera's row is dense, and a
    hole in it is an occlusion or glass. A real lidar drops single returns all along a wall (a
    quarter of them on a cheap one), so for it runs of up to ``nan_run`` invalid points do not
    cut, and a jump of more than ``max_jump`` (m) between neighbours does.

    In each cluster of at least min_points, sequential RANSAC takes one line after another.
    Each round scores ``iterations`` two-point hypotheses on about ``SCORED_POINTS`` evenly
    spaced points (neighbours on a dense row say the same), refits the best one's inliers
    once, cuts the line at gaps along it and at kinks, and takes each piece long enough and
    sure enough of its direction; a piece turned down for its direction alone gets a second
    look beside its neighbour (``_joined``). Lines of a cluster that nearly meet end at their
    corner. The rounds run compiled, the whole row in one call (``line_kernels.row_lines``):
    in numpy each round was a few dozen small array calls, most of a depth frame's detector
    time.

    ``report``, when given, is filled with why the row gave these lines.
    """
    kernels = line_kernels()
    scan = plain(scan, np.float64)
    index, starts = kernels.cluster_bounds(scan, params.nan_run, params.max_jump)
    points = scan[index]
    sigmas = point_sigmas(points, params)
    band = np.maximum(params.inlier_min, params.inlier_sigmas * sigmas)
    fits, fit_cluster, rejected, unsure, unsure_starts, unsure_cluster = kernels.row_lines(
        points,
        sigmas,
        band,
        starts,
        rng,
        *params.searched_by(),
    )
    bounds = list(itertools.pairwise(starts.tolist()))
    found = _grouped(
        fit_cluster.tolist(), [LineFit.from_values(f) for f in fits.tolist()], len(bounds)
    )
    pieces = [unsure[a:b] for a, b in itertools.pairwise(unsure_starts.tolist())]
    doubtful = _grouped(unsure_cluster.tolist(), pieces, len(bounds))
    lines: list[LineFit] = []
    for (a, b), taken, unsure_pieces in zip(bounds, found, doubtful, strict=True):
        joined = _joined(points[a:b], sigmas[a:b], unsure_pieces, params) if unsure_pieces else []
        if taken or joined:
            lines.extend(meet_at_corners(taken + joined, params))
    if report is not None:
        _fill(report, rejected, [b - a for a, b in bounds], lines, params)
    return lines


def _fill(
    report: RowReport,
    rejected: NDArray[np.int64],
    sizes: list[int],
    lines: list[LineFit],
    params: RansacConfig,
) -> None:
    """Say in ``report`` what the row gave, and why not more."""
    for reason, count in zip(line_kernels().REJECTIONS, rejected.tolist(), strict=True):
        if count:
            report.rejected[reason] += count
    if small := sum(size < params.min_points for size in sizes):
        report.rejected["cluster below min_points"] += small
    report.points = sum(sizes)
    report.clusters = sizes
    report.lines = [
        {"points": line.n_points, "length": line.length, "angle_sd": line.angle_sd}
        for line in lines
    ]
