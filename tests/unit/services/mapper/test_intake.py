"""The mapper's intake, step by step on a clock of its own: order, pose waits, drops, progress."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from wallmap.common.messages import Observations, Pose, WallObservation, pack
from wallmap.common.runtime import Stats
from wallmap.services.mapper import intake as intake_module
from wallmap.services.mapper.core import MapperCore
from wallmap.services.mapper.intake import Intake
from wallmap.services.mapper.mapping import Mapping
from wallmap.services.mapper.pose_judge import JudgeConfig

POSE_WAIT, GAP_WAIT = 2.0, 5.0


def _wall() -> WallObservation:
    """A wall 2 m ahead of the robot, across its view: (u, v) = (2, 0)."""
    return WallObservation(
        closest=np.array([2.0, 0.0]),
        cov=np.diag([1e-4, 1e-4]),
        p0=np.array([2.0, -1.0]),
        p1=np.array([2.0, 1.0]),
        n_points=200,
        rms=0.01,
    )


def _frame(seq: int, stamp: float | None = None, **how: object) -> bytes:
    stamp = 10.0 + 0.1 * seq if stamp is None else stamp
    return pack(Observations("run", seq, stamp, "base_link", [_wall()], **how))


def _intake() -> tuple[Intake, MapperCore, Stats]:
    stats = Stats(logging.getLogger("test_intake"))
    core = MapperCore(Mapping(judge=JudgeConfig(enabled=False)), stats)
    return Intake(core, POSE_WAIT, GAP_WAIT), core, stats


def _poses(core: MapperCore, *stamps: float) -> None:
    for stamp in stamps:
        core.poses.add(Pose(stamp, 0.0, 0.0, 0.0))
        core.poses_added += 1


def _progress(core: MapperCore) -> tuple[int, int, int]:
    run = core.progress.runs["run"]
    return run.processed, run.integrated, run.dropped


def test_frames_are_mapped_in_order_once_their_poses_come() -> None:
    intake, core, stats = _intake()
    intake.add(_frame(0), now=0.0)
    intake.add(_frame(2), now=0.0)  # 1 is late: 2 waits for it
    _poses(core, 9.0, 9.95, 10.05, 10.15, 10.25, 11.0)
    assert intake.process(now=0.0) == 1
    assert not intake.idle, "frame 2 waits for frame 1"
    intake.add(_frame(1), now=0.5)
    assert intake.process(now=0.5) == 2
    assert intake.idle
    assert stats.snapshot()["integrated"] == 3
    assert core.map.frames == 3
    assert _progress(core) == (3, 3, 0)
    intake.add(_frame(1), now=0.6)  # history brought it twice: taken once, acknowledged again
    assert intake.process(now=0.6) == 0
    assert stats.snapshot()["repeated"] == 1
    assert core.map.frames == 3


def test_a_frame_waits_for_its_pose_then_is_dropped_and_counted() -> None:
    intake, core, stats = _intake()
    _poses(core, 9.0, 9.9)
    intake.add(_frame(0), now=0.0)  # stamp 10.0: after the newest pose
    assert intake.process(now=0.0) == 0
    assert intake.poses_seen == core.poses_added, "it says which poses it has looked at"
    assert intake.process(now=POSE_WAIT - 0.1) == 0, "still within pose_wait"
    assert intake.process(now=POSE_WAIT + 0.1) == 1
    counts = stats.snapshot()
    assert counts["dropped"] == 1
    assert counts["dropped.pose_timeout"] == 1
    assert _progress(core) == (1, 0, 1), "a dropped frame moves its run on too"


def test_a_frame_before_every_pose_is_dropped_at_once() -> None:
    intake, core, stats = _intake()
    _poses(core, 20.0, 20.1)
    intake.add(_frame(0), now=0.0)  # stamp 10.0: long before the first pose
    assert intake.process(now=0.0) == 1
    assert stats.snapshot()["dropped.no_pose"] == 1


def test_a_gap_that_never_fills_is_given_up_when_time_passes() -> None:
    intake, core, stats = _intake()
    _poses(core, *np.arange(9.0, 11.0, 0.05))
    intake.add(_frame(0), now=0.0)
    intake.add(_frame(2), now=0.0)
    assert intake.process(now=0.0) == 1
    intake.tick(now=GAP_WAIT - 0.1)
    assert intake.process(now=GAP_WAIT - 0.1) == 0
    intake.tick(now=GAP_WAIT + 0.1)
    assert intake.process(now=GAP_WAIT + 0.1) == 1
    assert stats.snapshot()["lost"] == 1
    assert core.map.frames == 2


def test_a_malformed_payload_is_refused_and_the_intake_goes_on() -> None:
    intake, core, stats = _intake()
    _poses(core, *np.arange(9.0, 11.0, 0.05))
    intake.add(b"\x93not observations", now=0.0)
    intake.add(_frame(0), now=0.0)
    assert intake.process(now=0.0) == 1
    assert stats.snapshot()["refused"] == 1
    assert core.map.frames == 1


def test_a_skipped_frame_is_counted_and_not_waited_for() -> None:
    intake, core, stats = _intake()
    intake.add(_frame(0, skipped=True), now=0.0)  # no pose at all: it does not wait
    assert intake.process(now=0.0) == 1
    assert stats.snapshot()["skipped"] == 1
    assert _progress(core) == (1, 0, 1)


def test_when_poses_are_far_behind_the_oldest_frame_gives_way(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(intake_module, "MAX_PENDING", 3)
    intake, core, stats = _intake()
    for seq in range(5):
        intake.add(_frame(seq), now=0.0)
    assert len(intake.pending) == 3
    assert stats.snapshot()["dropped.backlog"] == 2
    _poses(core, *np.arange(9.0, 11.0, 0.05))
    assert intake.process(now=0.1) == 3
    assert _progress(core) == (5, 3, 2)
