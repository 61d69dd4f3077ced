"""What a pose source is worth, and how noisy the observations are, learnt from the walls. Pure.

Each frame the walls correct the source's pose by some ``d``; the filter predicted that correction
to have the covariance ``C = P_prior - P_post`` (the prior's uncertainty less what is left of it).
If the source is as good as assumed, ``d^2 / C`` is 1 on average; larger, the source is worse than
assumed (the prior too narrow: good observations would be refused), smaller, better (the prior too
wide: the walls' own noise would be taken for the source's). Scaling the assumed noise by that
ratio, a little at a time, is covariance matching (Mehra 1972; Myers and Tapley 1976): it settles
where the prior is what the source is worth. The ratios are clipped, so that a glitch the walls
caught does not teach the source is worse than it is.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from typing import Any

import numpy as np

from wallmap.common.rolling_median import RollingMedian
from wallmap.common.se2 import Array

OUTLIER = 9.0  # a correction's squared ratio to its predicted variance counts at most this


@dataclass(frozen=True)
class Trust:
    """A source's error model: frame-by-frame noise and drift, position (m) and heading (rad).

    Attributes:
        noise: Standard deviations of the noise of one pose, (xy, yaw).
        drift: Standard deviations the source's offset wanders per square root of a second,
            (xy, yaw): a drifting odometry's, a tracker's calibration's.
    """

    noise: tuple[float, float]
    drift: tuple[float, float]


class TrustLearner:
    """The assumed ``Trust`` scaled, per axis, until the corrections are what it predicts.

    Two numbers per axis (position, heading). The noise is scaled until the corrections' size
    matches their predicted covariance (covariance matching, above). The drift is scaled by
    how the corrections follow one another: a source that drifts is corrected the same way
    frame after frame (their normalised corrections correlated from one frame to the next),
    which says the offset the judge carries is not following the source fast enough; white
    corrections say it follows. This is the whiteness of the innovations (Mehra 1970), read
    as the step of an adjustment rather than a test.

    Args:
        assumed: The source's error model before anything is learnt.
        floor: The least noise and drift ever learnt: no pose source is exact, and a filter
            that believes one is refuses its next small error.
        every: Frames between two adjustments; each uses the frames since the last one.
        limit: The assumed noise is scaled by at most this...
        drift_limit: ...and the drift by at most this: a drift a tenth of the assumed noise
            every second would let the offset take up any error the walls leave unseen.
    """

    WHITE = 0.1  # lag-one correlation of the corrections below which the drift shrinks

    def __init__(
        self,
        assumed: Trust,
        floor: Trust,
        every: int = 10,
        limit: float = 100.0,
        drift_limit: float = 1.0,
    ) -> None:
        self.assumed, self.floor, self.every, self.limit = assumed, floor, every, limit
        self.drift_limit = drift_limit
        self.factor = (1.0, 1.0)  # of the noise's standard deviations (xy, yaw)
        self.drift = (1.0, 1.0)  # of the drift's
        self.trust = assumed
        self.seen = 0
        self._frames: list[tuple[float, float, Array]] = []  # ratios and normalised corrections

    def to_json(self) -> dict[str, Any]:
        """All it has learnt and is learning from, as plain numbers (a state file's)."""
        return {
            "noise_factor": list(self.factor),
            "drift_factor": list(self.drift),
            "seen": self.seen,
            "frames": [[a, b, n.tolist()] for a, b, n in self._frames],
        }

    def restore(self, data: dict[str, Any]) -> None:
        """Go on exactly where ``to_json`` left off; ValueError says what is wrong."""
        self.factor = _finite_pair(data["noise_factor"])
        self.drift = _finite_pair(data["drift_factor"])
        self.seen = int(data["seen"])
        self._frames = [(float(a), float(b), _finite(n, 3)) for a, b, n in data["frames"]]
        self._set_trust()

    def _set_trust(self) -> None:
        a, (n0, n1), (d0, d1) = self.assumed, self.factor, self.drift
        self.trust = Trust((a.noise[0] * n0, a.noise[1] * n1), (a.drift[0] * d0, a.drift[1] * d1))

    def add(self, correction: Array, predicted: Array) -> None:
        """One frame: the walls' correction (x, y, yaw) and its predicted variances."""
        variance = np.maximum(np.asarray(predicted, float), 1e-18)
        xy = float(correction[0] ** 2 + correction[1] ** 2) / float(variance[0] + variance[1])
        yaw = float(correction[2] ** 2) / float(variance[2])
        normalised = np.asarray(correction, float) / np.sqrt(variance)
        self._frames.append((xy, yaw, normalised))
        self.seen += 1
        if len(self._frames) >= self.every:
            self._adjust()

    def _adjust(self) -> None:
        ratios = np.array([(a, b) for a, b, _ in self._frames])
        u = np.array([n for _, _, n in self._frames])
        self._frames.clear()
        lag = [(u[1:, :2] * u[:-1, :2]).sum(axis=1), u[1:, 2] * u[:-1, 2]]
        power = [(u[:, :2] ** 2).sum(axis=1), u[:, 2] ** 2]
        noise, drift = [], []
        for axis in (0, 1):
            # The ratios' mean is 1 when the model is right; large ones (a glitch the walls
            # caught) are clipped at 3 sigma. A variance ratio, so a standard deviation's by
            # its square root; then halfway.
            step = float(np.mean(np.minimum(ratios[:, axis], OUTLIER))) ** 0.25
            low = self.floor.noise[axis] / self.assumed.noise[axis]
            noise.append(float(np.clip(self.factor[axis] * step, low, self.limit)))
            correlation = float(np.mean(lag[axis])) / max(float(np.mean(power[axis])), 1e-18)
            low = self.floor.drift[axis] / self.assumed.drift[axis]
            grown = self.drift[axis] * math.exp(0.5 * (np.clip(correlation, -1, 1) - self.WHITE))
            drift.append(float(np.clip(grown, low, self.drift_limit)))
        self.factor, self.drift = (noise[0], noise[1]), (drift[0], drift[1])
        self._set_trust()


class NoiseScale:
    """How much noisier the observations are than their line fits say, learnt from the fits.

    A line fitted to hundreds of scan points knows its offset to a millimetre; the wall it saw
    is not that straight, the scanner's sweep bent it, the scanner's mount is off by a little.
    At a frame's fitted pose, each observation's squared Mahalanobis distance to its wall would
    have the median of a chi-square with 2 degrees of freedom if its covariance were right;
    the median over recent frames, against that, is the factor the covariances are short by.

    Args:
        window: Frames kept.
        limits: The factor is kept within these.
    """

    MEDIAN_2DOF = 1.386294  # the median of a chi-square with 2 degrees of freedom

    def __init__(self, window: int = 200, limits: tuple[float, float] = (1.0, 100.0)) -> None:
        self.limits = limits
        self.scale = 1.0
        self._targets = RollingMedian(window)

    def to_json(self) -> dict[str, Any]:
        """The factor and the frames it comes from (a state file's)."""
        return {"scale": self.scale, "targets": list(self._targets)}

    def restore(self, data: dict[str, Any]) -> None:
        """Go on exactly where ``to_json`` left off; ValueError says what is wrong."""
        targets = _finite(data["targets"], None)
        self.scale = float(_finite([data["scale"]], 1)[0])
        self._targets.clear()
        self._targets.extend(targets.tolist())

    def add(self, m2: Array) -> None:
        """A frame's distances, computed with the covariances scaled by ``scale``."""
        if len(m2) < 2:
            return
        self._targets.add(self.scale * statistics.median(m2.tolist()) / self.MEDIAN_2DOF)
        if len(self._targets) >= 5:
            low, high = self.limits
            self.scale = min(max(self._targets.median(), low), high)


class JumpDetector:
    """Whether a pose source jumped: moved between two frames as no robot moves.

    Each frame's pose is predicted from the two before it (at the velocity between them); the
    deviation is compared with the deviations seen lately (their median absolute deviation),
    so a noisy source's jitter is not a jump and a precise source's small slip is. A jump is
    where a tracker swapped to a wrong solution, or back; between two jumps it may be wrong
    throughout, which only the walls can tell.

    Args:
        factor: A deviation this many robust standard deviations above is a jump...
        least: ...and at least this much (m, rad).
        window: Deviations kept.
    """

    def __init__(
        self,
        factor: float = 8.0,
        least: tuple[float, float] = (0.05, math.radians(2.0)),
        window: int = 200,
    ) -> None:
        self.factor, self.least = factor, least
        self._last: list[tuple[float, Array]] = []  # the two frames before, oldest first
        self._xy, self._yaw = RollingMedian(window), RollingMedian(window)

    def to_json(self) -> dict[str, Any]:
        """The frames before and the deviations seen lately (a state file's)."""
        return {
            "last": [[t, p.tolist()] for t, p in self._last],
            "deviations": [list(d) for d in zip(self._xy, self._yaw, strict=True)],
        }

    def restore(self, data: dict[str, Any]) -> None:
        """Go on exactly where ``to_json`` left off; ValueError says what is wrong."""
        self._last = [(float(t), _finite(p, 3)) for t, p in data["last"]]
        deviations = [_finite_pair(d) for d in data["deviations"]]
        self._xy.clear()
        self._yaw.clear()
        self._xy.extend(xy for xy, _ in deviations)
        self._yaw.extend(yaw for _, yaw in deviations)

    def add(self, stamp: float, pose: Array) -> bool:
        """The source's pose (x, y, yaw) at a frame; whether it jumped there."""
        pose = np.asarray(pose, float)
        history, self._last = self._last, [*self._last[-1:], (stamp, pose)]
        if len(history) < 2 or not 0.0 < stamp - history[1][0] < 1.0:
            return False
        (t0, p0), (t1, p1) = history
        if not 0.0 < t1 - t0 < 1.0:
            return False
        step = p1 - p0
        step[2] = math.remainder(step[2], 2 * math.pi)
        predicted = p1 + step * (stamp - t1) / (t1 - t0)
        xy = math.hypot(pose[0] - predicted[0], pose[1] - predicted[1])
        yaw = abs(math.remainder(pose[2] - predicted[2], 2 * math.pi))
        jumped = False
        if len(self._xy) >= 10:
            scale_xy, scale_yaw = 1.4826 * self._xy.median(), 1.4826 * self._yaw.median()
            jumped = xy > max(self.factor * scale_xy, self.least[0]) or yaw > max(
                self.factor * scale_yaw, self.least[1]
            )
        if not jumped:
            self._xy.add(xy)
            self._yaw.add(yaw)
        return jumped


def _finite(values: Any, size: int | None) -> Array:
    """Numbers read back from a state file: finite, and ``size`` of them if given."""
    array = np.asarray(values, dtype=float).reshape(-1)
    if (size is not None and array.shape != (size,)) or not np.isfinite(array).all():
        raise ValueError(f"expected {size or 'some'} finite numbers, got {values!r:.80}")
    return array


def _finite_pair(values: Any) -> tuple[float, float]:
    a, b = _finite(values, 2).tolist()
    return a, b
