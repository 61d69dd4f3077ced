"""Every pose judged against the walls: late, noisy or wrong poses still give one wall a surface.

The mapper's poses come from elsewhere (tf, odometry, a motion-capture system, a SLAM, the
project's scan matching), and none is the truth: it is late, noisy, and at times wrong. A wall
seen a thousand times knows where it is to a millimetre; a pose a degree off then puts the next
observation of it a few centimetres away, outside the gate, and starts a second wall beside the
first. So each frame's pose is a prior, and the frame's observations of the walls already mapped
correct it (``common.pose_fit``: the source's persistent error and the frame's own, fitted
together), within what the source has shown itself to be worth (``common.pose_trust``). The
source's latency is estimated from how the frames' lines turn against how the source turns
(``common.latency``), and each frame's pose is the source's at the frame's stamp plus it.

Per frame, one verdict:

- ``unjudged``: no settled wall in view (the start, a new room): the pose is taken as given.
- ``corrected``: the walls placed the frame, near where the source said.
- ``recovered``: the source was wrong (a tracker glitch, a slipping SLAM) and the walls clearly
  say where the frame was (``services.mapper.pose_search``): mapped from there, but it starts no
  wall, for a pose the source got wrong once may be wrong in a way the walls did not catch.
- ``refused``: the walls contradict the source and say nothing clear instead: nothing of the frame
  goes into the map. Counted.

The corrected pose is what the frame is mapped from, and what the trajectory shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wallmap.common import compiled, pose_fit, se2, wall_model
from wallmap.common.compiled import plain
from wallmap.common.config_file import require
from wallmap.common.ekf import CHI2_2DOF_999
from wallmap.common.latency import LatencyEstimator
from wallmap.common.messages import Observations, Pose
from wallmap.common.pose_trust import JumpDetector, NoiseScale, Trust, TrustLearner
from wallmap.common.se2 import Array
from wallmap.services.mapper.pose_buffer import PoseBuffer, SourcePose
from wallmap.services.mapper.pose_search import (
    Candidates,
    Search,
    associate,
    candidates,
    search_pose,
)
from wallmap.services.mapper.wall_map import WallMap

CHI2_6DOF_999 = 22.457744484825323  # 99.9 % of a chi-square with 6 degrees of freedom
GAP_ACCELERATION = (0.5, 1.5)  # m/s^2, rad/s^2: how far a robot strays from a straight line
ASSUMED = Trust(noise=(0.02, math.radians(1.0)), drift=(0.001, math.radians(0.02)))
FLOOR = Trust(noise=(0.002, math.radians(0.05)), drift=(0.0002, math.radians(0.005)))
MAX_LATENCY = 0.5  # s: a player sends poses this far past each frame, and a bit more
TAIL = 4.0  # a frame the walls contradict is tried again with the source's noise this much wider
ADOPT_AFTER = 10.0  # s of recovered frames agreeing on one new offset: the source moved for good
SUSPECT_FOR = 5.0  # s after a jump that the walls neither confirmed nor refuted: it was real
LATENCY_EVERY = 10  # turns between two latency estimates
# s: a first latency estimate this far from the guess remaps the frames so far. Nearer, the
# early walls are off by what the judge corrects frame by frame anyway, and mapping a third of
# a run again would cost it half as much time again (the Jackal: +23 ms, 171 frames, 1.5 s).
REMAP_SHIFT = 0.03


@dataclass(frozen=True)
class JudgeConfig:
    """How the mapper judges the poses it is given.

    Attributes:
        enabled: Judge every pose against the walls (the default); off (``--trust-poses``),
            poses are taken as they come, shifted by ``latency`` if it is given.
        latency: The source's latency (s): its pose of an instant is stamped this much later.
            None estimates it online (``--pose-latency`` fixes it).
        latency_sd: How far off the latency may be until it is estimated (s).
        max_latency: Latencies are looked for within this (s) either way.
        assumed: The source's noise and drift taken until learnt from the frames.
        floor: The least noise and drift ever learnt.
        offset_time: How long the source's persistent error lasts (s): the offset the judge
            carries from frame to frame is forgotten at this time constant.
        min_obs: A wall seen this often (and confirmed) judges poses.
        search: How far from a wrong pose the walls are asked where it was.
    """

    enabled: bool = True
    latency: float | None = None
    latency_sd: float = 0.05
    max_latency: float = 0.25
    assumed: Trust = field(default_factory=lambda: ASSUMED)
    floor: Trust = field(default_factory=lambda: FLOOR)
    offset_time: float = 5.0
    min_obs: int = 6
    search: Search = field(default_factory=Search)

    def __post_init__(self) -> None:
        if self.latency is not None:
            require(
                abs(self.latency) <= MAX_LATENCY,
                "latency",
                f"within +-{MAX_LATENCY} s",
                self.latency,
            )
        require(
            0 < self.max_latency <= MAX_LATENCY,
            "max_latency",
            f"0-{MAX_LATENCY} s",
            self.max_latency,
        )
        require(self.latency_sd > 0, "latency_sd", "positive", self.latency_sd)
        require(self.offset_time > 0, "offset_time", "positive", self.offset_time)
        require(self.min_obs >= 1, "min_obs", ">= 1", self.min_obs)

    def lookahead(self) -> float:
        """How far past a frame's stamp its source pose may lie (s)."""
        if self.latency is not None:
            return max(self.latency, 0.0)
        return self.max_latency if self.enabled else 0.0


@dataclass(frozen=True)
class Verdict:
    """What the judge made of one frame's pose.

    Attributes:
        pose: The pose to map the frame from (with its covariance), or None when refused.
        kind: ``unjudged``, ``corrected``, ``recovered`` or ``refused``.
        start_walls: Whether the frame's unmatched observations may start walls.
    """

    pose: Pose | None
    kind: str
    start_walls: bool = True


@dataclass
class _Counts:
    judged: int = 0
    corrected: int = 0
    recovered: int = 0
    refused: int = 0
    unjudged: int = 0


class PoseJudge:
    """The source's persistent error and latency, carried from frame to frame, and its worth."""

    def __init__(self, config: JudgeConfig | None = None) -> None:
        self.config = config or JudgeConfig()
        cfg = self.config
        self.offset = np.zeros(3)  # D: the source's persistent error, in the robot's frame
        self.cov = np.diag(np.square([1e-4, 1e-4, 1e-6]))  # of D
        self.latency = cfg.latency if cfg.latency is not None else 0.0
        self.latency_sd = 0.0 if cfg.latency is not None else cfg.latency_sd
        # Until the latency is first estimated, the frames are mapped with a guess: once it is
        # known, and far from the guess, the map of those first frames is made again
        # (``Mapping``): a wall started from poses a few degrees off would hold the map there.
        self.settled = cfg.latency is not None
        self.remap_due = False
        self.learner = TrustLearner(cfg.assumed, cfg.floor)
        self.noise = NoiseScale()
        self.turns = LatencyEstimator(cfg.max_latency)
        self.jumps = JumpDetector()
        # When the source jumped (its stamp), while the walls have not agreed with it since.
        self.suspect: float | None = None
        self.jumped: float | None = None  # the stamp of the source's last jump
        self.counts = _Counts()
        self.stamp: float | None = None
        self._alternative: tuple[Array, float, float] | None = None  # offset, since, last

    def source_stamp(self, stamp: float) -> float:
        """The source's stamp of the instant ``stamp``: later by its latency."""
        return stamp + self.latency

    def prepare(self, frame: Observations, source: SourcePose) -> Observations:
        """The frame's observations with the noise learnt: widened over a sweep, then scaled."""
        return sweep_widened(frame, source, self.noise.scale)

    def judge(
        self, frame: Observations, source: SourcePose, wall_map: WallMap, poses: PoseBuffer
    ) -> Verdict:
        """Place ``frame`` from the source's pose and the walls it saw.

        ``poses``: the source's poses, which the latency estimate reads the source's turns from.
        """
        self._learn_latency(frame, source.pose.stamp, poses)
        self._predict(frame.stamp)
        if self.jumps.add(frame.stamp, source.pose.vector):
            self.jumped = frame.stamp
            if self.suspect is None:
                self.suspect = frame.stamp  # until the walls agree with the source again
        if self.suspect is not None and frame.stamp - self.suspect > SUSPECT_FOR:
            self.suspect = None  # nor did they disagree: a jump that was the robot's own
        mean, cov = self._prior(source)
        x0, jx = pose_fit.frame_pose(mean, source.pose.vector)
        found = candidates(frame, x0, wall_map, self.config.min_obs)
        near = found.near()
        if not near:
            return self._unjudged(source, frame.stamp, x0, jx @ cov @ jx.T)
        self.counts.judged += 1
        matched = False
        for widen in (1.0, TAIL):  # a source's errors have longer tails than a Gaussian's
            prior = cov.copy()
            prior[pose_fit.NOISE, pose_fit.NOISE] *= widen**2
            fitted = self._fit(found, mean, prior, source.pose.vector, jx @ prior @ jx.T, x0)
            if fitted is not None and self._consistent(fitted, mean, prior, near):
                return self._accept(fitted, x0, jx @ prior @ jx.T, source, frame.stamp)
            matched = matched or fitted is not None
        # The walls contradict the source, or (no settled wall takes any observation, and the
        # source has not jumped) the walls near are not what this frame sees: a new wall in
        # front of an old one, or the source wrong by a step within its jitter. Either way the
        # walls are asked where the frame was.
        trusted = not matched and self.suspect is None
        recovered = self._recover(frame, source, wall_map, x0, near)
        if recovered is None and trusted:  # nothing clear: the pose is taken as given
            return self._unjudged(source, frame.stamp, x0, jx @ cov @ jx.T)
        if recovered is None:
            return self._refused()
        if trusted:  # the walls place the frame elsewhere: it was the source, as if it jumped
            self.jumped = self.suspect = frame.stamp
        return recovered

    def _unjudged(self, source: SourcePose, stamp: float, x0: Array, cov: Array) -> Verdict:
        """No settled wall can check the pose: taken as given, but starting no wall for a while.

        For ``SUSPECT_FOR`` after the source jumped: one frame that fits a wrong pose may have
        cleared the doubt, and the frames after it would start a turned copy of what they saw.
        """
        self.counts.unjudged += 1
        steady = self.jumped is None or stamp - self.jumped > SUSPECT_FOR
        return Verdict(_as_pose(source.pose, stamp, x0, cov), "unjudged", start_walls=steady)

    def _learn_latency(self, frame: Observations, placed_by: float, poses: PoseBuffer) -> None:
        """The frame's lines into the turning history; every LATENCY_EVERY turns, re-estimate.

        Counted as turns come, not as the history's length: a full history keeps its length,
        and an estimate reads all of it (a few ms), which every frame cannot afford. The
        source's poses are read up to ``placed_by``, the stamp of the one the frame is placed
        by: those have all come, whatever came after them depends on when (a run played twice
        is mapped the same).
        """
        if self.config.latency is not None or not frame.walls:
            return
        self.turns.add(frame.stamp, np.array([w.closest for w in frame.walls]))
        span = self.turns.span()
        if self.turns.added % LATENCY_EVERY or span is None:
            return
        reach = self.config.max_latency + 0.1
        found = self.turns.estimate(*poses.headings(span[0] - reach, placed_by))
        if found is None:
            return
        if not self.settled:
            shift = abs(found.latency - self.latency)
            self.remap_due = shift > max(REMAP_SHIFT, 2 * found.sd)
            self.settled = True
        self.latency, self.latency_sd = found.latency, found.sd

    def restart(self) -> None:
        """Forget the frames judged so far, not what was learnt of the source (a remap)."""
        self.offset = np.zeros(3)
        self.cov = np.diag(np.square([1e-4, 1e-4, 1e-6]))
        self.counts = _Counts()
        self.stamp = None
        self._alternative = None
        self.remap_due = False
        self.jumps = JumpDetector()
        self.suspect = None
        self.jumped = None

    def _predict(self, stamp: float) -> None:
        """Time passed since the last frame: the source's persistent error may have changed.

        It wanders (the drift learnt) and is forgotten over ``offset_time``: an
        Ornstein-Uhlenbeck process, exactly discretised. Without the forgetting, the error the
        judge carries would take up whatever the walls do not see (the position along the one
        wall a camera sees, the small errors of walls mapped from wrong poses) and walk off
        with the map, as an odometry does; with it, a good source's frame stays the map's.
        """
        dt = 0.0 if self.stamp is None else min(max(stamp - self.stamp, 0.0), 5.0)
        if self.stamp is not None and stamp < self.stamp - 60.0:
            self._alternative = None  # a new run: what it learnt of the source still holds
        self.stamp = stamp
        xy, yaw = self.learner.trust.drift
        keep = math.exp(-dt / self.config.offset_time)
        stationary = np.diag(np.square([xy, xy, yaw]) * self.config.offset_time / 2)
        self.offset = self.offset * keep
        self.cov = keep**2 * self.cov + (1 - keep**2) * stationary

    def _prior(self, source: SourcePose) -> tuple[Array, Array]:
        """The prior of ``[D, w]``: the carried error, the noise learnt.

        The frame's own noise also holds what is not known of the latency (the source's
        motion over that time) and, for a pose interpolated over a tracker's dropout, how far
        the robot may have strayed from the straight line the interpolation drew.
        """
        mean = np.zeros(pose_fit.STATE)
        mean[pose_fit.OFFSET] = self.offset
        cov = np.zeros((pose_fit.STATE, pose_fit.STATE))
        cov[pose_fit.OFFSET, pose_fit.OFFSET] = self.cov
        xy, yaw = self.learner.trust.noise
        body = np.array([*se2.unrotate(source.velocity[:2], source.pose.yaw), source.velocity[2]])
        noise = np.square([xy, xy, yaw]) + np.square(body * self.latency_sd)
        if source.gap > 0.05:
            noise = noise + np.square(np.array(GAP_ACCELERATION)[[0, 0, 1]] * source.gap**2 / 8)
        cov[pose_fit.NOISE, pose_fit.NOISE] = np.diag(noise)
        return mean, cov

    def _fit(
        self,
        found: Candidates,
        mean: Array,
        cov: Array,
        source: Array,
        prior_cov: Array,
        x0: Array,
    ) -> pose_fit.Fit | None:
        """Associate at the prior, fit, associate again at the fit and refit if that changed."""
        pairs, walls = associate(found, x0, prior_cov)
        if not walls:
            return None
        fitted = pose_fit.fit(mean, cov, source, pairs)
        again, walls_again = associate(found, fitted.pose, fitted.pose_cov)
        if walls_again and walls_again != walls:
            fitted = pose_fit.fit(mean, cov, source, again)
        return fitted

    def _consistent(self, fitted: pose_fit.Fit, mean: Array, cov: Array, near: int) -> bool:
        """The fit agrees with the prior and explains observations near settled walls.

        At least one, or most of them after the source jumped.
        """
        matched = sum(m2 <= CHI2_2DOF_999 for m2 in fitted.m2.tolist())
        if matched < (max(1, math.ceil(0.5 * near)) if self.suspect is not None else 1):
            return False
        d = pose_fit.difference(fitted.xi, mean)
        return compiled.pose_kernels().mahalanobis2(plain(cov, np.float64), d) <= CHI2_6DOF_999

    def _accept(
        self, fitted: pose_fit.Fit, x0: Array, prior_cov: Array, source: SourcePose, stamp: float
    ) -> Verdict:
        """The walls placed the frame near where the source said: carry on from there.

        How far they moved it, against how far the prior said they might, is what the source
        is worth (``TrustLearner``).
        """
        self.offset = fitted.xi[pose_fit.OFFSET].copy()
        carried = fitted.cov[pose_fit.OFFSET, pose_fit.OFFSET]
        self.cov = 0.5 * (carried + carried.T)
        self._alternative = None
        self.suspect = None
        moved = fitted.pose - x0
        moved[2] = se2.wrap(float(moved[2]))
        self.learner.add(moved, np.clip(np.diag(prior_cov - fitted.pose_cov), 0.0, None))
        self.noise.add(fitted.m2)
        self.counts.corrected += 1
        return Verdict(_as_pose(source.pose, stamp, fitted.pose, fitted.pose_cov), "corrected")

    def _recover(
        self, frame: Observations, source: SourcePose, wall_map: WallMap, x0: Array, near: int
    ) -> Verdict | None:
        """The walls contradict the source: where do they say the frame was? None if unclear."""
        alternative = self.alternative
        guess = None if alternative is None else se2.compose(source.pose.vector, alternative)
        cfg = self.config
        found = search_pose(frame, x0, guess, wall_map, near, cfg.min_obs, cfg.search)
        if found is None:
            return None
        pose, pose_cov = found
        self._remember(frame.stamp, pose, source.pose.vector)
        self.counts.recovered += 1
        placed = _as_pose(source.pose, frame.stamp, pose, pose_cov)
        return Verdict(placed, "recovered", start_walls=False)

    def _refused(self) -> Verdict:
        """The walls contradict the source and say nothing clear: nothing of the frame is mapped."""
        self.counts.refused += 1
        return Verdict(None, "refused", start_walls=False)

    def _remember(self, stamp: float, pose: Array, source: Array) -> None:
        """A recovered frame's offset; one that holds for ``ADOPT_AFTER`` s becomes the offset."""
        offset = se2.between(source, pose)
        alt = self._alternative
        if alt is not None and _close(alt[0], offset) and stamp - alt[2] < 0.5:
            self._alternative = (offset, alt[1], stamp)
            if stamp - alt[1] >= ADOPT_AFTER:
                self.offset = offset
                self._alternative = None
        else:
            self._alternative = (offset, stamp, stamp)

    @property
    def alternative(self) -> Array | None:
        """The offset of the last recovered frames, while they last: tried first next frame."""
        return None if self._alternative is None else self._alternative[0]

    def summary(self) -> dict[str, Any]:
        """For the map reply, ``wallmap status`` and ``wallmap up``: what the source is worth."""
        trust, c = self.learner.trust, self.counts
        return {
            "latency_s": round(self.latency, 4),
            "latency_fixed": self.config.latency is not None,
            "settled": self.settled,
            "latency_sd_s": round(self.latency_sd, 4),
            "heading_sd_deg": round(math.degrees(trust.noise[1]), 3),
            "position_sd_m": round(trust.noise[0], 4),
            "drift_deg_per_sqrt_s": round(math.degrees(trust.drift[1]), 3),
            "observation_noise_scale": round(self.noise.scale, 3),
            "offset": [round(float(v), 4) for v in self.offset],
            "frames_judged": c.judged,
            "frames_corrected": c.corrected,
            "frames_recovered": c.recovered,
            "frames_refused": c.refused,
            "frames_unjudged": c.unjudged,
        }

    def to_json(self) -> dict[str, Any]:
        """Everything it carries from frame to frame, for a state file.

        A restarted mapper then goes on exactly as this one would have: the frames it takes
        again from the history come out the same.
        """
        alternative = self._alternative
        if alternative is not None:
            alternative = (alternative[0].tolist(), *alternative[1:])
        return {
            "offset": self.offset.tolist(),
            "cov": self.cov.tolist(),
            "latency": self.latency,
            "latency_sd": self.latency_sd,
            "settled": self.settled,
            "stamp": self.stamp,
            "suspect": self.suspect,
            "jumped": self.jumped,
            "alternative": alternative,
            "learner": self.learner.to_json(),
            "noise": self.noise.to_json(),
            "turns": self.turns.to_json(),
            "jumps": self.jumps.to_json(),
            "counts": vars(self.counts).copy(),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any], config: JudgeConfig) -> PoseJudge:
        """The judge a state file kept (``to_json``); ValueError says what is wrong."""
        judge = cls(config)
        offset = np.asarray(data["offset"], dtype=float)
        cov = np.asarray(data["cov"], dtype=float)
        numbers = np.array([data["latency"], data["latency_sd"]], float)
        if offset.shape != (3,) or cov.shape != (3, 3):
            raise ValueError("the offset must hold 3 numbers, its covariance 3x3")
        if not all(np.isfinite(a).all() for a in (offset, cov, numbers)):
            raise ValueError("the pose judge's state must be finite")
        judge.offset, judge.cov = offset, cov
        if config.latency is None:
            judge.latency, judge.latency_sd = float(numbers[0]), float(numbers[1])
            judge.settled = bool(data["settled"])
            judge.turns.restore(data["turns"])
        judge.stamp = None if data["stamp"] is None else float(data["stamp"])
        judge.suspect = None if data["suspect"] is None else float(data["suspect"])
        judge.jumped = None if data["jumped"] is None else float(data["jumped"])
        alternative = data["alternative"]
        if alternative is not None:
            judge._alternative = (np.asarray(alternative[0], float), *map(float, alternative[1:]))
        judge.learner.restore(data["learner"])
        judge.noise.restore(data["noise"])
        judge.jumps.restore(data["jumps"])
        judge.counts = _Counts(**{k: int(v) for k, v in dict(data["counts"]).items()})
        return judge


def _close(a: Array, b: Array) -> bool:
    return math.hypot(a[0] - b[0], a[1] - b[1]) < 0.1 and abs(se2.wrap(a[2] - b[2])) < 0.05


def _as_pose(given: Pose, stamp: float, x: Array, cov: Array) -> Pose:
    """The source's pose moved to ``x``, stamped at the frame's instant (6-DoF extras kept)."""
    return replace(given, stamp=stamp, x=float(x[0]), y=float(x[1]), yaw=float(x[2]), cov=cov)


def sweep_widened(frame: Observations, source: SourcePose, scale: float = 1.0) -> Observations:
    """A frame captured over a sweep and not deskewed, its lines widened; then scaled.

    ``scale``: the judge's ``NoiseScale``, by which every covariance is multiplied.

    A spinning scanner sees each wall at another instant of its sweep; while the robot turns,
    its lines are turned and moved by up to the motion of the sweep. Without the beams' times
    that motion is unknown, so it is noise: uniform over the sweep, the robot-frame motion
    ``v T`` has variance ``(v T)^2 / 12``, which enters each line as pose noise does.
    """
    swept = frame.sweep > 0
    if not frame.walls or (not swept and scale == 1.0):
        return frame
    cov = np.array([w.cov for w in frame.walls])
    if swept:
        body = np.array([*se2.unrotate(source.velocity[:2], source.pose.yaw), source.velocity[2]])
        spread = np.diag(np.square(body * frame.sweep)) / 12.0
        z = np.array([w.closest for w in frame.walls])
        jac = wall_model.jacobian_pose_many(z, np.zeros_like(z), np.zeros(3))
        cov = cov + jac @ spread @ jac.transpose(0, 2, 1)
    if scale != 1.0:
        cov = cov * scale
    walls = [replace(w, cov=c) for w, c in zip(frame.walls, cov, strict=True)]
    return replace(frame, walls=walls)
