"""The source's poses as a live pose source would send them: a stream, ahead of the frames.

A pose source is judged against the walls by the mapper, which estimates its latency: the pose
that describes a frame's instant is the source's pose some tens of milliseconds later. So the
mapper needs the source's poses around and after each frame's stamp, not only one at it. The
player sends them on a 50 Hz grid up to ``LOOKAHEAD`` past the frame it sends next, as a
motion-capture system or a SLAM would have sent them by then.

Where the source has no pose (a tracker's dropout), none is made up: the stream leaves the gap
for the mapper to see, and the mapper judges a pose interpolated across it as the guess it is.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from wallmap.common.messages import Pose

POSE_PERIOD = 0.02  # s between the grid's poses
LOOKAHEAD = 0.6  # s past the next frame's stamp: more than any latency the mapper takes
DROPOUT = 0.1  # s from the nearest pose of the source: farther, a grid pose is not sent
SAME_STAMP = 1e-6  # s: a frame's stamp this close to a sent pose's is that stamp
AHEAD = 50  # grid poses worked out at once (a second of them): a seventh of one at a time

PosesAt = Callable[[NDArray[np.float64]], list[Pose | None]]


class PoseStream:
    """The poses of a source up to each frame's stamp plus ``LOOKAHEAD``, each sent once.

    Args:
        poses_at: The planar poses at some stamps, None where the source has none.
        stamps: The source's own pose stamps where it has a list of them (a topic, a TUM
            file), to leave its dropouts as gaps; None for tf, looked up as tf does.
    """

    def __init__(self, poses_at: PosesAt, stamps: NDArray[np.float64] | None = None) -> None:
        self._poses_at = poses_at
        self._stamps = stamps
        self._sent: float | None = None  # the newest grid stamp looked at
        self._newest: float | None = None  # the newest stamp sent
        self._ahead: dict[int, Pose | None] = {}  # grid poses worked out, by grid index

    def until(self, frame_stamp: float) -> list[Pose]:
        """The poses to send before the frame stamped ``frame_stamp``: the grid's, each once.

        The mapper interpolates a frame's pose between grid poses sent several frames before it,
        so which poses it has when the frame arrives never depends on which of two paths (poses
        straight to it, frames through the detector) was faster. Only where the source's poses
        end before the frame (the end of a run) is the frame's own pose sent, as the newest: the
        mapper waits for it, so that one cannot race either.
        """
        if self._sent is not None and frame_stamp < self._sent - 2 * LOOKAHEAD - 1.0:
            self._sent = self._newest = None  # played again from earlier (a seek back, a loop)
        horizon = frame_stamp + LOOKAHEAD
        start = frame_stamp - LOOKAHEAD  # after a seek forward, no more than that back
        if self._sent is not None:
            start = max(start, self._sent)
        first, end = math.floor(start / POSE_PERIOD) + 1, math.floor(horizon / POSE_PERIOD) + 1
        poses = [pose for k in range(first, end) if (pose := self._grid_pose(k)) is not None]
        self._sent = max(self._sent or start, POSE_PERIOD * (end - 1) if end > first else start)
        newest = poses[-1].stamp if poses else self._newest
        if newest is None or frame_stamp > newest + SAME_STAMP:
            (own,) = self._poses(np.array([frame_stamp]))
            if own is not None:
                poses.append(own)
                newest = frame_stamp
        self._newest = newest
        return poses

    def _grid_pose(self, k: int) -> Pose | None:
        """The grid's ``k``-th pose (at ``k * POSE_PERIOD``), the next AHEAD worked out with it."""
        if k not in self._ahead:
            ks = np.arange(k, k + AHEAD)
            self._ahead = dict(zip(ks.tolist(), self._poses(POSE_PERIOD * ks), strict=True))
        return self._ahead[k]

    def _poses(self, stamps: NDArray[np.float64]) -> list[Pose | None]:
        """The source's poses at ``stamps``, None in a dropout or beyond its poses."""
        return [
            pose if self._covered(stamp) else None
            for stamp, pose in zip(stamps.tolist(), self._poses_at(stamps), strict=True)
        ]

    def _covered(self, stamp: float) -> bool:
        """Whether the source has a pose within ``DROPOUT`` of ``stamp``."""
        if self._stamps is None:
            return True
        i = int(np.searchsorted(self._stamps, stamp))
        near = [self._stamps[j] for j in (i - 1, i) if 0 <= j < len(self._stamps)]
        return any(abs(s - stamp) <= DROPOUT for s in near)


class PosedSource(Protocol):
    """What a stream is made from: a bag or a TUM folder."""

    def planar_poses_at(self, stamps: NDArray[np.float64]) -> list[Pose | None]:
        """The planar poses (levelled, as its frames') at some stamps, None where it has none."""
        ...

    @property
    def pose_stamps(self) -> NDArray[np.float64] | None:
        """The source's own pose stamps, where it has a list of them."""
        ...


def stream_of(source: PosedSource) -> PoseStream:
    """The pose stream of a source: its poses levelled and made planar as its frames' are."""
    return PoseStream(source.planar_poses_at, source.pose_stamps)
