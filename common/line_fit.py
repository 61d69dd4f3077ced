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
    weights = np.ones(n) if sigmas is None else 1.0 / sigmas**2
    total = float(weights.sum())
    centroid = weights @ points / total
    centred = points - centroid
    wx, wy = weights * centred[:, 0], weights * centred[:, 1]
    sxx, syy, sxy = float(wx @ centred[:, 0]), float(wy @ centred[:, 1]), float(wx @ centred[:, 1])
    # The scatter's major axis runs along the line; the normal is across it (closed form, 2x2).
    angle = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    normal = np.array([-math.sin(angle), math.cos(angle)])
    offset = float(normal @ centroid)
    if offset < 0.0:
        normal, offset = -normal, -offset
    along = np.array([-normal[1], normal[0]])
    t = centred @ along
    residuals = centred @ normal
    chi2_per_dof = float(weights @ residuals**2) / max(n - 2, 1)
    scale2 = chi2_per_dof if sigmas is None else max(chi2_per_dof, 1.0)
    var_angle = scale2 / max(float(weights @ t**2), 1e-12)
    var_offset = scale2 / total
    # Rotating the normal by d_angle about the centroid moves (u, v) along `jac_angle`.
    jac_angle = normal * float(along @ centroid) + offset * along
    cov = var_angle * np.outer(jac_angle, jac_angle) + var_offset * np.outer(normal, normal)
    return LineFit(
        normal=normal,
        offset=offset,
        centroid=centroid,
        closest=offset * normal,
        cov=cov_scale * cov,
        p0=centroid + t.min() * along,
        p1=centroid + t.max() * along,
        n_points=n,
        rms=float(np.sqrt(residuals @ residuals / n)),
        angle_sd=float(np.sqrt(cov_scale * var_angle)),
        noise_ratio=math.nan if sigmas is None else math.sqrt(chi2_per_dof),
    )


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
    w = 1.0 / sigmas**2
    xy = points - points.mean(axis=0)
    x, y = xy[:, 0], xy[:, 1]
    sums = np.cumsum(np.stack([w, w * x, w * y, w * x * x, w * x * y, w * y * y]), axis=1)
    cut = np.arange(min_points, n - min_points + 1)
    head = sums[:, cut - 1]
    tail = sums[:, -1:] - head
    two = _smallest_scatter_eigenvalue(*head) + _smallest_scatter_eigenvalue(*tail)
    one = float(_smallest_scatter_eigenvalue(*sums[:, -1]))
    best = int(np.argmin(two))
    residual = max(float(two[best]), 1e-12)
    f = ((one - residual) / 3.0) / (residual / (n - 5))
    return int(cut[best]) if f > f_threshold else None
