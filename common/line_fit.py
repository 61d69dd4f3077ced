"""Total-least-squares line fit with the covariance of the line's closest point.

The paper reports each wall by its closest point (u, v) to the sensor but gives the filter no
measurement covariance. The fit here provides one: with residual variance ``sigma^2`` along
the normal, a TLS line through ``N`` points has an offset variance ``sigma^2 / N`` at the centroid
and an angle variance ``sigma^2 / sum(t_i^2)`` (``t_i`` the points' positions along the line),
the two independent. Both are mapped to (u, v) by the Jacobian of ``(u, v) = (n . c) n``.
"""

from __future__ import annotations

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

    @property
    def length(self) -> float:
        """Length of the fitted segment."""
        return float(np.linalg.norm(self.p1 - self.p0))


def fit_line(points: Array, *, sigma_floor: float = 0.0, cov_scale: float = 1.0) -> LineFit:
    """Fit a line to ``points`` (N x 2, N >= 2) by total least squares.

    Args:
        points: the points, all finite.
        sigma_floor: lower bound on the per-point noise (m): a few points can line up by chance
            better than the sensor really measures.
        cov_scale: factor on the covariance, for noise that is correlated along a scan (a depth
            camera's errors are), which the independent-points formula underestimates.
    """
    centroid = points.mean(axis=0)
    centred = points - centroid
    scatter = centred.T @ centred
    _, vectors = np.linalg.eigh(scatter)
    normal = vectors[:, 0]
    offset = float(normal @ centroid)
    if offset < 0.0:
        normal, offset = -normal, -offset
    along = np.array([-normal[1], normal[0]])
    t = centred @ along
    residuals = centred @ normal
    n = len(points)
    dof = max(n - 2, 1)
    sigma2 = max(float(residuals @ residuals) / dof, sigma_floor**2)
    var_angle = sigma2 / max(float(t @ t), 1e-12)
    var_offset = sigma2 / n
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
    )
