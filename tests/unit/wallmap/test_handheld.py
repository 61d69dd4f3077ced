"""Generated handheld recordings mapped offline: 6-DoF camera, a tilted fixed frame, a kitchen's
clutter, brought the three ways users have it (``handheld_scenes``), scored against the truth.
"""

from __future__ import annotations

import pytest
from handheld_scenes import TUM, score
from rosbags.highlevel import AnyReader

from wallmap.common.map_consistency import MappedWall, fans
from wallmap.common.messages import Frame
from wallmap.common.ros2_types import ros2_typestore
from wallmap.config import Config, configured
from wallmap.offline import map_bag, pipeline_for, walls
from wallmap.services.player.bag_contents import IMAGE
from wallmap.services.player.pose_sources import parse_pose_source
from wallmap.services.ros2_source.live import LiveFrames


@pytest.mark.parametrize("style", ["camera", "robot", "tum"])
def test_a_handheld_camera_in_a_tilted_frame_maps_the_walls_not_the_clutter(
    handheld_recordings, style
):
    info = handheld_recordings[style]
    wall_map = map_bag(info.path, TUM if style == "tum" else None)
    assert wall_map.frames == info.n_frames
    served = walls(wall_map, min_obs=3)
    result = score(info, served)
    assert result.precision >= 0.85
    assert result.recall >= 0.9
    assert result.median_angle_deg <= 0.5
    assert result.median_offset_m <= 0.02
    assert result.duplicates <= 1
    assert fans([MappedWall.from_reply(w) for w in served]) == []


def test_without_levelling_the_tilted_frame_gives_no_map(handheld_recordings):
    """What --level none does to a frame tilted 30 degrees: the band is not where the walls are."""
    info = handheld_recordings["camera"]
    levelled = score(info, walls(map_bag(info.path), min_obs=3))
    as_is = score(
        info, walls(map_bag(info.path, configured("player.source.level=none")), min_obs=3)
    )
    assert as_is.recall < levelled.recall - 0.5


def test_sent_live_the_tilted_frame_is_levelled_from_the_first_frames(handheld_recordings) -> None:
    """The 6-DoF tf bag message by message through ``LiveFrames``, as `wallmap ros2` receives
    it, its frames and poses through the pipeline the services run: the survey of the first
    frames levels the frame, without a ``base_link`` the poses are the camera's."""
    info = handheld_recordings["camera"]
    pipeline = pipeline_for(Config())
    reported: list[tuple[str, str]] = []
    live = LiveFrames(
        IMAGE,
        parse_pose_source("tf"),
        rows=pipeline.rows,
        report=lambda counter, line: reported.append((counter, line)),
    )
    sent = 0
    with AnyReader([info.path], default_typestore=ros2_typestore()) as reader:
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic.endswith("camera_info"):
                live.add_camera_info(msg)
            elif connection.msgtype == IMAGE:
                live.add_sensor(msg)
            else:
                live.add_tf(msg, static=connection.topic == "/tf_static")
            frames = live.ready()
            for pose in live.take_poses():
                pipeline.add_pose(pose)
            for frame in frames:
                pipeline.step(
                    Frame(
                        "live",
                        sent,
                        frame.stamp,
                        frame.frame_id,
                        frame.points,
                        frame.T_base_sensor,
                        "depth",
                        band=frame.band,
                    )
                )
                sent += 1
    assert sent >= info.n_frames - 15  # the last tf_wait's frames still wait
    counters = [counter for counter, _ in reported]
    # each image comes before its CameraInfo in this bag: the first waits for it, not dropped
    assert counters == ["pose_source_changed", "surveyed"], reported
    assert "tilted 30.0 degrees from level" in reported[-1][1], reported[-1][1]
    assert "floor at -1.30 m" in reported[-1][1], reported[-1][1]
    result = score(info, walls(pipeline.map, min_obs=3))
    assert result.precision >= 0.85
    assert result.recall >= 0.9
    assert result.median_offset_m <= 0.02
