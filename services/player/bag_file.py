"""Open a ROS 1 or ROS 2 bag and read its messages, every failure as one readable line.

rosbags fails on a user's bad bag in many ways (a suffix that does not match the contents, an
old format, a damaged index, a chunk that does not decode, even AssertionError). The player and
``wallmap doctor`` both read bags through `BagFile`, so the user gets the same one-line
`PlayerError` from either.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

from wallmap.common.ros2_types import ros2_typestore
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.lz4_chunks import Reveal, deserialize_head
from wallmap.services.player.mapped_bag import compression, mapped_messages

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection

BAG_FORMS = "a ROS 1 .bag file, a ROS 2 bag folder with metadata.yaml, or a ROS 2 .mcap file"
# rosbags picks the format from the file name, so the suffix has to match the contents.
SUFFIXES = {b"#ROSBAG V2.0": ".bag", b"\x89MCAP": ".mcap", b"SQLite format 3\x00": ".db3"}


@dataclass(frozen=True)
class Topic:
    """One topic of a bag.

    Attributes:
        name: As spelled in the bag (a leading '/' or not).
        msgtype: Its message type in ROS 2 spelling, e.g. ``sensor_msgs/msg/PointCloud2``.
        connections: rosbags' connections carrying it.
    """

    name: str
    msgtype: str
    connections: tuple[Connection, ...]

    @property
    def count(self) -> int:
        """Number of messages."""
        return sum(c.msgcount for c in self.connections)


def _one_line(err: BaseException) -> str:
    """A library error as one readable line (some rosbags errors have no text).

    rosbags puts a cause's arguments in its text as a tuple (``('Header could not be read',)``):
    the words are kept, the tuple's quotes and brackets not.
    """
    text = re.sub(r"""\((['"])(.*?)\1,\)""", r"\2", str(err))
    return " ".join(text.split()) or type(err).__name__


def _unreadable(path: Path, err: BaseException) -> PlayerError:
    """The error for a bag rosbags fails on, with its reason kept as one line.

    Old or interrupted ROS 1 recorders leave bags whose index does not match their chunks (e.g.
    the 2010 demo bag of laser_scan_matcher); ROS 1's own tools repair those, so say how.
    """
    repair = ""
    if path.suffix == ".bag":
        repair = (
            f"; ROS 1 can often repair it: `rosbag reindex {path}` rebuilds a broken index, then "
            f"`rosbag fix {path} fixed.bag` updates old message definitions (e.g. roslib/Header)"
        )
    return PlayerError(
        f"cannot read bag {path}; it looks damaged or was written by an unsupported recorder "
        f"({_one_line(err)}){repair}"
    )


def _check_path(path: Path) -> None:
    """Reject paths rosbags cannot read with a message saying why, before rosbags sees them.

    Raises:
        PlayerError: No such path, a folder without metadata.yaml, an unreadable file, an old
            or unknown format, or a suffix that does not match the contents.
    """
    if not path.exists():
        raise PlayerError(f"bag not found: {path}")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            inside = sorted(p.name for p in path.iterdir() if p.suffix in (".mcap", ".bag"))
            hint = f" (it holds {', '.join(inside)}: play the file itself)" if inside else ""
            msg = f"{path} is a folder without metadata.yaml{hint}; expected {BAG_FORMS}"
            raise PlayerError(msg)
        return
    try:
        with path.open("rb") as file:
            magic = file.read(16)
    except OSError as err:
        raise PlayerError(f"cannot read bag {path}: {_one_line(err)}") from err
    if magic.startswith(b"#ROSRECORD"):
        raise PlayerError(
            f"{path} is an old '#ROSRECORD V1.x' bag, which cannot be read; convert it to "
            f"format 2.0 with ROS 1's `rosbag fix` first"
        )
    for prefix, suffix in SUFFIXES.items():
        if magic.startswith(prefix):
            if path.suffix != suffix:
                raise PlayerError(f"{path} holds a {suffix} bag; rename it to end in {suffix}")
            return
    if magic.startswith(b"#ROSBAG"):
        version = magic.split(b"\n", 1)[0].decode("ascii", "replace")
        raise PlayerError(f"{path} is a {version!r} bag; only ROS 1 bag format 2.0 is supported")
    raise PlayerError(f"{path} is not a ROS bag; expected {BAG_FORMS}")


def _open_reader(path: Path) -> AnyReader:
    """An open reader (rosbags') of ``path``, given Humble's typestore only if the bag needs it.

    A ROS 1 bag carries its message definitions, as does a ROS 2 bag recorded since Iron and
    every MCAP file: rosbags reads the messages with those. Only a ROS 2 bag recorded without
    them needs a default typestore, and Humble's takes a tenth of a second to build, a seventh
    of a player's start. So the bag is opened without it first; one that then fails
    (without definitions, or damaged) is opened again with it, and fails as it always did.
    """
    from rosbags.highlevel import AnyReader  # noqa: PLC0415 - for processes that read bags

    reader = AnyReader([path])
    try:
        reader.open()
    except Exception:  # whatever it was, the second opening says it again
        reader = AnyReader([path], default_typestore=ros2_typestore())
        reader.open()
    return reader


class BagFile:
    """An open bag: its topics, its time span, and its messages in bag order.

    Attributes:
        path: The bag.
        reader: rosbags' reader, open until ``close``.
        topics: Every topic with a known message type, by name.
        start_ns: Receive time of the first message, ns.
        duration_ns: From the first message to the last, ns.
        message_count: Messages in the bag.
    """

    def __init__(self, path: Path) -> None:
        """Open the bag.

        Raises:
            PlayerError: The path is not a bag rosbags can read (see ``_check_path``), or rosbags
                fails on it.
        """
        self.path = Path(path)
        _check_path(self.path)
        try:
            self.reader = _open_reader(self.path)
        except Exception as err:  # a damaged bag fails in many ways (even AssertionError)
            raise _unreadable(self.path, err) from err
        self.topics = {
            name: Topic(name, info.msgtype, tuple(info.connections))
            for name, info in self.reader.topics.items()
            if info.msgtype is not None
        }
        self.start_ns: int = self.reader.start_time
        self.duration_ns: int = self.reader.duration
        self.message_count: int = self.reader.message_count

    def messages(
        self,
        topics: Iterable[Topic],
        *,
        mapped: bool = False,
        start: int | None = None,
        stop: int | None = None,
    ) -> Iterator[tuple[str, int, Any]]:
        """(topic name, receive time ns, deserialized message) of some topics, in bag order.

        Args:
            topics: The topics to read.
            mapped: Read a ROS 1 bag as views over the mapped file, or over its chunks
                decompressed as far as read (LZ4) or one ahead on a worker (bz2; see
                ``mapped_bag``): for large clouds of which only some rows are read, and for
                small messages (tf, poses) among them, whose chunks rosbags reads whole.
            start: Bag time (ns) of the first message kept.
            stop: Bag time (ns) before which messages are kept.

        Raises:
            PlayerError: A damaged chunk or message (damage surfaces as assorted library errors).
        """
        for connection, receive_ns, msg, _ in self._read(topics, mapped, start, stop):
            yield connection.topic, receive_ns, msg

    def sensor_messages(
        self, topic: Topic, *, start: int | None = None, stop: int | None = None
    ) -> Iterator[tuple[int, Any, Reveal]]:
        """(receive time ns, message, reveal) of a sensor topic, its data read as it is revealed.

        Of an LZ4 bag, only each message's head is decompressed before it is handed out, and
        ``reveal(n)`` decompresses the first ``n`` bytes of its ``data`` (``lz4_chunks``): a
        frame reads the rows it searches, not the cloud. Of any other bag the message is read
        as ``messages(mapped=True)`` reads it, and ``reveal`` does nothing. ``start`` and
        ``stop`` are those of ``messages``.

        Raises:
            PlayerError: A damaged chunk or message, here or when revealing.
        """
        for _, receive_ns, msg, reveal in self._read([topic], True, start, stop, heads=True):
            yield receive_ns, msg, self._reporting(reveal)

    def _read(
        self,
        topics: Iterable[Topic],
        mapped: bool,
        start: int | None,
        stop: int | None,
        *,
        heads: bool = False,
    ) -> Iterator[tuple[Connection, int, Any, Reveal]]:
        """``messages``' and ``sensor_messages``' reading; ``heads``: theirs alone, if LZ4."""
        connections = [c for topic in topics for c in topic.connections]
        if not connections:
            return
        ids = frozenset(c.id for c in connections) if heads else frozenset()
        try:
            raws = (
                mapped_messages(self.reader, connections, start, stop, heads=ids)
                if mapped
                else None
            )
            if raws is None:
                raws = self.reader.messages(connections=connections, start=start, stop=stop)
            for connection, receive_ns, raw in raws:
                msg, reveal = deserialize_head(
                    raw, lambda raw, t=connection.msgtype: self.reader.deserialize(raw, t)
                )
                yield connection, receive_ns, msg, reveal
        except Exception as err:
            raise _unreadable(self.path, err) from err

    def _reporting(self, reveal: Reveal) -> Reveal:
        """``reveal``, failing as the bag's one-line error."""

        def reported(count: int) -> None:
            try:
                reveal(count)
            except Exception as err:
                raise _unreadable(self.path, err) from err

        return reported

    def first(
        self,
        topic: Topic,
        *,
        mapped: bool = False,
        start: int | None = None,
        stop: int | None = None,
    ) -> tuple[int, Any] | None:
        """(receive time ns, message) of a topic's first message in ``[start, stop)``, or None.

        Args are those of ``messages``.
        """
        stream = self.messages([topic], mapped=mapped, start=start, stop=stop)
        item = next(stream, None)
        stream.close()
        return None if item is None else (item[1], item[2])

    @property
    def chunk_compression(self) -> str | None:
        """How a ROS 1 bag's chunks are compressed; None for a ROS 2 bag.

        ``none``, ``lz4`` or ``bz2`` (``+`` between several). An LZ4 cloud is decompressed as
        far as it is read (``lz4_chunks``), a bz2 chunk whole, at tens of MB/s: the doctor says
        so.
        """
        from rosbags.rosbag1 import Reader as Reader1  # noqa: PLC0415 - loaded with the bag

        readers = self.reader.readers
        if not readers or not all(isinstance(r, Reader1) for r in readers):
            return None
        used = {compression(chunk) for r in readers for chunk in r.chunks.values()}
        return "+".join(sorted(used)) or "none"

    def close(self) -> None:
        """Close the bag; safe to call twice."""
        if self.reader.stack is not None:
            self.reader.close()

    def __enter__(self) -> Self:
        """The bag itself, closed on the way out of the ``with`` block."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the bag."""
        self.close()
