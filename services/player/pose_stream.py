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
from wallmap.services.player.placement import Placement

POSE_PERIOD = 0.02  # s between the grid's poses
LOOKAHEAD = 0.6  # s past the next frame's stamp: more than any latency the mapper takes
DROPOUT = 0.1  # s from the nearest pose of the source: farther, a grid pose is not sent
SAME_STAMP = 1e-6  # s: a frame's stamp this close to a sent pose's is that stamp


class PoseStream:
    """The poses of a source up to each frame's stamp plus ``LOOKAHEAD``, each sent once.

    Args:
        pose_at: The planar pose at a stamp, or None where the source has none.
        stamps: The source's own pose stamps where it has a list of them (a topic, a TUM
            file), to leave its dropouts as gaps; None for tf, looked up as tf does.
    """

    def __init__(
        self,
        pose_at: Callable[[float], Pose | None],
        stamps: NDArray[np.float64] | None = None,
    ) -> None:
        self._pose_at = pose_at
        self._stamps = stamps
        self._sent: float | None = None  # the newest grid stamp looked at
        self._newest: float | None = None  # the newest stamp sent

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
        grid = POSE_PERIOD * np.arange(
            math.floor(start / POSE_PERIOD) + 1, math.floor(horizon / POSE_PERIOD) + 1
        )
        poses = [pose for stamp in grid.tolist() if (pose := self._pose(stamp)) is not None]
        self._sent = max(self._sent or start, float(grid[-1]) if len(grid) else start)
        newest = poses[-1].stamp if poses else self._newest
        if newest is None or frame_stamp > newest + SAME_STAMP:
            own = self._pose(frame_stamp)
            if own is not None:
                poses.append(own)
                newest = frame_stamp
        self._newest = newest
        return poses

    def _pose(self, stamp: float) -> Pose | None:
        """The source's pose at ``stamp``, or None in a dropout or beyond its poses."""
        return self._pose_at(stamp) if self._covered(stamp) else None

    def _covered(self, stamp: float) -> bool:
        """Whether the source has a pose within ``DROPOUT`` of ``stamp``."""
        if self._stamps is None:
            return True
        i = int(np.searchsorted(self._stamps, stamp))
        near = [self._stamps[j] for j in (i - 1, i) if 0 <= j < len(self._stamps)]
        return any(abs(s - stamp) <= DROPOUT for s in near)


class PosedSource(Protocol):
    """What a stream is made from: a bag or a TUM folder."""

    placement: Placement

    def pose_at(self, stamp: float) -> Pose | None:
        """The 6-DoF pose at a stamp, or None."""
        ...

    @property
    def pose_stamps(self) -> NDArray[np.float64] | None:
        """The source's own pose stamps, where it has a list of them."""
        ...


def stream_of(source: PosedSource) -> PoseStream:
    """The pose stream of a source: its poses levelled and made planar as its frames' are."""
    identity = np.eye(4)
    return PoseStream(
        lambda stamp: source.placement.place(source.pose_at(stamp), identity)[0],
        source.pose_stamps,
    )
