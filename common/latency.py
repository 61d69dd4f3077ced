"""The time offset between a pose source and the sensor, from how both turn. Pure.

A pose source is late: its pose of an instant is stamped some tens of milliseconds later (a
motion-capture system's processing, a SLAM's, a sensor stamped at the end of its sweep rather
than its start). While the robot turns at a steady rate the offset is a constant heading error,
indistinguishable from a bias; when the turn rate changes, the sensor and the source turn at
different instants. So the offset is where the two turning histories agree best: the temporal
calibration that Kalibr initialises by correlating angular rates, done here with the sensor's
own lines. Between two consecutive frames every line the robot sees turns by minus the robot's
turn (moving does not turn a line), which gives the sensor's turn; the source's over the same
interval, shifted by a candidate latency, is read off its poses. The latency that explains the
sensor's turns best (a robust least-squares fit over a grid, refined by a parabola) is the
estimate, once the turns say it clearly.
"""

from __future__ import annotations

import collections
import math
import statistics
from dataclasses import dataclass
from typing import Any

import numpy as np

from wallmap.common import compiled
from wallmap.common.compiled import plain
from wallmap.common.se2 import Array

MATCH_ANGLE = math.radians(10.0)  # consecutive frames' lines farther apart are not one line
MATCH_OFFSET = 0.3  # m: ...nor lines whose distances from the robot differ more
TURN_FLOOR = math.radians(0.02)  # no frame-to-frame turn is seen better than this
OUTLIER = 3.0  # residuals beyond this many sigma are outliers: a mismatched line, a glitch
SMOOTH = 0.1  # s: the source's heading is averaged over this, as the lines see turns
GRID = 0.01  # s: the source's heading is resampled on this grid to be averaged
CHAIN = 4  # consecutive frame-to-frame turns added into one
# The fit's cost rises this much 20 ms either side of its minimum, and is this much higher at
# every latency farther off: a clear estimate.
CLEAR = 4.0


@dataclass(frozen=True)
class Estimate:
    """A latency (s) and its standard deviation (s), from ``turns`` frame-to-frame turns."""

    latency: float
    sd: float
    turns: int


def line_turn(before: Array, after: Array) -> float | None:
    """The robot's turn between two frames (rad), from the closest points of their lines.

    Each line of ``after`` (n, 2: closest points (u, v) in the robot frame) is matched to the
    line of ``before`` nearest in direction, if within ``MATCH_ANGLE`` and ``MATCH_OFFSET``;
    a line turns by minus the robot's turn. None without a match.
    """
    if not len(before) or not len(after):
        return None
    turns = compiled.pose_kernels().line_turns(
        plain(before, np.float64), plain(after, np.float64), MATCH_ANGLE, MATCH_OFFSET
    )
    return -statistics.median(turns.tolist()) if len(turns) else None


def _chained(turns: Array) -> tuple[Array, Array, Array]:
    """Turns over CHAIN consecutive frame intervals that follow one another without a gap.

    The source's jitter is the same over a long interval as over a short one, the turn it is
    compared with grows with the interval: longer intervals see the latency more clearly.
    """
    t0, t1, turn = turns[:, 0], turns[:, 1], turns[:, 2]
    n = len(turns) - CHAIN + 1
    if n < 1:
        return t0[:0], t1[:0], turn[:0]
    starts = np.arange(n)
    joined = np.ones(n, dtype=bool)
    for k in range(CHAIN - 1):
        joined &= t1[starts + k] == t0[starts + k + 1]
    total = sum(turn[starts + k] for k in range(CHAIN))
    keep = starts[joined]
    return t0[keep], t1[keep + CHAIN - 1], total[joined]


def _smoothed(stamps: Array, yaw: Array) -> tuple[Array, Array]:
    """The source's heading on a ``GRID`` grid, averaged over ``SMOOTH``.

    A noisy tracker's heading jitters by more than the latency's effect on one turn, the
    average does not (and a symmetric average shifts nothing in time).
    """
    grid = np.arange(stamps[0], stamps[-1], GRID)
    if len(grid) < 3:
        return stamps, yaw
    resampled = np.interp(grid, stamps, yaw)
    half = round(SMOOTH / (2 * GRID))  # an odd width, centred: an even one would shift by 5 ms
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    padded = np.pad(resampled, (half, half), mode="edge")
    return grid, np.convolve(padded, kernel, mode="valid")


class LatencyEstimator:
    """The frames' turns as their lines say, and the latency that fits the source's best.

    Args:
        max_latency: Latencies looked for lie within this (s) either way.
        window: Frame-to-frame turns kept.
        step: The grid's step (s), refined by a parabola.
    """

    def __init__(self, max_latency: float = 0.25, window: int = 600, step: float = 0.005) -> None:
        self.grid = np.arange(-max_latency, max_latency + step / 2, step)
        self._turns: collections.deque[tuple[float, float, float]] = collections.deque(
            maxlen=window
        )
        self._last: tuple[float, Array] | None = None
        self.added = 0  # turns ever added: the kept ones stop growing in number once full

    def add(self, stamp: float, closest: Array) -> None:
        """A frame's stamp and its lines' closest points (n, 2), in the robot frame."""
        if self._last is not None and 0.0 < stamp - self._last[0] < 0.5:
            turn = line_turn(self._last[1], closest)
            if turn is not None:
                self._turns.append((self._last[0], stamp, turn))
                self.added += 1
        elif self._last is not None and stamp < self._last[0]:
            self._turns.clear()  # time went back: another run
        self._last = (stamp, closest)

    def to_json(self) -> dict[str, Any]:
        """The turns kept and the last frame's lines (a state file's)."""
        last = None if self._last is None else [self._last[0], self._last[1].tolist()]
        return {"turns": [list(t) for t in self._turns], "last": last, "added": self.added}

    def restore(self, data: dict[str, Any]) -> None:
        """Go on exactly where ``to_json`` left off; ValueError says what is wrong."""
        turns = np.asarray(data["turns"], dtype=float).reshape(-1, 3)
        last = data["last"]
        closest = None if last is None else np.asarray(last[1], dtype=float).reshape(-1, 2)
        if not np.isfinite(turns).all() or (closest is not None and not np.isfinite(closest).all()):
            raise ValueError("the latency's turns must be finite")
        self._turns.clear()
        self._turns.extend((a, b, c) for a, b, c in turns.tolist())
        self._last = None if closest is None else (float(last[0]), closest)
        self.added = int(data.get("added", len(self._turns)))  # older state files: as kept

    def __len__(self) -> int:
        return len(self._turns)

    def span(self) -> tuple[float, float] | None:
        """The stamps the kept turns cover, for the source's poses to be read over."""
        if not self._turns:
            return None
        return self._turns[0][0], self._turns[-1][1]

    def estimate(self, stamps: Array, yaw: Array) -> Estimate | None:
        """The latency that best explains the turns, None until the turns say it clearly.

        ``yaw``: the source's heading (unwrapped) at increasing ``stamps``. Only the turns these
        poses cover at every latency looked for are read: how many poses a source has sent
        beyond them is a matter of timing (how far ahead of the frames it runs), and must
        change nothing, nor may a turn be read off the poses' clamped end.
        """
        if len(self._turns) < 20 or len(stamps) < 2:
            return None
        t0, t1, seen = _chained(np.array(self._turns))
        margin = SMOOTH / 2 + GRID  # the average's edge, where it is padded
        covered = (t0 + self.grid[0] - margin >= stamps[0]) & (
            t1 + self.grid[-1] + margin <= stamps[-1]
        )
        t0, t1, seen = t0[covered], t1[covered], seen[covered]
        if len(t0) < 10:
            return None
        grid, smooth = _smoothed(stamps, yaw)
        # At each latency, the source's turns against the lines', their residuals scaled by how
        # well the lines see a turn (the MAD where they fit best); an outlier costs the same
        # at any latency.
        cost = compiled.pose_kernels().turn_costs(
            *(plain(a, np.float64) for a in (t0, t1, seen, self.grid, grid, smooth)),
            TURN_FLOOR,
            OUTLIER,
        )
        best = int(np.argmin(cost))
        if best in (0, len(self.grid) - 1):
            return None  # at the edge of what is looked for: not found
        step = float(self.grid[1] - self.grid[0])
        near = max(1, round(0.02 / step))
        rise = min(cost[max(best - near, 0)], cost[min(best + near, len(cost) - 1)]) - cost[best]
        # Clear: the cost rises either side, and no latency farther off fits nearly as well
        # (turns that say two latencies, as a noisy tracker's can, say neither).
        far = np.abs(np.arange(len(cost)) - best) > near
        if rise < CLEAR or cost[far].min(initial=np.inf) - cost[best] < CLEAR:
            return None
        low, mid, high = cost[best - 1], cost[best], cost[best + 1]
        curvature = (low - 2 * mid + high) / step**2
        shift = 0.5 * step * (low - high) / (low - 2 * mid + high) if curvature > 0 else 0.0
        # Each turn is in CHAIN overlapping windows: as many times less independent evidence.
        sd = math.sqrt(CHAIN / curvature) if curvature > 0 else step
        return Estimate(float(self.grid[best] + shift), max(sd, 1e-4), len(self._turns))
