"""Where one robot's map frame lies in another's, from the walls of the two maps alone.

Two robots switched on in different places map the same building in different frames; nothing
relates the frames but the walls both saw. Walls are few, long and exact, so they fix the
transform well once the maps overlap: two walls that are not parallel fix it entirely.

The search (``align``), with no initial guess:

1. **Turns.** Every pair of walls (one per map) votes, weighted by the shorter's length, for the
   turn that makes them parallel (modulo 180 degrees); the strongest peaks, each taken both ways
   round, are the turns tried.
2. **Shifts.** For a turn, each pair of walls of the two maps within ``parallel`` of each other
   puts B's shift on a line (the shifts that bring the two walls onto one line). Two such lines
   from walls ``min_spread`` apart cross at one shift; the heaviest piles of crossings are the
   shifts tried.
3. **Verification.** Each (turn, shift) is scored on the whole map: the length of B's walls that
   lands on a wall of A (parallel, on its line within ``offset``, overlapping it). The best
   wins only when the next best that is a different transform scores clearly less
   (``ambiguity``, ``margin``): a symmetric building (a row of equal rooms seen in its middle)
   waits for more of the map.
4. **Refinement.** Gauss-Newton on (x, y, yaw) minimising the distance of the matched stretches'
   ends to the other map's lines, matches found again after each step; its covariance is the
   inverse of the information the matches give (``Alignment.cov``).

Pure numpy over plain arrays (``Walls``), no Zenoh: the merge service and the tests share it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wallmap.common.se2 import wrap

Array = NDArray[np.float64]

MAX_LINES = 300  # parallel pairs, heaviest first, whose crossings vote for a shift


@dataclass(frozen=True)
class AlignConfig:
    """How two maps are aligned.

    Attributes:
        min_length: shortest wall (m) used: short ones are furniture and fragments.
        parallel: largest angle (deg) between two walls taken for one.
        offset: farthest (m) a wall may lie from the other's line to be taken for it.
        turns: turn peaks tried (each both ways round).
        shifts: shifts tried per turn.
        min_spread: smallest angle (deg) between two walls whose lines fix a shift.
        min_matched: fewest walls matched, in two directions, for an alignment.
        min_overlap: least length (m) of walls on one another for an alignment.
        ambiguity: the next different transform must score below this share of the best...
        margin: ...or this much (m) less: in a large building of equal rooms a shift by one room
            fits all but the walls at the ends, which are many.
        iterations: refinement steps.
    """

    min_length: float = 0.8
    parallel: float = 3.0
    offset: float = 0.2
    turns: int = 4
    shifts: int = 8
    min_spread: float = 30.0
    min_matched: int = 4
    min_overlap: float = 6.0
    ambiguity: float = 0.7
    margin: float = 5.0
    iterations: int = 6


@dataclass(frozen=True)
class Walls:
    """A map's walls as segments: (n, 2) first and second ends, in the map's frame."""

    a: Array
    b: Array

    @classmethod
    def of(cls, segments: Array) -> Walls:
        """From (n, 2, 2) segments."""
        segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
        return cls(segments[:, 0].copy(), segments[:, 1].copy())

    @property
    def length(self) -> Array:
        """(n,) lengths."""
        d = self.b - self.a
        return np.hypot(d[:, 0], d[:, 1])

    @property
    def angle(self) -> Array:
        """(n,) direction in [0, pi): a line's, either way along it."""
        d = self.b - self.a
        return np.arctan2(d[:, 1], d[:, 0]) % math.pi

    def moved(self, pose: Array) -> Walls:
        """These walls placed by ``pose`` (x, y, yaw): in the frame ``pose`` lives in."""
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rot = np.array([[c, -s], [s, c]])
        return Walls(self.a @ rot.T + pose[:2], self.b @ rot.T + pose[:2])

    def longer_than(self, length: float) -> Walls:
        """Only the walls at least ``length`` long."""
        keep = self.length >= length
        return Walls(self.a[keep], self.b[keep])


@dataclass(frozen=True)
class Alignment:
    """Where map B's frame lies in map A's.

    Attributes:
        pose: (x, y, yaw) of B's frame in A's: ``p_A = R(yaw) p_B + (x, y)``.
        cov: its 3x3 covariance.
        matched: B's walls matched to A's.
        overlap: length (m) of B's walls lying on A's.
        runner_up: the score of the best different transform, as a share of this one's.
    """

    pose: Array
    cov: Array
    matched: int
    overlap: float
    runner_up: float


def align(a: Walls, b: Walls, config: AlignConfig | None = None) -> Alignment | None:
    """B's frame in A's from the walls alone (the module's steps).

    None while the maps do not overlap enough to say, or could be put together more than one
    way.
    """
    config = config or AlignConfig()
    a, b = a.longer_than(config.min_length), b.longer_than(config.min_length)
    if min(len(a.a), len(b.a)) < config.min_matched:
        return None
    scored = [(_score(a, b.moved(pose), config)[0], pose) for pose in _hypotheses(a, b, config)]
    if not scored:
        return None
    scored.sort(key=lambda item: -item[0])
    best_score, best = scored[0]
    pose, cov, owner, length = _refined(a, b, best, config)
    matched, overlap = int((owner >= 0).sum()), float(length[owner >= 0].sum())
    if (
        matched < config.min_matched
        or overlap < config.min_overlap
        or not _spread(a, owner, config)
    ):
        return None
    other = max((s for s, p in scored[1:] if _different(p, pose)), default=0.0)
    runner_up = other / max(best_score, 1e-9)
    if runner_up >= config.ambiguity and best_score - other < config.margin:
        return None
    return Alignment(pose, cov, matched, overlap, runner_up)


def _hypotheses(a: Walls, b: Walls, config: AlignConfig) -> list[Array]:
    """Transforms to try: turns (step 1) times shifts (step 2)."""
    found = []
    for turn in _turns(a, b, config):
        moved = b.moved(np.array([0.0, 0.0, turn]))
        found += [np.array([*shift, turn]) for shift in _shifts(a, moved, config)]
    return found


def _turns(a: Walls, b: Walls, config: AlignConfig) -> list[float]:
    """The strongest turns making walls of B parallel to walls of A, each both ways round."""
    bins = 180
    diff = (a.angle[:, None] - b.angle[None, :]) % math.pi
    weight = np.minimum(a.length[:, None], b.length[None, :])
    votes = np.bincount(
        (diff / math.pi * bins).astype(np.int64).ravel() % bins, weight.ravel(), minlength=bins
    )
    smooth = votes + np.roll(votes, 1) + np.roll(votes, -1)
    peaks = [
        k
        for k in np.argsort(-smooth)
        if smooth[k] > 0 and smooth[k] >= smooth[k - 1] and smooth[k] >= smooth[(k + 1) % bins]
    ]
    turns = []
    for k in peaks[: config.turns]:
        near = (diff - (k + 0.5) * math.pi / bins + math.pi / 2) % math.pi - math.pi / 2
        close = (np.abs(near) < 1.5 * math.pi / bins) & (weight > 0)
        centre = (k + 0.5) * math.pi / bins + float(np.average(near[close], weights=weight[close]))
        turns += [centre, centre + math.pi]
    return [float(wrap(t)) for t in turns]


def _shifts(a: Walls, b: Walls, config: AlignConfig) -> list[Array]:
    """Shifts putting parallel walls of A and (turned) B on one line (step 2).

    Each parallel pair says how far B must move along A's wall's normal: a line of shifts. Two
    such lines from walls ``min_spread`` apart or more cross at one shift; the crossings of the
    right pairs pile up at the right shift, the rest scatter. The heaviest piles are tried.
    """
    i, j = np.nonzero(
        np.abs(_angle_gap(a.angle[:, None], b.angle[None, :])) < math.radians(config.parallel)
    )
    normal = _normals(a)[i]
    mid_b = 0.5 * (b.a[j] + b.b[j])
    need = np.einsum("nk,nk->n", normal, a.a[i] - mid_b)  # normal . t putting b on a's line
    weight = np.minimum(a.length[i], b.length[j])
    heaviest = np.argsort(-weight)[:MAX_LINES]
    normal, need, weight = normal[heaviest], need[heaviest], weight[heaviest]
    k, m = np.triu_indices(len(need), 1)
    det = normal[k, 0] * normal[m, 1] - normal[k, 1] * normal[m, 0]
    crossing = np.abs(det) >= math.sin(math.radians(config.min_spread))
    k, m, det = k[crossing], m[crossing], det[crossing]
    tx = (need[k] * normal[m, 1] - need[m] * normal[k, 1]) / det
    ty = (normal[k, 0] * need[m] - normal[m, 0] * need[k]) / det
    return _piles(tx, ty, weight[k] * weight[m], config.shifts)


def _piles(x: Array, y: Array, weight: Array, count: int, cell: float = 0.2) -> list[Array]:
    """The ``count`` heaviest ``cell``-sized piles of points, each as its weighted mean."""
    if not len(x):
        return []
    key = np.floor(x / cell).astype(np.int64) * 1_000_003 + np.floor(y / cell).astype(np.int64)
    _, which = np.unique(key, return_inverse=True)
    mass = np.bincount(which, weight)
    found = []
    for pile in np.argsort(-mass)[:count]:
        mine = which == pile
        w = weight[mine]
        found.append(np.array([np.average(x[mine], weights=w), np.average(y[mine], weights=w)]))
    return found


def _angle_gap(x: Array | float, y: Array | float) -> Array:
    """Signed difference of two line directions, in [-pi/2, pi/2)."""
    return (np.asarray(x) - np.asarray(y) + math.pi / 2) % math.pi - math.pi / 2


def _normals(walls: Walls) -> Array:
    """(n, 2) unit normals (left of a to b)."""
    d = walls.b - walls.a
    return np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(walls.length, 1e-12)[:, None]


def _matches(a: Walls, b: Walls, config: AlignConfig) -> tuple[Array, Array, Array]:
    """For each wall of B, its wall of A (or -1) and the stretch of B lying along it.

    Returns A's index per B wall, and the ends (n, 2) of the overlapping stretch, on B's wall.
    Among candidates (parallel, both ends within ``offset`` of A's line, overlapping along it)
    the longest overlap wins.
    """
    normal = _normals(a)
    rho = np.einsum("nk,nk->n", normal, a.a)
    off0 = b.a @ normal.T - rho  # (b, a): B's ends from A's lines
    off1 = b.b @ normal.T - rho
    ok = _angle_gap(b.angle[:, None], a.angle[None, :]) < math.radians(config.parallel)
    ok &= _angle_gap(b.angle[:, None], a.angle[None, :]) > -math.radians(config.parallel)
    ok &= (np.abs(off0) < config.offset) & (np.abs(off1) < config.offset)
    unit = (a.b - a.a) / np.maximum(a.length, 1e-12)[:, None]
    t0 = np.einsum("bk,ak->ba", b.a, unit) - np.einsum("ak,ak->a", a.a, unit)
    t1 = np.einsum("bk,ak->ba", b.b, unit) - np.einsum("ak,ak->a", a.a, unit)
    low = np.maximum(np.minimum(t0, t1), 0.0)
    high = np.minimum(np.maximum(t0, t1), a.length[None, :])
    overlap = np.where(ok, high - low, 0.0)
    best = np.argmax(overlap, axis=1)
    rows = np.arange(len(b.a))
    length = overlap[rows, best]
    owner = np.where(length > 0.0, best, -1)
    # The overlapping stretch's ends, on B's wall: where A's extent starts and ends along it.
    span = (t1 - t0)[rows, best]
    span = np.where(np.abs(span) < 1e-12, 1e-12, span)
    f_low = (low[rows, best] - t0[rows, best]) / span
    f_high = (high[rows, best] - t0[rows, best]) / span
    d = b.b - b.a
    ends = np.stack([b.a + f_low[:, None] * d, b.a + f_high[:, None] * d], axis=1)
    return owner, ends, np.maximum(length, 0.0)


def _score(a: Walls, b: Walls, config: AlignConfig) -> tuple[float, int]:
    """Length of B's walls lying on walls of A, and how many of B's walls do."""
    owner, _, length = _matches(a, b, config)
    return float(length[owner >= 0].sum()), int((owner >= 0).sum())


def _spread(a: Walls, owner: Array, config: AlignConfig) -> bool:
    """Whether the walls of A matched by B's run in two directions ``min_spread`` apart.

    Two such directions fix a shift. ``owner``: which wall of A each of B's lies on (-1: none).
    """
    angles = a.angle[owner[owner >= 0]]
    gaps = np.abs(_angle_gap(angles[:, None], angles[None, :]))
    return bool(len(angles) and gaps.max() >= math.radians(config.min_spread))


def _different(p: Array, q: Array) -> bool:
    """Two transforms that put the maps together differently (not one found twice)."""
    return bool(np.hypot(*(p[:2] - q[:2])) > 0.5 or abs(wrap(p[2] - q[2])) > math.radians(5.0))


def refine(a: Walls, b: Walls, pose: Array, config: AlignConfig) -> tuple[Array, Array, int, float]:
    """Gauss-Newton on B's frame in A's from ``pose``, the matched stretches' ends onto A's lines.

    Matches are found again each step. Returns the pose, its covariance, the matches and the
    length of B's walls on A's.
    """
    pose, cov, owner, length = _refined(a, b, pose, config)
    return pose, cov, int((owner >= 0).sum()), float(length[owner >= 0].sum())


def _refined(
    a: Walls, b: Walls, pose: Array, config: AlignConfig
) -> tuple[Array, Array, Array, Array]:
    """``refine``'s pose and covariance, with the matches at that pose.

    The matches: which wall of A each of B's lies on (-1: none), and the length of each on it.
    """
    pose = np.asarray(pose, dtype=float).copy()
    cov = np.eye(3)
    normals = _normals(a)
    rhos = np.einsum("nk,nk->n", normals, a.a)
    for _ in range(config.iterations):
        owner, ends, length = _matches(a, b.moved(pose), config)
        keep = owner >= 0
        if keep.sum() < 2:
            break
        local = _back(ends[keep].reshape(-1, 2), pose)  # the stretches' ends in B's frame
        normal = np.repeat(normals[owner[keep]], 2, axis=0)
        rho = np.repeat(rhos[owner[keep]], 2)
        weight = np.repeat(length[keep], 2)  # a longer stretch says more
        r = point_line_residuals(pose, local, normal, rho)
        j = point_line_jacobian(pose, local, normal)
        info = j.T @ (weight[:, None] * j)
        if np.linalg.cond(info) > 1e12:
            break
        step = np.linalg.solve(info, -j.T @ (weight * r))
        pose += step
        pose[2] = wrap(pose[2])
        sigma2 = float(weight @ r**2 / max(weight.sum(), 1e-9)) + 1e-6
        cov = np.linalg.inv(info) * sigma2 * float(weight.sum()) / max(len(r) - 3, 1)
        if np.hypot(*step[:2]) < 1e-5 and abs(step[2]) < 1e-7:
            break
    owner, _, length = _matches(a, b.moved(pose), config)
    return pose, 0.5 * (cov + cov.T), owner, length


def _back(points: Array, pose: Array) -> Array:
    """Points of A's frame in B's frame (``pose`` is B's frame in A's)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rel = points - pose[:2]
    return np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)


def point_line_residuals(pose: Array, points: Array, normal: Array, rho: Array) -> Array:
    """Signed distances of B's points, placed by ``pose``, from A's lines ``normal . p = rho``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    x = c * points[:, 0] - s * points[:, 1] + pose[0]
    y = s * points[:, 0] + c * points[:, 1] + pose[1]
    return normal[:, 0] * x + normal[:, 1] * y - rho


def point_line_jacobian(pose: Array, points: Array, normal: Array) -> Array:
    """The Jacobian of :func:`point_line_residuals` with respect to (x, y, yaw), (n, 3)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx = -s * points[:, 0] - c * points[:, 1]  # d/dyaw of the placed point
    dy = c * points[:, 0] - s * points[:, 1]
    return np.stack([normal[:, 0], normal[:, 1], normal[:, 0] * dx + normal[:, 1] * dy], axis=1)
