"""A frame's pose from the walls it saw, with the pose source's pose as the prior. Pure.

A pose source's pose is a measurement, not the truth. Shifted by its latency (``common.latency``
estimates it), it is still off by an error that persists from frame to frame (``D``: a tracker's
calibration, a drifting odometry) and by noise fresh every frame (``w``). The pose of a frame is
modelled as

    x = s * D * w

with ``s`` the source's pose at the frame's instant and ``*`` the composition of ``common.se2``.
Both errors are in the robot's frame, as a mount's or a tracker's body calibration is: an error of
the source's world frame (a drifting odometry's ``map -> odom``) is one in the robot's frame that
changes as the robot moves, which the offset's drift takes up; in the world frame instead, a
heading error would move the pose by its distance from the map's origin, and every correction of
the heading far from it would be one of the position too. The state ``xi = [D (3), w (3)]`` has
a Gaussian prior: ``D`` carried from frame to frame, ``w`` fresh every frame; they differ by
their priors alone, which is what keeps a persistent error apart from noise.

The frame's observations of mapped walls measure ``x`` through the wall model
(``common.wall_model``), each with the noise of its line fit and of the wall's estimate,
``R + H P H^T``. The fit is the iterated EKF update (Gauss-Newton on the posterior): a heading off
by 15 degrees is far from linear.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wallmap.common import compiled, se2
from wallmap.common.compiled import plain
from wallmap.common.se2 import Array

STATE = 6
OFFSET = slice(0, 3)  # D: the source's error that persists, in the robot's frame
NOISE = slice(3, 6)  # w: this frame's own error, in the robot's frame
ANGLES = (2, 5)
STEP_TOLERANCE = 1e-3  # m, rad: a Gauss-Newton step this small is the last one needed


@dataclass(frozen=True)
class Pairs:
    """Observations of one frame and the mapped walls they were associated with.

    Attributes:
        z: The observed closest points (u, v) in the robot frame, (n, 2).
        r: Their covariances, (n, 2, 2).
        s: The walls' states (closest points to their anchors), (n, 2).
        anchor: The walls' anchors, (n, 2).
        p: The walls' covariances, (n, 2, 2).
    """

    z: Array
    r: Array
    s: Array
    anchor: Array
    p: Array

    def __len__(self) -> int:
        return len(self.z)

    def subset(self, keep: Array) -> Pairs:
        """The pairs a boolean mask keeps."""
        return Pairs(self.z[keep], self.r[keep], self.s[keep], self.anchor[keep], self.p[keep])


@dataclass(frozen=True)
class Fit:
    """The fitted state of one frame.

    Attributes:
        xi: The posterior mean of ``[D, w]``.
        cov: Its covariance (6x6; zero rows and columns for what was held fixed).
        pose: The frame's pose ``x`` at ``xi``.
        pose_cov: Its covariance (3x3).
        m2: Each pair's squared Mahalanobis distance at the fit, under ``R + H P H^T``.
    """

    xi: Array
    cov: Array
    pose: Array
    pose_cov: Array
    m2: Array


def frame_pose(xi: Array, source: Array) -> tuple[Array, Array]:
    """The frame's pose ``x = s * D * w`` and its Jacobian d x / d xi (3x6)."""
    moved = se2.compose(source, xi[OFFSET])
    x = se2.compose(moved, xi[NOISE])
    outer_a, outer_b = se2.compose_jacobians(moved, xi[NOISE])
    _, inner_b = se2.compose_jacobians(source, xi[OFFSET])
    jac = np.empty((3, STATE))
    jac[:, OFFSET] = outer_a @ inner_b
    jac[:, NOISE] = outer_b
    return x, jac


def difference(a: Array, b: Array) -> Array:
    """``a - b`` for states, the angles wrapped."""
    d = a - b
    for i in ANGLES:
        d[i] = se2.wrap(float(d[i]))
    return d


def fit(
    mean: Array,
    cov: Array,
    source: Array,
    pairs: Pairs,
    active: Array | None = None,
    iterations: int = 5,
) -> Fit:
    """The frame's state given its prior ``(mean, cov)`` and the walls it saw.

    Args:
        mean: Prior mean of ``[D, w]``.
        cov: Prior covariance (6x6).
        source: The source's pose at the frame's instant (its latency taken off).
        pairs: The frame's observations and their walls (none: the prior is the answer).
        active: Which states are estimated (a boolean mask); the others stay at their mean.
            Default: all.
        iterations: Gauss-Newton steps at most; it stops sooner once a step is small
            (``STEP_TOLERANCE``).
    """
    active = np.ones(STATE, dtype=bool) if active is None else active
    # Gauss-Newton over a dozen pairs is some fifty numpy calls an iteration: compiled, as one
    # pass (``common.pose_kernels``; its tests hold it to the numpy it replaced).
    xi, posterior, x, pose_cov, m2 = compiled.pose_kernels().fit(
        plain(mean, np.float64),
        plain(cov, np.float64),
        plain(source, np.float64),
        tuple(plain(a, np.float64) for a in (pairs.z, pairs.r, pairs.s, pairs.anchor, pairs.p)),
        plain(active, np.bool_),
        iterations,
        STEP_TOLERANCE,
    )
    return Fit(xi, posterior, x, pose_cov, m2)
