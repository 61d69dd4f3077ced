"""The live page's map: poses kept in stamp order whatever order they arrive in."""

from __future__ import annotations

import pytest

from wallmap.common.messages import Observations, Pose
from wallmap.view.live import POSES_KEPT, LiveMap


def _pose(stamp: float) -> Pose:
    return Pose(stamp, stamp, 0.0, 0.0)


def test_a_late_pose_into_a_full_buffer_takes_its_place_and_the_oldest_goes() -> None:
    live = LiveMap()
    for k in range(POSES_KEPT):
        live.add_pose(_pose(float(k)))
    live.add_pose(_pose(POSES_KEPT - 1.5))  # late: between the last two
    live.add_pose(_pose(-1.0))  # older than everything kept: ignored
    path = live.latest()["recent"]
    xs = [x for x, _ in path]
    assert len(xs) == POSES_KEPT
    assert xs == sorted(xs)
    assert xs[0] == 1.0
    assert POSES_KEPT - 1.5 in xs


def test_observations_are_placed_with_the_pose_at_their_stamp() -> None:
    live = LiveMap()
    for stamp in (0.0, 0.02, 0.04):
        live.add_pose(_pose(stamp))
    live.set_observations(Observations("r", 7, 0.03, "base_link", ()))
    placed = live.latest()["observations"]
    assert placed["stamp"] == placed["pose"]["stamp"] == 0.03
    assert placed["pose"]["x"] == pytest.approx(0.03)
