"""The source's poses as a live pose source would send them: a stream, ahead of the frames.

A pose source is judged against the walls by the mapper, which estimates its latency: the pose
that describes a frame's instant is the source's pose some tens of milliseconds later. So the
mapper needs the source's poses around and after each frame's stamp, not only one at it. The
player sends them on a 50 Hz grid (and at every frame's stamp), up to ``LOOKAHEAD`` past the frame
it sends next, as a motion-capture system or a SLAM would have sent them by then.

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
SAME_STAMP = 1e-6  # s: a frame's stamp this close to a grid stamp is that stamp (sent once)


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
        self._sent: float | None = None  # the newest stamp sent

    def until(self, frame_stamp: float) -> list[Pose]:
        """The poses to send before the frame stamped ``frame_stamp``: its own, then the grid's.

        The frame's own pose comes first: the mapper's buffer takes poses in any order. Each
        stamp is sent once: a frame stamped on the grid where the grid has been sent already
        has its pose sent with it.
        """
        if self._sent is not None and frame_stamp < self._sent - 2 * LOOKAHEAD - 1.0:
            self._sent = None  # played again from earlier (a seek back, a loop)
        horizon = frame_stamp + LOOKAHEAD
        start = frame_stamp - LOOKAHEAD  # after a seek forward, no more than that back
        if self._sent is not None:
            start = max(start, self._sent)
        grid = POSE_PERIOD * np.arange(
            math.floor(start / POSE_PERIOD) + 1, math.floor(horizon / POSE_PERIOD) + 1
        )
        grid = grid[np.abs(grid - frame_stamp) > SAME_STAMP]  # the frame's own is sent instead
        on_grid = abs(frame_stamp - POSE_PERIOD * round(frame_stamp / POSE_PERIOD)) <= SAME_STAMP
        sent = on_grid and self._sent is not None and frame_stamp <= self._sent + SAME_STAMP
        poses = []
        for stamp in ([] if sent else [frame_stamp]) + grid.tolist():
            pose = self._pose_at(stamp) if self._covered(stamp) else None
            if pose is not None:
                poses.append(pose)
        self._sent = max(self._sent or start, float(grid[-1]) if len(grid) else start)
        return poses

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
