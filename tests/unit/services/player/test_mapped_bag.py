"""Reading an uncompressed ROS 1 bag through a memory map gives exactly rosbags' messages."""

from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from wallmap.common.scan_row import RowSelection
from wallmap.scene import Camera, write_scene_bag
from wallmap.services.player.bag_contents import read_contents
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.mapped_bag import mapped_messages

CAMERA = Camera(width=32, height=24)


def _bag(tmp_path: Path, name: str, **kwargs: object) -> Path:
    path = tmp_path / name
    write_scene_bag(path, seed=9, n_frames=12, sensor="pointcloud", camera=CAMERA, **kwargs)
    return path


def test_mapped_messages_are_rosbags_messages(tmp_path: Path) -> None:
    bag = _bag(tmp_path, "plain.bag", fmt="ros1")
    with AnyReader([bag]) as reader:
        # Every topic at once: chunks interleave connections and carry connection records.
        expected = [(c.id, t, bytes(raw)) for c, t, raw in reader.messages()]
        mapped = mapped_messages(reader, reader.connections)
        assert mapped is not None
        got = [(c.id, t, bytes(raw)) for c, t, raw in mapped]
    assert len(got) == len(expected) > 12
    assert got == expected


def test_compressed_and_ros2_bags_are_left_to_rosbags(tmp_path: Path) -> None:
    for bag in (
        _bag(tmp_path, "lz4.bag", fmt="ros1", compress=True),
        _bag(tmp_path, "ros2", fmt="ros2-mcap"),
    ):
        with AnyReader([bag]) as reader:
            assert mapped_messages(reader, reader.connections) is None


def test_frames_from_a_mapped_bag_match_a_compressed_copy(tmp_path: Path) -> None:
    """The same scene through both read paths gives the same frames, rows and whole."""
    plain, packed = (
        _bag(tmp_path, "a.bag", fmt="ros1"),
        _bag(tmp_path, "b.bag", fmt="ros1", compress=True),
    )
    for rows in (None, RowSelection()):
        with BagSource(plain) as a, BagSource(packed) as b:
            pairs = list(zip(a.frames(rows), b.frames(rows), strict=True))
        assert len(pairs) == 12
        for (fa, pa), (fb, pb) in pairs:
            assert fa.stamp == fb.stamp
            assert pa.vector.tolist() == pb.vector.tolist()
            np.testing.assert_array_equal(fa.points, fb.points)


def test_a_damaged_message_position_is_one_readable_error(tmp_path: Path) -> None:
    bag = _bag(tmp_path, "broken.bag", fmt="ros1")
    with BagSource(bag) as source:
        inner = source._bag.reader.readers[0]
        for index in inner.indexes.values():
            index[:] = [entry._replace(offset=entry.offset + 3) for entry in index]
        with pytest.raises(PlayerError, match=r"cannot read bag .*broken\.bag"):
            list(source.frames())


def _survey(bag: Path) -> tuple[str, ...]:
    """What the player's first pass found: tf, the odometry and its stamps, the first cloud."""
    with BagFile(bag) as opened:
        contents = read_contents(opened)
    assert contents.poses["/odom"], "the scene has odometry"
    first = contents.firsts["/camera/depth/points"]
    assert first is not None
    return (
        repr(contents.tf_links),
        repr(contents.poses),
        repr(contents.pose_stamps),
        bytes(first.data).hex(),
    )


def test_the_survey_reads_tf_and_poses_through_the_map(tmp_path: Path) -> None:
    """The player's first pass (tf, poses) over a plain bag reads only those messages' pages,
    not every chunk with the clouds in it, and finds what rosbags finds in a compressed copy."""
    plain = _bag(tmp_path, "a.bag", fmt="ros1")
    packed = _bag(tmp_path, "b.bag", fmt="ros1", compress=True)
    with BagFile(plain) as opened:
        opened.reader.messages = None  # type: ignore[method-assign] # rosbags' chunk reader
        read_contents(opened)
    assert _survey(plain) == _survey(packed)
