"""Where the walls say a frame was, when its pose is wrong: association and the search. Pure.

A tracker that jumps, a SLAM that slips: the pose is 10-20 degrees and tens of centimetres off,
and at the given pose no observation passes the gate of the wall it saw. The walls still say
where the frame was. A wall's direction does not depend on where the robot stands, so every
observation and every settled wall near it give a heading error (how far the observed line is
turned from the one predicted); the true one is where many of them agree. From each such heading
the frame is fitted to the walls in a wide window (``common.pose_fit``), and the fit that explains
the most observations wins, if it explains most of them and clearly more than any other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wallmap.common import compiled, ekf, pose_fit, se2, wall_model
from wallmap.common.compiled import plain
from wallmap.common.ekf import CHI2_2DOF_999
from wallmap.common.messages import Observations
from wallmap.common.se2 import Array
from wallmap.services.mapper.wall_map import WallMap

_TIGHT_SD = (0.01, math.radians(0.3))  # m, rad: the gate of the final association


@dataclass(frozen=True)
class Search:
    """How far from a wrong pose the walls are asked where it was.

    Attributes:
        angle: Heading errors up to this (rad) are looked for...
        distance: ...and position errors up to this (m).
        vote_sd: Observations agree on a heading error within about this (rad).
        hypotheses: Heading errors tried, the best supported first.
        share: The winner explains at least this share of the observations near settled walls.
    """

    angle: float = math.radians(25.0)
    distance: float = 0.4
    vote_sd: float = math.radians(1.0)
    hypotheses: int = 3
    share: float = 0.6


@dataclass(frozen=True)
class Candidates:
    """Each observation of a frame and every settled wall near where it puts a wall, as arrays.

    Gathered once per frame (the grid index and the extents, in Python), then scored from any
    pose near the one they were gathered from in one numpy pass (``associate``).

    Attributes:
        obs: The observation index of each candidate pair, (m,).
        walls: The wall id of each pair.
        z: The observed closest points, (m, 2); ``r`` their covariances, (m, 2, 2).
        s: The walls' states, (m, 2); ``anchor`` their anchors; ``p`` their covariances.
    """

    obs: Array
    walls: list[int]
    z: Array
    r: Array
    s: Array
    anchor: Array
    p: Array

    def near(self) -> int:
        """How many observations have a settled wall near them."""
        return len(set(self.obs.tolist()))


def candidates(frame: Observations, pose: Array, wall_map: WallMap, min_obs: int) -> Candidates:
    """The settled walls (confirmed, seen ``min_obs`` times) near each observation from ``pose``.

    Each wall's covariance has the map's ``line_floor`` added: no wall is straighter, nor
    known better in the map, than that (it was mapped from poses that were not exact). A
    pose fitted to walls believed to the millimetre follows every small error of theirs, and
    the walls mapped from it then follow the pose: the map drifts as an odometry does.
    """
    rows = []
    cfg = wall_map.config
    for i, obs in enumerate(frame.walls):
        for wall in wall_map.near_observation(obs, pose):
            if wall.n_obs >= min_obs and wall.confirmed(cfg):
                rows.append((i, wall.id, obs.closest, obs.cov, wall.s, wall.anchor, wall.p))
    if not rows:
        e2, e22 = np.zeros((0, 2)), np.zeros((0, 2, 2))
        return Candidates(np.zeros(0, dtype=int), [], e2, e22, e2, e2, e22)
    obs_index, ids, z, r, s, anchor, p = zip(*rows, strict=True)
    z, r, s, anchor, p = (np.array(a) for a in (z, r, s, anchor, p))
    p = p + ekf.line_spread(s, cfg.line_floor)
    return Candidates(np.array(obs_index), list(ids), z, r, s, anchor, p)


def associate(
    found: Candidates, pose: Array, pose_cov: Array
) -> tuple[pose_fit.Pairs, list[tuple[int, int]]]:
    """Each observation's most likely candidate wall seen from ``pose``, within the gate.

    Maximum likelihood on the innovation covariance ``S = H P H^T + R + J Q J^T``, inside the
    99.9 % chi-square gate, as ``WallMap.match`` scores one pair, here all pairs at once.
    Returns the pairs for the fit and, per pair, (observation index, wall id).
    """
    if not len(found.obs):
        return _no_pairs(), []
    keep = compiled.pose_kernels().best_pairs(
        found.s,
        found.p,
        found.anchor,
        found.z,
        found.r,
        plain(pose, np.float64),
        plain(pose_cov, np.float64),
        found.obs,
        CHI2_2DOF_999,
    )
    if not len(keep):
        return _no_pairs(), []
    pairs = pose_fit.Pairs(
        found.z[keep], found.r[keep], found.s[keep], found.anchor[keep], found.p[keep]
    )
    return pairs, [(int(found.obs[k]), found.walls[k]) for k in keep]


def _no_pairs() -> pose_fit.Pairs:
    empty2, empty22 = np.zeros((0, 2)), np.zeros((0, 2, 2))
    return pose_fit.Pairs(empty2, empty22, empty2, empty2, empty22)


def fit_from(
    frame: Observations,
    guess: Array,
    guess_sd: tuple[float, float],
    wall_map: WallMap,
    min_obs: int,
) -> tuple[pose_fit.Fit, int] | None:
    """The frame fitted to the walls from a guessed pose; with how many observations it explains.

    Associated in a window of ``guess_sd`` (m, rad), fitted, then associated again at the fit
    with a tight gate and fitted once more: what passes that gate is what the pose explains.
    """
    sd = np.array([guess_sd[0], guess_sd[0], guess_sd[1]])
    cov = np.diag(np.square(sd))
    found = candidates(frame, guess, wall_map, min_obs)
    pairs, matched = associate(found, guess, cov)
    if not matched:
        return None
    fitted = _fit_pose(guess, cov, pairs)
    tight = np.diag(np.square([_TIGHT_SD[0], _TIGHT_SD[0], _TIGHT_SD[1]]))
    pairs, matched = associate(found, fitted.pose, fitted.pose_cov + tight)
    if not matched:
        return None
    fitted = _fit_pose(guess, cov, pairs)
    return fitted, int(np.sum(fitted.m2 <= CHI2_2DOF_999))


def _fit_pose(guess: Array, cov: Array, pairs: pose_fit.Pairs) -> pose_fit.Fit:
    """A plain pose fit: the guess with covariance ``cov`` as the prior (``x = guess * w``)."""
    mean = np.zeros(pose_fit.STATE)
    prior = np.eye(pose_fit.STATE)
    prior[pose_fit.NOISE, pose_fit.NOISE] = cov
    active = np.zeros(pose_fit.STATE, dtype=bool)
    active[pose_fit.NOISE] = True
    return pose_fit.fit(mean, prior, guess, pairs, active)


def heading_votes(frame: Observations, pose: Array, wall_map: WallMap, config: Search) -> Array:
    """Heading errors (rad) the observations and the settled walls near them agree on, best first.

    Each observation and each wall near it predict a heading error: the angle from the observed
    closest point to the one predicted from ``pose`` (a position error moves a line, it does not
    turn it). Each candidate is scored by how many observations have a candidate within about
    ``vote_sd`` of it.
    """
    margin = config.distance + 1.0
    per_obs: list[Array] = []
    for obs in frame.walls:
        seg = np.array(
            [pose[:2] + se2.rotate(obs.p0, pose[2]), pose[:2] + se2.rotate(obs.p1, pose[2])]
        )
        box = np.array([seg.min(axis=0) - margin, seg.max(axis=0) + margin])
        walls = [wall_map.walls[i] for i in wall_map.index.near(box)]
        if not walls:
            continue
        s = np.array([w.s for w in walls])
        anchor = np.array([w.anchor for w in walls])
        predicted = wall_model.predict_many(s, anchor, pose)
        turn = np.arctan2(predicted[:, 1], predicted[:, 0]) - math.atan2(
            obs.closest[1], obs.closest[0]
        )
        turn = (turn + math.pi) % (2 * math.pi) - math.pi
        reach = np.abs(np.linalg.norm(predicted, axis=1) - np.linalg.norm(obs.closest))
        per_obs.append(turn[(np.abs(turn) <= config.angle) & (reach <= margin)])
    candidates = np.concatenate(per_obs) if per_obs else np.zeros(0)
    if not len(candidates):
        return candidates
    score = np.zeros(len(candidates))
    for turns in per_obs:
        if len(turns):
            close = np.abs(candidates[:, None] - turns[None, :]).min(axis=1)
            score += np.exp(-0.5 * (close / config.vote_sd) ** 2)
    chosen: list[float] = []
    for i in np.argsort(-score):
        if all(abs(candidates[i] - c) > 2 * config.vote_sd for c in chosen):
            chosen.append(float(candidates[i]))
        if len(chosen) == config.hypotheses:
            break
    return np.array(chosen)


def search_pose(
    frame: Observations,
    pose: Array,
    alternative: Array | None,
    wall_map: WallMap,
    near: int,
    min_obs: int,
    config: Search,
) -> tuple[Array, Array] | None:
    """Where the walls clearly say the frame was, near the wrong ``pose``; None if unclear.

    ``alternative``: a pose tried first (where the last recovered frames' offset puts this one).
    """
    needed = max(2, math.ceil(config.share * near))
    if alternative is not None:
        tried = fit_from(frame, alternative, (0.05, math.radians(2.0)), wall_map, min_obs)
        if tried is not None and tried[1] >= needed:
            return tried[0].pose, tried[0].pose_cov
    results: list[tuple[int, float, pose_fit.Fit]] = []
    for turn in heading_votes(frame, pose, wall_map, config):
        guess = np.array([pose[0], pose[1], se2.wrap(pose[2] + turn)])
        tried = fit_from(frame, guess, (config.distance / 2, math.radians(2.0)), wall_map, min_obs)
        if tried is not None:
            fitted, explained = tried
            results.append(
                (explained, -float(np.sum(np.minimum(fitted.m2, CHI2_2DOF_999))), fitted)
            )
    if not results:
        return None
    results.sort(key=lambda r: (r[0], r[1]), reverse=True)
    best = results[0]
    if best[0] < needed:
        return None
    rivals = [r for r in results[1:] if r[0] >= best[0] and not _same(r[2].pose, best[2].pose)]
    if rivals:
        return None
    return best[2].pose, best[2].pose_cov


def _same(a: Array, b: Array) -> bool:
    return math.hypot(a[0] - b[0], a[1] - b[1]) < 0.05 and abs(se2.wrap(a[2] - b[2])) < 0.02
