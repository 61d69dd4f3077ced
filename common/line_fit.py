"""Total-least-squares line fit with the covariance of the line's closest point.

The paper reports each wall by its closest point (u, v) to the sensor but gives the filter no
measurement covariance. The fit here provides one: with residual variance ``sigma^2`` along
the normal, a TLS line through ``N`` points has an offset variance ``sigma^2 / N`` at the centroid
and an angle variance ``sigma^2 / sum(t_i^2)`` (``t_i`` the points' positions along the line),
the two independent. Both are mapped to (u, v) by the Jacobian of ``(u, v) = (n . c) n``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


@dataclass(frozen=True)
class LineFit:
    """A line fitted to 2-D points.

    Attributes:
        normal: unit normal, oriented away from the origin (``normal . centroid >= 0``).
        offset: distance of the line from the origin.
        centroid: mean of the points, on the line.
        closest: closest point of the line to the origin, ``offset * normal``: the paper's (u, v).
        cov: 2x2 covariance of ``closest``.
        p0, p1: end points, the extreme points projected onto the line.
        n_points: points in the fit.
        rms: root-mean-square distance of the points from the line.
        angle_sd: standard deviation of the line's direction (rad).
        noise_ratio: residual spread relative to the given per-point noise (1 when the noise
            model is right; NaN without one).
    """

    normal: Array
    offset: float
    centroid: Array
    closest: Array
    cov: Array
    p0: Array
    p1: Array
    n_points: int
    rms: float
    angle_sd: float
    noise_ratio: float

    @property
    def length(self) -> float:
        """Length of the fitted segment."""
        return float(np.linalg.norm(self.p1 - self.p0))


def fit_line(points: Array, sigmas: Array | None = None, *, cov_scale: float = 1.0) -> LineFit:
    """Fit a line to ``points`` (N x 2, N >= 2) by weighted total least squares.

    Args:
        points: the points, all finite.
        sigmas: per-point noise (m), e.g. growing with range for a depth camera: far points then
            weigh less, and the covariance is never tighter than this noise allows. Without it
            the noise is estimated from the residuals alone.
        cov_scale: factor on the covariance, for noise that is correlated along a scan (a depth
            camera's errors are), which the independent-points formula underestimates.
    """
    n = len(points)
    weights = np.ones(n) if sigmas is None else 1.0 / (sigmas * sigmas)
    normal, offset, centroid, centred, total = _weighted_line(points, weights)
    nx, ny = normal
    # Positions along the line and residuals across it, in one product (this runs per line).
    t, residuals = (centred @ np.array([[-ny, nx], [nx, ny]])).T
    chi2_per_dof = float(weights @ (residuals * residuals)) / max(n - 2, 1)
    scale2 = chi2_per_dof if sigmas is None else max(chi2_per_dof, 1.0)
    var_angle = scale2 / max(float(weights @ (t * t)), 1e-12)
    var_offset = scale2 / total
    # Rotating the normal by d_angle about the centroid moves (u, v) along `jac_angle`.
    c_along = float(centroid[1] * nx - centroid[0] * ny)
    jx, jy = nx * c_along - offset * ny, ny * c_along + offset * nx
    cov = np.array(
        [
            [
                var_angle * jx * jx + var_offset * nx * nx,
                var_angle * jx * jy + var_offset * nx * ny,
            ],
            [
                var_angle * jx * jy + var_offset * nx * ny,
                var_angle * jy * jy + var_offset * ny * ny,
            ],
        ]
    )
    along = np.array([-ny, nx])
    return LineFit(
        normal=normal,
        offset=offset,
        centroid=centroid,
        closest=offset * normal,
        cov=cov_scale * cov,
        p0=centroid + float(t.min()) * along,
        p1=centroid + float(t.max()) * along,
        n_points=n,
        rms=math.sqrt(float(residuals @ residuals) / n),
        angle_sd=math.sqrt(cov_scale * var_angle),
        noise_ratio=math.nan if sigmas is None else math.sqrt(chi2_per_dof),
    )


def line_through(points: Array, sigmas: Array) -> tuple[Array, float]:
    """The weighted TLS line's unit normal and offset alone, for when no more is needed."""
    normal, offset, *_ = _weighted_line(points, 1.0 / (sigmas * sigmas))
    return normal, offset


def _weighted_line(points: Array, weights: Array) -> tuple[Array, float, Array, Array, float]:
    """Normal (away from the origin), offset, centroid, centred points and total weight."""
    total = float(weights.sum())
    centroid = weights @ points / total
    centred = points - centroid
    (sxx, sxy), (_, syy) = (centred * weights[:, None]).T @ centred
    # The scatter's major axis runs along the line; the normal is across it (closed form, 2x2).
    angle = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    normal = np.array([-math.sin(angle), math.cos(angle)])
    offset = float(normal @ centroid)
    if offset < 0.0:
        normal, offset = -normal, -offset
    return normal, offset, centroid, centred, total


def _smallest_scatter_eigenvalue(
    w: Array, sx: Array, sy: Array, sxx: Array, sxy: Array, syy: Array
) -> Array:
    """Weighted sum of squared TLS residuals from running sums (closed form for 2x2)."""
    a = sxx - sx * sx / w
    b = sxy - sx * sy / w
    c = syy - sy * sy / w
    return 0.5 * (a + c) - np.sqrt(0.25 * (a - c) ** 2 + b * b)


def bend_split(points: Array, sigmas: Array, min_points: int, f_threshold: float) -> int | None:
    """Where to cut points ordered along a line in two, if two lines fit much better than one.

    Walls meet at any angle, also at a slight kink, and a line fitted across a kink is off in
    angle. An F-test compares one line with the best two (3 more parameters: a second line and the
    cut); every cut is scored at once from running sums.

    Returns:
        the size of the first part, or None to keep one line.
    """
    n = len(points)
    if n < 2 * min_points:
        return None
    w = 1.0 / (sigmas * sigmas)
    x, y = (points - points[n // 2]).T  # centred on a middle point, for precise sums
    wx, wy = w * x, w * y
    sums = np.cumsum(np.vstack((w, wx, wy, wx * x, wx * y, wy * y)), axis=1)
    head = sums[:, min_points - 1 : n - min_points]
    tail = sums[:, -1:] - head
    two = _smallest_scatter_eigenvalue(*head) + _smallest_scatter_eigenvalue(*tail)
    one = float(_smallest_scatter_eigenvalue(*sums[:, -1]))
    best = int(np.argmin(two))
    residual = max(float(two[best]), 1e-12)
    f = ((one - residual) / 3.0) / (residual / (n - 5))
    return min_points + best if f > f_threshold else None
