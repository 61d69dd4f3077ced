"""The per-wall EKF: innovation, association score and update.

The paper scores an observation against a wall with a Gaussian of the *wall's* covariance alone.
That is wrong twice over: a wall seen a hundred times has a tiny covariance, so a good new
observation (with its own, larger, noise) looks impossible and starts a duplicate wall; and the
score ignores how pose error moves the observation. Association must use the innovation
covariance ``S = H P H^T + R + J Q J^T`` (wall, measurement and pose uncertainty together). The
most likely wall is the one with the highest Gaussian log-likelihood of its innovation under S,
among those whose Mahalanobis distance passes a chi-square gate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wallmap.common import wall_model

Array = NDArray[np.float64]

_EYE2 = np.eye(2)
CHI2_2DOF_999 = 13.815510557964274  # 99.9 % gate of a chi-square with 2 degrees of freedom


@dataclass(frozen=True)
class Innovation:
    """An observation compared with a wall's prediction.

    Attributes:
        residual: observation minus prediction (2,).
        cov: innovation covariance S (2x2).
        jacobian: d prediction / d state (2x2), kept for the update.
        mahalanobis2: squared Mahalanobis distance of the residual under S.
        log_likelihood: Gaussian log-density of the residual under S.
    """

    residual: Array
    cov: Array
    jacobian: Array
    mahalanobis2: float
    log_likelihood: float


def inverse_and_det(m: Array) -> tuple[Array, float]:
    """Inverse and determinant of a 2x2 matrix, in closed form (hot path)."""
    a, b, c, d = float(m[0, 0]), float(m[0, 1]), float(m[1, 0]), float(m[1, 1])
    det = a * d - b * c
    return np.array([[d, -b], [-c, a]]) / det, det


def innovation(
    s: Array, p: Array, anchor: Array, z: Array, r: Array, pose: Array, pose_cov: Array
) -> Innovation:
    """Compare observation ``z`` (covariance ``r``) seen from ``pose`` with wall state ``s, p``."""
    h = wall_model.jacobian_state(s, anchor, pose)
    hp = wall_model.jacobian_pose(s, anchor, pose)
    cov = h @ p @ h.T + r + hp @ pose_cov @ hp.T
    residual = z - wall_model.predict(s, anchor, pose)
    inverse, det = inverse_and_det(cov)
    m2 = float(residual @ inverse @ residual)
    return Innovation(residual, cov, h, m2, -0.5 * (m2 + math.log(det)) - math.log(2.0 * math.pi))


def update(s: Array, p: Array, innov: Innovation) -> tuple[Array, Array]:
    """EKF update in Joseph form, which keeps P symmetric and positive for tiny covariances."""
    h = innov.jacobian
    gain = p @ h.T @ inverse_and_det(innov.cov)[0]
    s_new = s + gain @ innov.residual
    i_kh = _EYE2 - gain @ h
    r_eff = innov.cov - h @ p @ h.T  # the measurement and pose part of S
    p_new = i_kh @ p @ i_kh.T + gain @ r_eff @ gain.T
    return s_new, 0.5 * (p_new + p_new.T)


def fuse(
    s_a: Array, p_a: Array, anchor_a: Array, s_b: Array, p_b: Array, anchor_b: Array
) -> tuple[Array, Array]:
    """Two estimates of one wall fused into one, in the parameterisation of wall ``a``.

    Wall ``b`` is first re-expressed as its closest point to ``a``'s anchor (the measurement
    model seen from that anchor with zero heading), then the two are combined in information form.
    """
    at_a = np.array([anchor_a[0], anchor_a[1], 0.0])
    z = wall_model.predict(s_b, anchor_b, at_a)
    j = wall_model.jacobian_state(s_b, anchor_b, at_a)
    info_a, info_b = np.linalg.inv(p_a), np.linalg.inv(j @ p_b @ j.T)
    p = np.linalg.inv(info_a + info_b)
    return p @ (info_a @ s_a + info_b @ z), 0.5 * (p + p.T)


def line_jacobian(s: Array) -> Array:
    """The Jacobian d s / d (rho, theta) of a line's closest point s = rho (cos theta, sin theta).

    The columns move the line across itself (its offset) and turn it about its foot point.
    """
    rho = float(np.linalg.norm(s))
    n = s / rho
    return np.column_stack([n, rho * wall_model.direction(s)])


def line_spread(s: Array, sd: tuple[float, float]) -> Array:
    """The covariance a line's offset and angle standard deviations give its closest point.

    ``J diag(sd^2) J^T`` with ``J = line_jacobian(s)``, for one closest point (2,) or many
    (n, 2) at once: ``sd[0]^2 n n^T + (rho sd[1])^2 d d^T``, the normal ``n``, the direction ``d``.
    """
    rho = np.linalg.norm(s, axis=-1, keepdims=True)
    n = s / rho
    d = np.stack([-n[..., 1], n[..., 0]], axis=-1)
    across, turn = n * sd[0], d * (rho * sd[1])
    return across[..., :, None] * across[..., None, :] + turn[..., :, None] * turn[..., None, :]


def line_agreement(
    s_a: Array,
    p_a: Array,
    anchor_a: Array,
    s_b: Array,
    p_b: Array,
    anchor_b: Array,
    floor: tuple[float, float],
) -> float:
    """How well two wall estimates agree on one line: the squared Mahalanobis distance.

    Wall ``b`` is re-expressed as its closest point to ``a``'s anchor (as in :func:`fuse`); the
    difference is weighed by both covariances and by ``floor`` (offset m, angle rad) standard
    deviations: real walls are not perfectly straight, and an estimate seen a thousand times is
    not a thousand times surer of that. Compare with ``CHI2_2DOF_999``.
    """
    at_a = np.array([anchor_a[0], anchor_a[1], 0.0])
    z = wall_model.predict(s_b, anchor_b, at_a)
    j = wall_model.jacobian_state(s_b, anchor_b, at_a)
    d = s_a - z
    return float(d @ np.linalg.solve(p_a + j @ p_b @ j.T + line_spread(s_a, floor), d))


def initial_state(z: Array, r: Array, pose: Array, pose_cov: Array) -> tuple[Array, Array, Array]:
    """A new wall from one observation: ``(s, P, anchor)``."""
    s, anchor, ds_dz, ds_dpose = wall_model.from_observation(z, pose)
    p = ds_dz @ r @ ds_dz.T + ds_dpose @ pose_cov @ ds_dpose.T
    return s, 0.5 * (p + p.T), anchor
