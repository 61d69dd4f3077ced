"""The mapper's intake: each frame's observations once, in frame order, then held for its pose.

The policy the mapper lives by, apart from Zenoh and from the clock (every call is given
``now``, so it is tested step by step):

- **Order.** Observations are taken once each and in each player run's frame order
  (``InOrder``): history can bring one twice or late, and a gap waits ``gap_wait`` seconds for
  it to come, then is given up and counted as lost. A frame that came again is acknowledged
  again (its acknowledgement was lost on the way).
- **Poses.** A frame waits for the pose that covers its stamp, at most ``pose_wait`` seconds,
  then is dropped and counted (``pose_timeout``; ``no_pose`` when the source has none near it).
  A frame the detector skipped (behind in real time) is counted as such.
- **Backlog.** At most MAX_PENDING frames wait for poses: when poses are that far behind, the
  oldest gives way (``backlog``), so the mapper never stops reading its channel.
- **Progress.** Every frame taken or dropped moves its run's progress, the acknowledgement a
  ``--fast`` player paces itself by.
"""

from __future__ import annotations

import collections
from collections.abc import Callable
from typing import TYPE_CHECKING

from wallmap.common.codec import MessageError
from wallmap.common.frame_order import InOrder
from wallmap.common.messages import Observations, Pose, unpack_observations
from wallmap.services.mapper.core import BACKLOG, DROP_REASONS, UPDATE_FRAMES, MapperCore
from wallmap.services.mapper.pose_buffer import Lookup, SourcePose

if TYPE_CHECKING:
    from wallmap.common.runtime import Stats

MAX_PENDING = 2048  # observations waiting for poses (a few KB each)


class Intake:
    """Observations in, in frame order; each integrated into ``core``'s map once its pose is known.

    ``on_pose(pose, odom_frame)`` is told each frame's corrected pose under ``--slam`` (the
    service publishes it).
    """

    def __init__(
        self,
        core: MapperCore,
        pose_wait: float,
        gap_wait: float,
        on_pose: Callable[[Pose, str], None] | None = None,
    ) -> None:
        self.core = core
        self.pose_wait = pose_wait
        self.on_pose = on_pose
        self.pending: collections.deque[tuple[float, Observations]] = collections.deque()
        self.poses_seen = 0  # the core's pose count when the head last found no pose for it
        with core.lock:  # runs restored from the state file go on from where they stood
            self.order = InOrder(core.progress.runs.values(), gap_wait=gap_wait)

    @property
    def idle(self) -> bool:
        """Nothing waits: neither for a pose nor for a gap in a run to fill."""
        return not self.pending and not self.order.waiting()

    def add(self, payload: bytes, now: float) -> None:
        """A received payload: refused and counted if it does not decode, else taken in order."""
        try:
            obs = unpack_observations(payload)
        except MessageError as err:
            self.core.stats.refuse("observations", str(err))
            return
        self._take(obs, now)

    def tick(self, now: float) -> None:
        """Time passed: gaps held longer than ``gap_wait`` are given up."""
        self._take(None, now)

    def process(self, now: float) -> int:
        """Integrate or drop the frames at the head whose turn has come; how many.

        It stops at a frame still within ``pose_wait`` of its pose: the caller waits for the
        core's pose count to move past ``poses_seen`` (or a little time) and calls again.
        """
        done = 0
        while self.pending and self._process_head(now):
            done += 1
        return done

    def _take(self, obs: Observations | None, now: float) -> None:
        core = self.core
        taken = self.order.take(obs, now)
        for again in taken.repeated:  # its acknowledgement was lost on the way: say it again
            core.stats.add("repeated")
            with core.lock:
                core.progress.again(again.run)
        if taken.lost:
            core.stats.note(
                "lost",
                "lost",
                f"gave up {taken.lost} frames that never came (past the history "
                "window, or a service was down longer)",
                n=taken.lost,
            )
        for ready in taken.ready:
            self._queue(ready, now)

    def _queue(self, obs: Observations, now: float) -> None:
        if len(self.pending) >= MAX_PENDING:
            _, oldest = self.pending.popleft()
            self._done(oldest, integrated=False)
            count_drop(self.core.stats, oldest, BACKLOG, self.pose_wait)
        self.pending.append((now, obs))

    def _process_head(self, now: float) -> bool:
        """Integrate or drop the oldest observation; False when it must wait longer."""
        core = self.core
        arrived, obs = self.pending[0]
        if obs.skipped:  # the detector skipped it (behind in real time) and said so
            self.pending.popleft()
            self._done(obs, integrated=False)
            core.stats.add("skipped")
            return True
        with core.lock:
            source = core.source_pose(obs.stamp, now - arrived)
            if source is Lookup.WAIT and now - arrived < self.pose_wait:
                self.poses_seen = core.poses_added
                return False
            self.pending.popleft()
            if isinstance(source, SourcePose):
                self._integrate(obs, source)
            self._done(obs, integrated=not isinstance(source, Lookup))
        if isinstance(source, Lookup):
            count_drop(core.stats, obs, DROP_REASONS[source], self.pose_wait)
        else:
            core.stats.add("integrated")
        return True

    def _integrate(self, obs: Observations, source: SourcePose) -> None:
        """Fold a frame in (the core's lock held) and say what changed."""
        core = self.core
        pose = core.mapping.integrate(obs, source)
        if core.corrector is not None and self.on_pose is not None and pose:
            self.on_pose(pose, source.pose.frame)
        if core.judge is not None:
            core.pose_source = core.judge.summary()
        core.dirty = True
        if (
            core.updates_wanted
            and core.map.frames - core.updated_frames >= UPDATE_FRAMES
            and not core.update_due.is_set()
        ):
            core.update_due.set()

    def _done(self, obs: Observations, *, integrated: bool) -> None:
        with self.core.lock:
            self.core.progress.count(obs.run, obs.seq, integrated=integrated)


def count_drop(stats: Stats, obs: Observations, reason: str, pose_wait: float) -> None:
    """Count and log (at most once a second per reason) a frame dropped for want of a pose."""
    why = {
        "pose_timeout": f"no pose covered it within {pose_wait:.1f} s (is a pose source running?)",
        "no_pose": "no pose near its stamp (before the first pose, or in a gap)",
        BACKLOG: f"{MAX_PENDING} newer frames wait for poses too (is a pose source running?)",
    }[reason]
    stats.add("dropped")
    stats.note(f"dropped.{reason}", reason, f"dropped the frame at {obs.stamp:.3f}: {why}")
