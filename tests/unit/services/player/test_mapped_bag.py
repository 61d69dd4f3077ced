"""Reading a ROS 1 bag through a memory map, or its chunks decompressed ahead, gives exactly
rosbags' messages."""

import threading
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1

from wallmap.common.scan_row import RowSelection
from wallmap.scene import Camera, write_scene_bag
from wallmap.services.player.bag_contents import read_contents
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.mapped_bag import mapped_messages

CAMERA = Camera(width=32, height=24)
CLOUD_TOPIC = "/camera/depth/points"


def _bag(
    tmp_path: Path, name: str, *, frames: int = 12, camera: Camera = CAMERA, **kwargs: object
) -> Path:
    path = tmp_path / name
    write_scene_bag(path, seed=9, n_frames=frames, sensor="pointcloud", camera=camera, **kwargs)
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


def _repacked(plain: Path, path: Path, compression: Writer1.CompressionFormat) -> Path:
    """``plain``'s messages again, in chunks of about 16 kB compressed with ``compression``."""
    writer = Writer1(path)
    writer.set_compression(compression)
    writer.chunk_threshold = 16 * 1024  # many chunks, each holding a few messages
    with AnyReader([plain]) as reader, writer:
        out = {
            c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
            for c in reader.connections
        }
        for connection, stamp, raw in reader.messages():
            writer.write(out[connection.id], stamp, raw)
    return path


@pytest.mark.parametrize("compression", list(Writer1.CompressionFormat))
def test_compressed_chunks_give_rosbags_messages(
    tmp_path: Path, compression: Writer1.CompressionFormat
) -> None:
    """Decompressed one chunk ahead on a worker: every message, in order, and time windows."""
    packed = _repacked(
        _bag(tmp_path, "plain.bag", fmt="ros1"), tmp_path / "packed.bag", compression
    )
    with AnyReader([packed]) as reader:
        assert len(reader.readers[0].chunks) > 5
        for window in ({}, {"start": reader.start_time + 200_000_000, "stop": reader.end_time - 1}):
            expected = [(c.id, t, bytes(raw)) for c, t, raw in reader.messages(**window)]
            unpacked = mapped_messages(reader, reader.connections, **window)
            assert unpacked is not None
            got = [(c.id, t, bytes(raw)) for c, t, raw in unpacked]
            assert len(got) == len(expected) > 12
            assert got == expected
        first = mapped_messages(reader, reader.connections)
        assert first is not None
        assert next(first)[1] == reader.start_time
        first.close()  # a reader stopping early (the survey's) leaves no worker behind
    for worker in [t for t in threading.enumerate() if t.name.startswith("unpack")]:
        worker.join(timeout=5.0)  # it finishes the chunk under way, takes no other, and ends
        assert not worker.is_alive()


def _file_backed_mb() -> float:
    """This process's resident pages that are a file's (a mapped bag's among them), MB."""
    status = Path("/proc/self/status").read_text(encoding="utf-8")
    return (
        int(next(line for line in status.splitlines() if line.startswith("RssFile:")).split()[1])
        / 1024
    )


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads Linux's /proc")
@pytest.mark.parametrize(
    ("topics", "share", "compress"),
    [
        ("clouds", 1.0, False),
        ("clouds", 0.25, False),
        ("all", 1.0, False),
        ("all", 0.25, False),
        ("all", 1.0, True),
    ],
)
def test_pages_read_do_not_stay_in_the_player(
    tmp_path: Path, topics: str, share: float, compress: bool
) -> None:
    """Pages are let go as reading goes on: the resident set stays flat.

    ``share``: the leading part of each message read, as the player reads only the rows that
    can see the band. Every topic at once reads the small messages stamped after a cloud but
    written before it after the cloud; the kernel maps a large folio around each page read.
    ``compress``: LZ4 chunks, their compressed pages read as they are decompressed.
    """
    bag = _bag(
        tmp_path, "big.bag", frames=48, camera=Camera(320, 240), fmt="ros1", compress=compress
    )
    with AnyReader([bag]) as reader:
        read = [c for c in reader.connections if topics == "all" or c.topic == CLOUD_TOPIC]
        before = _file_backed_mb()
        pages = 0
        for _, _, raw in mapped_messages(reader, read) or ():
            message = np.frombuffer(raw, dtype=np.uint8)
            every_page = message[: int(share * message.size)][::4096]
            every_page.copy()  # a byte of every page read, as decoding them reads them
            pages += every_page.size
        grown = _file_backed_mb() - before
    assert pages > 48 * 600 * share  # 48 clouds of 2.4 MB
    assert grown < 0.5, f"{grown:.1f} MB of the bag stayed resident"


def test_ros2_bags_are_left_to_rosbags(tmp_path: Path) -> None:
    with AnyReader([_bag(tmp_path, "ros2", fmt="ros2-mcap")]) as reader:
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


def test_a_damaged_compressed_chunk_is_one_readable_error(tmp_path: Path) -> None:
    """The worker's failure reaches the reader as the bag's error, not a thread's traceback."""
    bag = _bag(tmp_path, "packed.bag", fmt="ros1", compress=True)
    with AnyReader([bag]) as reader:
        chunk = max(reader.readers[0].chunks.values(), key=lambda c: c.datapos)
    data = bytearray(bag.read_bytes())
    for i in range(chunk.datapos + 40, chunk.datapos + 240):
        data[i] ^= 0x5A
    bag.write_bytes(bytes(data))
    with BagFile(bag) as opened:
        topic = opened.topics[CLOUD_TOPIC]
        with pytest.raises(PlayerError, match=r"cannot read bag .*packed\.bag.*LZ4"):
            list(opened.messages([topic], mapped=True))


def _survey(bag: Path) -> tuple[str, ...]:
    """What the player's first pass found: tf, the odometry and its stamps, the first cloud."""
    with BagFile(bag) as opened:
        contents = read_contents(opened)
    assert contents.poses["/odom"], "the scene has odometry"
    first = contents.firsts[CLOUD_TOPIC]
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
