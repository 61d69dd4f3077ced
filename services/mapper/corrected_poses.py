"""``{prefix}/pose/corrected`` and ``{prefix}/pose/correction`` under ``--slam``."""

from __future__ import annotations

import logging

import zenoh

from wallmap.common.messages import Pose, pack
from wallmap.common.transport import Keys
from wallmap.services.mapper.pose_correction import PoseCorrector


class CorrectedPoses:
    """``{prefix}/pose/corrected`` and ``{prefix}/pose/correction`` (map -> odom) under --slam.

    Published from the observations thread, frame by frame; DROP, so a slow reader never holds
    the map back. It also says when the pose runs on odometry alone, once per stretch.
    """

    ALONE_AFTER = 15  # frames without a wall fixing the pose before it is said

    def __init__(self, session: zenoh.Session, keys: Keys, log: logging.Logger) -> None:
        self._log = log
        drop = zenoh.CongestionControl.DROP
        self._pose = session.declare_publisher(keys.pose_corrected, congestion_control=drop)
        self._correction = session.declare_publisher(keys.pose_correction, congestion_control=drop)
        self._alone_since: int | None = None

    def publish(self, corrector: PoseCorrector, pose: Pose, odom_frame: str) -> None:
        """Say the corrected pose of a frame, and the correction that takes odometry there."""
        self._pose.put(pack(pose))
        if (correction := corrector.correction(pose.stamp, odom_frame)) is not None:
            self._correction.put(pack(correction))
        if corrector.streak == 0:
            if self._alone_since is not None and self._alone_since >= self.ALONE_AFTER:
                self._log.info("walls fix the pose again after %d frames", self._alone_since)
            self._alone_since = None
            return
        self._alone_since = corrector.streak
        if corrector.streak == self.ALONE_AFTER:
            self._log.warning(
                "running on odometry alone: no mapped wall fixed the pose for %d frames",
                self.ALONE_AFTER,
            )
