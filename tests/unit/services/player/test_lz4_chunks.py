"""An LZ4 bag's clouds decompressed only as far as the player reads them, and read right."""

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore

from wallmap.common.scan_row import RowSelection
from wallmap.scene import Camera, write_scene_bag
from wallmap.services.player.bag_contents import read_stamps
from wallmap.services.player.bag_file import BagFile, Topic
from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.lz4_chunks import HEAD
from wallmap.services.player.placement import SURVEY_FRAMES

CLOUD_TOPIC = "/camera/depth/points"
CAMERA = Camera(width=320, height=240)  # a cloud of 2.4 MB: LZ4 blocks of 64 kB, many


FRAMES = 40


def _scene(tmp_path: Path, name: str, *, compress: bool) -> Path:
    path = tmp_path / name
    write_scene_bag(
        path,
        seed=4,
        n_frames=FRAMES,
        fmt="ros1",
        sensor="pointcloud",
        camera=CAMERA,
        compress=compress,
    )
    return path


def _unsurveyed_cloud_chunks(reader: AnyReader) -> list[Any]:
    """The chunks of the clouds the player's survey does not decode whole (each ends a chunk).

    The survey decodes the first cloud of each of SURVEY_FRAMES stretches of the bag
    (``bag_frames.read_survey_frames``).
    """
    begin, length = reader.start_time, max(reader.duration, 1)
    step = length // SURVEY_FRAMES + 1
    (conn,) = [c for c in reader.connections if c.topic == CLOUD_TOPIC]
    entries = reader.readers[0].indexes[conn.id]
    surveyed = {
        min((e.time for e in entries if start <= e.time < start + step), default=None)
        for start in range(begin, begin + length, step)
    }
    chunks = reader.readers[0].chunks
    return [chunks[e.chunk_pos] for e in entries if e.time not in surveyed]


def _damage_tails(bag: Path) -> int:
    """Spoil the last bytes of the unsurveyed clouds' chunks: their bottom rows, packed."""
    with AnyReader([bag]) as reader:
        chunks = _unsurveyed_cloud_chunks(reader)
    data = bytearray(bag.read_bytes())
    for chunk in chunks:
        end = chunk.datapos + chunk.datasize
        data[end - 64 : end] = bytes(64)  # the end mark and the last block's sequences
    bag.write_bytes(bytes(data))
    return len(chunks)


def _reveal_whole(bag: BagFile, topic: Topic) -> None:
    for _, msg, reveal in bag.sensor_messages(topic):
        reveal(len(msg.data))


def test_an_lz4_cloud_is_decompressed_only_as_far_as_its_rows_are_read(tmp_path: Path) -> None:
    """The frames of an LZ4 bag whose clouds' last bytes are spoilt are the plain bag's frames.

    The rows that cannot see the band are never decompressed, so their damage is never met;
    reading the clouds whole meets it (the damage is real), and is one readable error.
    """
    plain, packed = (
        _scene(tmp_path, "plain.bag", compress=False),
        _scene(tmp_path, "packed.bag", compress=True),
    )
    assert _damage_tails(packed) >= FRAMES - SURVEY_FRAMES
    with BagSource(plain) as a, BagSource(packed) as b:
        pairs = list(zip(a.frames(RowSelection()), b.frames(RowSelection()), strict=True))
    assert len(pairs) == FRAMES
    for (fa, pa), (fb, pb) in pairs:
        assert fa.stamp == fb.stamp
        assert pa.vector.tolist() == pb.vector.tolist()
        np.testing.assert_array_equal(fa.points, fb.points)
    with BagFile(packed) as opened:
        topic = opened.topics[CLOUD_TOPIC]
        assert len(read_stamps(opened, topic).stamps) == FRAMES  # the doctor reads heads alone
        with pytest.raises(PlayerError, match=r"cannot read bag .*packed\.bag.*LZ4"):
            list(opened.messages([topic], mapped=True))
        with pytest.raises(PlayerError, match=r"cannot read bag .*packed\.bag.*LZ4"):
            _reveal_whole(opened, opened.topics[CLOUD_TOPIC])


def _cloud(typestore: object, frame_id: str, rows: int) -> object:
    types = typestore.types  # type: ignore[attr-defined]
    field = types["sensor_msgs/msg/PointField"]
    header = types["std_msgs/msg/Header"](
        seq=1, stamp=types["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id=frame_id
    )
    data = np.random.default_rng(1).integers(0, 255, rows * 40 * 12, dtype=np.uint8)
    return types["sensor_msgs/msg/PointCloud2"](
        header=header,
        height=rows,
        width=40,
        fields=[field(name=n, offset=4 * k, datatype=7, count=1) for k, n in enumerate("xyz")],
        is_bigendian=False,
        point_step=12,
        row_step=480,
        data=data,
        is_dense=True,
    )


def _head(msg: Any) -> tuple[object, ...]:
    """A cloud's fields before its data (each reader makes its own message classes)."""
    header, stamp = msg.header, msg.header.stamp
    fields = [(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    return (
        header.seq,
        stamp.sec,
        stamp.nanosec,
        header.frame_id,
        msg.height,
        msg.width,
        fields,
        msg.is_bigendian,
        msg.point_step,
        msg.row_step,
    )


@pytest.mark.parametrize("frame_id", ["camera", "c" * (HEAD + 1000)])
def test_a_cloud_read_from_its_head_is_rosbags_cloud(tmp_path: Path, frame_id: str) -> None:
    """Its head as rosbags reads it, its data as revealed; a head longer than ``HEAD`` too."""
    typestore = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "clouds.bag"
    writer = Writer1(path)
    writer.set_compression(Writer1.CompressionFormat.LZ4)
    with writer:
        msgtype = "sensor_msgs/msg/PointCloud2"
        conn = writer.add_connection("/cloud", msgtype, typestore=typestore)
        for k in range(3):
            raw = typestore.serialize_ros1(_cloud(typestore, frame_id, 6000), msgtype)
            writer.write(conn, 1_000_000_000 + k, raw)
    with AnyReader([path]) as reader:
        expected = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    with BagFile(path) as opened:
        got = list(opened.sensor_messages(opened.topics["/cloud"]))
        assert len(got) == len(expected) == 3
        for (_, msg, reveal), want in zip(got, expected, strict=True):
            assert _head(msg) == _head(want)
            reveal(100 * msg.row_step)
            np.testing.assert_array_equal(msg.data[: 100 * 480], want.data[: 100 * 480])
            reveal(len(msg.data))
            np.testing.assert_array_equal(msg.data, want.data)
            assert msg.is_dense is False  # it lies after the data: not read with the head
