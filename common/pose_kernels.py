"""The pose judge's per-frame algebra, compiled (numba): association, the pose fit, the turns.

``pose_fit.fit`` (Gauss-Newton on ``x = s * D * w`` against a frame's walls) and the scores
``pose_search.associate`` ranks a frame's candidate walls by are the same few lines of 2x2 and
6x6 algebra per pair; in numpy each was about fifty calls of a few microseconds on arrays of a
dozen pairs, and together they were a third of the mapper's time per frame. Here each is one
pass, and so is what was left in numpy around them: picking each observation's wall from the
scores, the fit's distance from its prior (``PoseJudge._consistent``), the turns of a frame's
lines that the latency is estimated from and the cost of each latency tried
(``latency.line_turn``, ``LatencyEstimator.estimate``). The equations are those of
``common.wall_model`` (the model and its Jacobians, tested against numeric differentiation
there), ``common.se2`` and ``common.pose_fit``, written out in scalars;
``tests/unit/common/test_pose_kernels.py`` checks these against the numpy they replace.

No SciPy here, so numba has no LAPACK: the 6x6 systems are solved by Gaussian elimination with
partial pivoting and back substitution, as LAPACK's ``gesv`` does (to the last bits).
Compiled once per machine and cached, as ``line_kernels`` is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

Array = NDArray[np.float64]


@njit(cache=True, nogil=True)
def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, nogil=True)
def linearized(s: Array, anchor: Array, pose: Array) -> tuple[Array, Array, Array]:
    """``wall_model``'s prediction and Jacobians (by the state, by the pose) for n walls."""
    n = len(s)
    predicted, by_state, by_pose = np.empty((n, 2)), np.empty((n, 2, 2)), np.empty((n, 2, 3))
    c, q = math.cos(pose[2]), math.sin(pose[2])
    for i in range(n):
        sx, sy = s[i, 0], s[i, 1]
        dx, dy = pose[0] - anchor[i, 0], pose[1] - anchor[i, 1]
        rho2 = sx * sx + sy * sy
        sd = sx * dx + sy * dy
        k = 1.0 - sd / rho2
        a, b = c * sx + q * sy, -q * sx + c * sy
        predicted[i, 0], predicted[i, 1] = k * a, k * b
        # k I + s grad(k)^T, turned into the robot's frame: R(yaw)^T (k I + s grad^T)
        twice = 2.0 * (sd / (rho2 * rho2))
        gx, gy = -dx / rho2 + twice * sx, -dy / rho2 + twice * sy
        m00, m01, m10, m11 = k + sx * gx, sx * gy, sy * gx, k + sy * gy
        by_state[i, 0, 0], by_state[i, 0, 1] = c * m00 + q * m10, c * m01 + q * m11
        by_state[i, 1, 0], by_state[i, 1, 1] = -q * m00 + c * m10, -q * m01 + c * m11
        by_pose[i, 0, 0], by_pose[i, 0, 1] = -a * sx / rho2, -a * sy / rho2
        by_pose[i, 1, 0], by_pose[i, 1, 1] = -b * sx / rho2, -b * sy / rho2
        by_pose[i, 0, 2], by_pose[i, 1, 2] = k * b, -k * a
    return predicted, by_state, by_pose


@njit(cache=True, nogil=True)
def _mm(a: Array, b: Array) -> Array:
    """``a @ b`` for small matrices: numba's own needs SciPy's BLAS."""
    out = np.zeros((a.shape[0], b.shape[1]))
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            for j in range(b.shape[1]):
                out[i, j] += a[i, k] * b[k, j]
    return out


@njit(cache=True, nogil=True)
def _mv(a: Array, v: Array) -> Array:
    """``a @ v`` for a small matrix and vector."""
    out = np.zeros(a.shape[0])
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            out[i] += a[i, k] * v[k]
    return out


@njit(cache=True, nogil=True)
def _covariance(hw: Array, p: Array, extra: Array) -> tuple[float, float, float, float]:
    """``hw p hw^T + extra`` of one pair, its four entries (row-major)."""
    out = _mm(_mm(hw, p), hw.T.copy()) + extra
    return out[0, 0], out[0, 1], out[1, 0], out[1, 1]


@njit(cache=True, nogil=True)
def scores(
    s: Array, p: Array, anchor: Array, z: Array, r: Array, pose: Array, pose_cov: Array
) -> tuple[Array, Array]:
    """``ekf.innovation``'s squared Mahalanobis distance and log-likelihood of each wall.

    ``S = H P H^T + R + J Q J^T`` with ``Q`` the pose's covariance: the likelihood association
    maximises over a frame's candidate pairs.
    """
    n = len(s)
    predicted, by_state, by_pose = linearized(s, anchor, pose)
    m2, log_likelihood = np.empty(n), np.empty(n)
    for i in range(n):
        from_pose = _mm(_mm(by_pose[i], pose_cov), by_pose[i].T.copy())
        c00, c01, c10, c11 = _covariance(by_state[i], p[i], r[i] + from_pose)
        e0, e1 = z[i, 0] - predicted[i, 0], z[i, 1] - predicted[i, 1]
        det = c00 * c11 - c01 * c10
        m2[i] = (c11 * e0**2 - (c01 + c10) * e0 * e1 + c00 * e1**2) / det
        log_likelihood[i] = -0.5 * (m2[i] + math.log(det)) - math.log(2.0 * math.pi)
    return m2, log_likelihood


@njit(cache=True, nogil=True)
def best_pairs(
    s: Array,
    p: Array,
    anchor: Array,
    z: Array,
    r: Array,
    pose: Array,
    pose_cov: Array,
    obs: NDArray[np.int64],
    gate: float,
) -> NDArray[np.intp]:
    """Each observation's most likely candidate wall within ``gate``, by ``scores``.

    ``obs``: the observation of each candidate pair (rows of ``z``). Returns the chosen
    candidates' indices in the order of their observations; the first of equals.
    """
    m2, log_likelihood = scores(s, p, anchor, z, r, pose, pose_cov)
    best = np.full(obs.max() + 1 if len(obs) else 0, -1, dtype=np.intp)
    for k in range(len(obs)):
        score, i = log_likelihood[k], obs[k]
        inside = m2[k] <= gate and math.isfinite(score)
        if inside and (best[i] < 0 or score > log_likelihood[best[i]]):
            best[i] = k
    return best[best >= 0].copy()


@njit(cache=True, nogil=True)
def line_turns(before: Array, after: Array, match_angle: float, match_offset: float) -> Array:
    """How each line of ``after`` turned from the line of ``before`` nearest it in direction.

    Lines are closest points (n, 2) in the robot frame; a pair is one line only if within
    ``match_angle`` (rad) and ``match_offset`` (m); a line of ``after`` matching none has no
    turn. The first of equally near lines is taken.
    """
    a0, d0 = np.empty(len(before)), np.empty(len(before))
    for j in range(len(before)):
        a0[j] = math.atan2(before[j, 1], before[j, 0])
        d0[j] = math.hypot(before[j, 0], before[j, 1])
    turns, m = np.empty(len(after)), 0
    for i in range(len(after)):
        a1 = math.atan2(after[i, 1], after[i, 0])
        d1 = math.hypot(after[i, 0], after[i, 1])
        nearest, size = np.nan, np.inf
        for j in range(len(before)):
            turn = (a1 - a0[j] + math.pi) % (2 * math.pi) - math.pi
            if abs(turn) <= match_angle and abs(d1 - d0[j]) <= match_offset and abs(turn) < size:
                nearest, size = turn, abs(turn)
        if size < np.inf:
            turns[m] = nearest
            m += 1
    return turns[:m].copy()


@njit(cache=True, nogil=True)
def _interp(x: float, xp: Array, fp: Array, per_step: float) -> float:
    """``np.interp(x, xp, fp)``, its formula to the bit, for ``xp`` evenly spaced.

    The interval is guessed from the spacing (``per_step``: its reciprocal, for a product is
    quicker than a quotient) and then checked against ``xp``, not searched for.
    """
    if not x >= xp[0]:  # before the first (or NaN, which interp also leaves at the edge)
        return fp[0] if x < xp[0] else np.nan
    if x >= xp[-1]:
        return fp[-1]
    j = min(int((x - xp[0]) * per_step), len(xp) - 2)
    while xp[j] > x:
        j -= 1
    while xp[j + 1] <= x:
        j += 1
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    return slope * (x - xp[j]) + fp[j]


@njit(cache=True, nogil=True)
def least_median(r: Array) -> float:
    """The smallest of the rows' medians: ``np.median(r, axis=1).min()``, to the bit (no NaN).

    A row's median is taken only where it may be below the smallest so far: when no more than
    the lower middle of the row's values lie below it, the row's median is not below it either.
    So a few medians are taken, not one a row (which was half of ``turn_costs``' time).
    """
    least, middle = np.inf, (r.shape[1] - 1) // 2
    for i in range(r.shape[0]):
        below = 0
        for v in r[i]:
            below += v < least
        if below > middle:
            least = min(least, np.median(r[i]))
    return least


@njit(cache=True, nogil=True)
def turn_costs(
    t0: Array,
    t1: Array,
    seen: Array,
    shifts: Array,
    xp: Array,
    fp: Array,
    floor: float,
    outlier: float,
) -> Array:
    """``LatencyEstimator.estimate``'s robust cost of each latency in ``shifts``.

    The source's turn from ``t0`` to ``t1`` (its heading ``fp`` at stamps ``xp``, evenly
    spaced), shifted by the latency, against the turns ``seen``: residuals scaled by their
    spread (1.4826 times the smallest median, at least ``floor``), each costing half its
    square up to ``outlier``.
    """
    n, k = len(shifts), len(seen)
    step = xp[1] - xp[0]
    per_step = 1.0 / step if step > 0.0 else 0.0
    r = np.empty((n, k))
    for i in range(n):
        for j in range(k):
            later = _interp(t1[j] + shifts[i], xp, fp, per_step)
            turned = later - _interp(t0[j] + shifts[i], xp, fp, per_step)
            r[i, j] = abs(turned - seen[j])
    scale = max(1.4826 * least_median(r), floor)
    cost = np.zeros(n)
    for i in range(n):
        for j in range(k):
            capped = min(r[i, j] / scale, outlier)
            cost[i] += 0.5 * capped**2
    return cost


@njit(cache=True, nogil=True)
def mahalanobis2(cov: Array, d: Array) -> float:
    """``d^T cov^-1 d`` for a small covariance, by elimination (``_solve``)."""
    x = _solve(cov, d.copy().reshape(len(d), 1))
    total = 0.0
    for i in range(len(d)):
        total += d[i] * x[i, 0]
    return total


@njit(cache=True, nogil=True)
def _solve(a: Array, b: Array) -> Array:
    """``a x = b`` for a small square ``a`` and ``b`` (m, k): elimination, pivoted."""
    m = len(a)
    work, rhs = a.copy(), b.copy()
    for col in range(m):
        pivot = col + np.argmax(np.abs(work[col:, col]))
        if pivot != col:
            for k in range(m):
                work[col, k], work[pivot, k] = work[pivot, k], work[col, k]
            for k in range(rhs.shape[1]):
                rhs[col, k], rhs[pivot, k] = rhs[pivot, k], rhs[col, k]
        for row in range(col + 1, m):
            factor = work[row, col] / work[col, col]
            for k in range(col, m):
                work[row, k] -= factor * work[col, k]
            for k in range(rhs.shape[1]):
                rhs[row, k] -= factor * rhs[col, k]
    for col in range(m - 1, -1, -1):
        for k in range(rhs.shape[1]):
            total = rhs[col, k]
            for j in range(col + 1, m):
                total -= work[col, j] * rhs[j, k]
            rhs[col, k] = total / work[col, col]
    return rhs


@njit(cache=True, nogil=True)
def _compose(a: Array, b: Array) -> Array:
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2])])


@njit(cache=True, nogil=True)
def frame_pose(xi: Array, source: Array) -> tuple[Array, Array]:
    """``pose_fit.frame_pose``: ``x = s * D * w`` and d x / d xi (3x6)."""
    moved = _compose(source, xi[0:3])
    x = _compose(moved, xi[3:6])
    jac = np.zeros((3, 6))
    c, q = math.cos(moved[2]), math.sin(moved[2])
    outer_a = np.array(
        [[1.0, 0.0, -q * xi[3] - c * xi[4]], [0.0, 1.0, c * xi[3] - q * xi[4]], [0.0, 0.0, 1.0]]
    )
    c0, q0 = math.cos(source[2]), math.sin(source[2])
    inner_b = np.array([[c0, -q0, 0.0], [q0, c0, 0.0], [0.0, 0.0, 1.0]])
    jac[:, 0:3] = _mm(outer_a, inner_b)
    jac[0, 3], jac[0, 4], jac[1, 3], jac[1, 4], jac[2, 5] = c, -q, q, c, 1.0
    return x, jac


@njit(cache=True, nogil=True)
def _normal_equations(
    xi: Array, source: Array, mean: Array, info: Array, index: NDArray[np.intp], pairs: tuple
) -> tuple[Array, Array, Array, Array, Array]:
    """At ``xi``: the normal matrix and gradient, the residuals, their Jacobians and S^-1."""
    z, r, s, anchor, p = pairs
    n, m = len(z), len(index)
    x, jx = frame_pose(xi, source)
    predicted, by_state, by_pose = linearized(s, anchor, x)
    jx_active = np.empty((3, m))
    for k in range(m):
        jx_active[:, k] = jx[:, index[k]]
    residual, h, s_inv = np.empty((n, 2)), np.empty((n, 2, m)), np.empty((n, 2, 2))
    to_mean = np.empty(m)
    for k in range(m):
        d = mean[index[k]] - xi[index[k]]
        to_mean[k] = _wrap(d) if index[k] == 2 or index[k] == 5 else d
    normal, gradient = info.copy(), _mv(info, to_mean)
    for i in range(n):
        c00, c01, c10, c11 = _covariance(by_state[i], p[i], r[i])
        det = c00 * c11 - c01 * c10
        s_inv[i, 0, 0], s_inv[i, 0, 1] = c11 / det, -c01 / det
        s_inv[i, 1, 0], s_inv[i, 1, 1] = -c10 / det, c00 / det
        residual[i, 0], residual[i, 1] = z[i, 0] - predicted[i, 0], z[i, 1] - predicted[i, 1]
        h[i] = _mm(by_pose[i], jx_active)
        ht_s = _mm(h[i].T.copy(), s_inv[i])
        normal += _mm(ht_s, h[i])
        gradient += _mv(ht_s, residual[i])
    return normal, gradient, residual, h, s_inv


@njit(cache=True, nogil=True)
def fit(
    mean: Array,
    cov: Array,
    source: Array,
    pairs: tuple,
    active: NDArray[np.bool_],
    iterations: int,
    tolerance: float,
) -> tuple[Array, Array, Array, Array, Array]:
    """``pose_fit.fit``: the posterior ``xi``, its covariance, the pose, its covariance, m2."""
    index = np.flatnonzero(active)
    m = len(index)
    prior = np.empty((m, m))
    for a in range(m):
        for b in range(m):
            prior[a, b] = cov[index[a], index[b]]
    info = _solve(prior, np.eye(m))
    xi = mean.copy()
    normal, gradient, residual, h, s_inv = _normal_equations(xi, source, mean, info, index, pairs)
    for _ in range(iterations if len(pairs[0]) else 0):
        step = _solve(normal, gradient.reshape(m, 1))[:, 0].copy()  # one kind of array each
        for k in range(m):
            xi[index[k]] += step[k]
        xi[2], xi[5] = _wrap(xi[2]), _wrap(xi[5])
        if np.abs(step).max() < tolerance:
            # converged: the linearisation just made holds at the new mean (``pose_fit.fit``)
            for i in range(len(residual)):
                residual[i] -= _mv(h[i], step)
            break
        normal, gradient, residual, h, s_inv = _normal_equations(
            xi, source, mean, info, index, pairs
        )
    inverse = _solve(normal, np.eye(m))
    posterior = np.zeros((6, 6))
    for a in range(m):
        for b in range(m):
            posterior[index[a], index[b]] = inverse[a, b]
    posterior = 0.5 * (posterior + posterior.T)
    x, jx = frame_pose(xi, source)
    m2 = np.empty(len(residual))
    for i in range(len(residual)):
        weighted = _mv(s_inv[i], residual[i])
        m2[i] = residual[i, 0] * weighted[0] + residual[i, 1] * weighted[1]
    return xi, posterior, x, _mm(_mm(jx, posterior), jx.T.copy()), m2


def warm_up() -> None:
    """Compile (or load from the cache) every kernel a frame calls now, not on the first frame.

    ``scores`` is not among them: frames reach it through ``best_pairs``, loaded with it.
    """
    one2, one22 = np.array([[1.0, 0.2]]), np.array([np.eye(2) * 1e-4])
    pose, cov = np.array([0.1, 0.0, 0.05]), np.eye(3) * 1e-4
    best_pairs(one2, one22, np.zeros((1, 2)), one2, one22, pose, cov, np.zeros(1, np.int64), 13.8)
    line_turns(one2, one2, 0.2, 0.3)
    mahalanobis2(np.eye(6), np.ones(6))
    line = np.linspace(0.0, 1.0, 5)
    turn_costs(line[:2], line[1:3], line[:2], line[:3] - 0.5, line, line, 1e-3, 3.0)
    pairs = (one2, one22, one2, np.zeros((1, 2)), one22)
    fit(np.zeros(6), np.eye(6) * 1e-4, pose, pairs, np.ones(6, dtype=np.bool_), 5, 1e-3)
