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

from wallmap.common.compiled import line_kernels, plain

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

    @classmethod
    def from_values(cls, values: list[float]) -> LineFit:
        """The fit from ``line_kernels.fit_values``' numbers (its ``FIT_FIELDS``, in order)."""
        nx, ny, offset, cx, cy, c00, c01, c11, p0x, p0y, p1x, p1y, n, rms, sd, ratio = values
        normal = np.array([nx, ny])
        return cls(
            normal=normal,
            offset=offset,
            centroid=np.array([cx, cy]),
            closest=offset * normal,
            cov=np.array([[c00, c01], [c01, c11]]),
            p0=np.array([p0x, p0y]),
            p1=np.array([p1x, p1y]),
            n_points=int(n),
            rms=rms,
            angle_sd=sd,
            noise_ratio=ratio,
        )

    @property
    def length(self) -> float:
        """Length of the fitted segment."""
        return math.hypot(self.p1[0] - self.p0[0], self.p1[1] - self.p0[1])


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
    points = plain(points, np.float64)
    weights = np.ones(len(points)) if sigmas is None else plain(1.0 / (sigmas * sigmas), np.float64)
    values = line_kernels().fit_values(points, weights, sigmas is None, cov_scale)
    return LineFit.from_values(values.tolist())


def bend_split(points: Array, sigmas: Array, min_points: int, f_threshold: float) -> int | None:
    """Where to cut points ordered along a line in two, if two lines fit much better than one.

    Walls meet at any angle, also at a slight kink, and a line fitted across a kink is off in
    angle. An F-test compares one line with the best two (3 more parameters: a second line and the
    cut); every cut is scored at once from running sums of the weighted scatter, whose smallest
    eigenvalue (closed form for 2x2) is the weighted sum of squared TLS residuals.

    Returns:
        the size of the first part, or None to keep one line.
    """
    cut = line_kernels().bend_cut(
        plain(points, np.float64), plain(sigmas, np.float64), min_points, f_threshold
    )
    return None if cut < 0 else cut
