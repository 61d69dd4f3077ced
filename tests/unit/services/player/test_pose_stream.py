"""The source's poses sent ahead of the frames, its dropouts left as gaps; scans deskewed."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from wallmap.common.messages import Pose
from wallmap.scene import Glitch, PoseFaults
from wallmap.scene.trajectory import Trajectory
from wallmap.services.player.laserscan import beam_times, deskew
from wallmap.services.player.pose_choice import default_source
from wallmap.services.player.pose_stream import LOOKAHEAD, POSE_PERIOD, PoseStream


def _line(stamp: float) -> Pose:
    return Pose(stamp, 0.5 * stamp, 0.0, 0.1 * stamp)


def _each(pose_at):
    """A stream's source of poses at many stamps, from one at a stamp."""
    return lambda stamps: [pose_at(stamp) for stamp in stamps.tolist()]


def test_poses_go_out_up_to_the_lookahead_once_each() -> None:
    stream = PoseStream(_each(_line))
    grid = [p.stamp for p in stream.until(10.0)]
    assert grid[0] == pytest.approx(10.0 - LOOKAHEAD + POSE_PERIOD)
    assert grid[-1] == pytest.approx(10.0 + LOOKAHEAD)
    assert np.allclose(np.diff(grid), POSE_PERIOD)  # the grid alone: 10.0 is on it
    second = [p.stamp for p in stream.until(10.1)]
    assert second[0] > grid[-1]  # nothing sent twice
    assert second[-1] == pytest.approx(10.1 + LOOKAHEAD)


def test_a_frame_past_the_source_s_last_pose_gets_its_own_as_the_newest() -> None:
    """Off the grid a frame's pose is interpolated, except past the source's end: it is sent."""
    stream = PoseStream(
        _each(lambda t: _line(t) if t <= 10.005 else None)
    )  # as tf: no pose past it
    sent = [p.stamp for p in stream.until(9.5)]
    assert 9.5 in sent  # on the grid
    assert not [s for s in stream.until(9.91) if abs(s.stamp - 9.91) < 1e-9]  # 9.92 is sent
    last = stream.until(10.005)
    assert [p.stamp for p in last] == [10.005]  # its own, past the grid's last (10.0)


def test_a_dropout_is_left_a_gap_and_a_seek_back_starts_afresh() -> None:
    stamps = np.concatenate([np.arange(0.0, 5.0, 0.01), np.arange(5.6, 10.0, 0.01)])
    stream = PoseStream(_each(_line), stamps)
    sent = [p.stamp for p in stream.until(5.2)]
    assert not any(5.1 < s < 5.5 for s in sent)
    assert stream.until(1.0)[0].stamp == pytest.approx(1.0 - LOOKAHEAD + POSE_PERIOD)
    assert len(stream.until(1.05)) > 1


def test_a_timed_scan_is_deskewed_to_its_first_beam() -> None:
    """A wall seen while the robot turns 10 degrees over the sweep is straight once deskewed."""
    n = 100
    angles = np.linspace(-0.5, 0.5, n)
    turn = math.radians(10.0)
    ranges = []
    for k, a in enumerate(angles):
        heading = turn * k / (n - 1)  # the robot's heading when beam k fires
        direction = a + heading  # in the first beam's frame
        ranges.append(2.0 / math.cos(direction))  # the wall x = 2 in the first beam's frame
    points = np.stack([np.cos(angles) * ranges, np.sin(angles) * ranges, np.zeros(n)], axis=1)
    out = deskew(points[None].astype(np.float32), np.eye(4), np.array([0.0, 0.0, turn]))
    np.testing.assert_allclose(out[0, :, 0], 2.0, atol=1e-4)
    scan = SimpleNamespace(ranges=[1.0] * n, time_increment=0.001, scan_time=0.0)
    assert beam_times(scan, 0.1) == (True, pytest.approx(0.099))
    untimed = SimpleNamespace(ranges=[1.0] * n, time_increment=0.0, scan_time=0.0)
    assert beam_times(untimed, 0.1) == (False, 0.1)


def test_the_default_takes_the_one_pose_topic_of_a_bag_without_tf() -> None:
    from wallmap.services.player.pose_sources import parse_pose_source

    topic = SimpleNamespace
    tracked = {
        "/scan": topic(msgtype="sensor_msgs/msg/LaserScan"),
        "/vrpn/pose": topic(msgtype="geometry_msgs/msg/PoseStamped"),
    }
    spec, note = default_source(parse_pose_source("tf"), tracked)
    assert str(spec) == "pose:/vrpn/pose"
    assert note is not None
    assert "no tf" in note
    with_tf = {**tracked, "/tf": topic(msgtype="tf2_msgs/msg/TFMessage")}
    assert default_source(parse_pose_source("tf"), with_tf) == (parse_pose_source("tf"), None)
    named = parse_pose_source("tf:map>base_link")
    assert default_source(named, tracked) == (named, None)


def test_faults_make_a_source_late_noisy_and_wrong_for_a_while() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    truth = Trajectory(t, 0.3 * t, np.zeros_like(t), 0.2 * t)
    late = PoseFaults(latency=0.1).apply(truth)
    np.testing.assert_allclose(late.x[20:], 0.3 * (t[20:] - 0.1), atol=1e-9)
    glitch = PoseFaults(glitches=(Glitch(2.0, 1.0, 12.0, 0.1),)).apply(truth)
    wrong = (t >= 2.0) & (t < 3.0)
    np.testing.assert_allclose(glitch.yaw[wrong] - truth.yaw[wrong], math.radians(12.0))
    np.testing.assert_allclose(glitch.yaw[~wrong], truth.yaw[~wrong])
    with pytest.raises(ValueError, match="START:DURATION"):
        Glitch.parse("12:3")


def test_every_stamp_is_sent_once_where_frames_fall_on_the_grid() -> None:
    """15 Hz frames fall on the 50 Hz grid every 0.2 s: their pose is not sent twice."""
    stream = PoseStream(_each(lambda t: Pose(t, t, 0.0, 0.0)))
    stamps = [p.stamp for k in range(60) for p in stream.until(1700000000.0 + k / 15)]
    assert len(stamps) == len(set(round(s, 6) for s in stamps))


def test_a_tf_bag_s_poses_at_once_are_its_poses_one_by_one(tmp_path) -> None:
    """A second of the grid at once (a tf chain's lookups batched): the same planar poses."""
    from wallmap.scene import Camera, write_scene_bag
    from wallmap.services.player.sources import open_source

    bag = tmp_path / "s.bag"
    write_scene_bag(bag, seed=2, n_frames=40, fmt="ros1", sensor="depth16", camera=Camera(80, 60))
    with open_source(bag) as source:
        stamps = [frame.stamp for frame, _ in source.frames()]
        grid = np.concatenate(
            [np.arange(stamps[0] - 1.0, stamps[-1] + 1.0, POSE_PERIOD), stamps[:5]]
        )
        many = source.planar_poses_at(grid)
        one_by_one = source.placement.planar_each(source.pose_at, grid)
    assert [p is None for p in many] == [p is None for p in one_by_one]
    assert any(p is None for p in many), "stamps beyond the poses have none"
    assert sum(p is not None for p in many) > 100
    for a, b in zip(many, one_by_one, strict=True):
        if a is not None and b is not None:
            assert (a.stamp, a.frame, a.child, a.cov) == (b.stamp, b.frame, b.child, b.cov)
            assert a.vector == pytest.approx(b.vector, abs=1e-12)
