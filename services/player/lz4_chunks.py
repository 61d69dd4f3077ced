"""LZ4 chunks of a ROS 1 bag decompressed only as far as they are read.

A 640x480 cloud of an LZ4 bag fills a chunk of 10 MB, and decompressing all of it (2.2 ms here)
was most of a player's work on such a bag, although the detector searches a band of rows in the
image's upper part. LZ4 decompresses front to back in a stream, so a chunk here is a buffer of
its uncompressed size filled on demand: the records before a message, the message's head (its
header, its layout), then the image rows a frame reads (``reveal``). What lies beyond them is
never decompressed, nor checked: as with an uncompressed bag, bytes never read cannot fail.

A message read this way is deserialized from its head: its ``data`` is a view over the buffer
whose unread part is unset until revealed, and a field after the data (a cloud's ``is_dense``)
reads as zero, False. The player's decoders need no such field: they find invalid points
themselves.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from wallmap.services.player.errors import PlayerError
from wallmap.services.player.ros1_records import UINT32, message_at, record_header

if TYPE_CHECKING:
    import mmap

    from rosbags.interfaces import Connection

HEAD = 64 * 1024  # bytes of a message read before it is deserialized: its header, its layout
TAIL = 4096  # bytes at a message's end set to zero when its head is read: fields after its data
STEP = 1024 * 1024  # bytes decompressed a call: a few calls a frame, in buffers the heap reuses
Reveal = Callable[[int], None]  # makes the first n bytes of a message's data readable


class LazyChunk(np.ndarray):
    """A chunk's uncompressed bytes, decompressed up to ``filled``; what lies beyond is unset.

    An array of the heap, which the player's allocator recycles frame after frame
    (``common.allocator``): fresh pages would fault in at every frame. The views deserialized
    messages hold over it keep it alive, and a view's ``obj`` leads back to it to reveal more.
    """

    filled: int
    compressed: memoryview
    address: int
    _used: int
    _context: Any

    @classmethod
    def open(cls, compressed: memoryview, size: int) -> LazyChunk:
        """A chunk of ``size`` bytes uncompressed, none of them decompressed yet."""
        chunk = np.empty(size, dtype=np.uint8).view(cls)
        chunk.compressed, chunk.filled, chunk._used, chunk._context = compressed, 0, 0, None
        chunk.address = _address(chunk)
        return chunk

    def fill(self, upto: int) -> None:
        """Decompress until the first ``upto`` bytes (at most the chunk's size) are readable.

        Raises:
            PlayerError: The compressed data ends before the chunk does.
            RuntimeError: LZ4 finds the data damaged (the bag's caller makes it one line).
        """
        from lz4.frame import create_decompression_context, decompress_chunk  # noqa: PLC0415

        upto = min(upto, self.size)
        while self.filled < upto:
            if self._context is None:  # the first frame, or one after another (concatenated)
                self._context = create_decompression_context()
            want = min(STEP, self.size - self.filled)
            got, used, ended = decompress_chunk(
                self._context, self.compressed[self._used :], max_length=want
            )
            memoryview(self)[self.filled : self.filled + len(got)] = got  # not kept: a cycle
            self.filled += len(got)
            self._used += used
            if ended:
                self._context = None
            if not got and (ended is False or self._used >= len(self.compressed)):
                msg = f"an LZ4 chunk ends after {self.filled} of its {self.size} bytes"
                raise PlayerError(msg)


def _address(buffer: Any) -> int:
    """Where a buffer's bytes start in memory."""
    return int(np.frombuffer(buffer, dtype=np.uint8).__array_interface__["data"][0])


def _offset_in(data: Any, chunk: LazyChunk) -> int | None:
    """Where an array's bytes start in ``chunk``, or None if they are not a view into it."""
    if not isinstance(data, np.ndarray) or data.size == 0:
        return None
    offset = int(data.__array_interface__["data"][0]) - chunk.address
    return offset if offset >= 0 and offset + data.nbytes <= chunk.size else None


def _nothing(_count: int) -> None:
    """The ``Reveal`` of a message read whole."""


def lazy_messages(
    mapped: mmap.mmap,
    chunks: dict[int, Any],
    entries: list[Any],
    by_id: dict[int, Connection],
    heads: frozenset[int],
    let_go: Callable[[int, int], None],
) -> Iterator[tuple[Connection, int, memoryview]]:
    """(connection, stamp ns, message view) of LZ4 chunks, each decompressed as far as read.

    Messages of the connections in ``heads`` are filled up to ``HEAD`` bytes (see ``LazyChunk``
    and ``deserialize_head``); the others whole. ``let_go(start, end)``: the bag's bytes there
    were read (a chunk's, once the next one is opened or the last message was read past: its
    messages are read on after they are handed out).
    """
    file_view = memoryview(mapped)
    opened: dict[int, LazyChunk] = {}
    last = {entry.chunk_pos: k for k, entry in enumerate(entries)}
    previous: Any = None  # the chunk opened last (rosbags' record of it)
    for k, entry in enumerate(entries):
        chunk = opened.get(entry.chunk_pos)
        if chunk is None:
            if previous is not None:
                let_go(previous.datapos, previous.datapos + previous.datasize)
            previous = chunks[entry.chunk_pos]
            chunk = opened[entry.chunk_pos] = _open(file_view, entry.chunk_pos, chunks)
        view = memoryview(chunk)  # never kept by the chunk: the two would be a cycle
        conn, start, end = message_at(view, entry.offset, chunk.fill)
        chunk.fill(min(end, start + HEAD) if conn in heads else end)
        if chunk.filled < end:  # a field after the data reads as zero, not as the last frame's
            chunk[max(chunk.filled, end - TAIL) : end] = 0
        if last[entry.chunk_pos] == k:
            del opened[entry.chunk_pos]  # the messages' views keep it while they are held
        yield by_id[conn], entry.time, view[start:end]
    if previous is not None:  # asked for a message after the last: done with them all
        let_go(previous.datapos, previous.datapos + previous.datasize)


def _open(view: memoryview, pos: int, chunks: dict[int, Any]) -> LazyChunk:
    """The chunk record at ``pos``: its compressed data, and its size from its header."""
    fields, _ = record_header(view, pos)
    size = fields.get("size", b"")
    if len(size) != 4:
        msg = f"the chunk at byte {pos} has no size in its header"
        raise PlayerError(msg)
    chunk = chunks[pos]
    data = view[chunk.datapos : chunk.datapos + chunk.datasize]
    return LazyChunk.open(data, UINT32.unpack(size)[0])


def deserialize_head(
    raw: memoryview | bytes, deserialize: Callable[[memoryview | bytes], Any]
) -> tuple[Any, Reveal]:
    """A message deserialized from what of ``raw`` is readable, and how to reveal its data.

    A view over a ``LazyChunk`` not yet filled to its end is read from its head. A
    deserializer reads front to back, so when the message's data starts within what is filled,
    every field before it was read from decompressed bytes. A head longer than what is filled
    reads on into bytes not yet decompressed: the deserializer then fails, or places the data
    past what is filled; either way the message is filled whole and read again. Anything else
    is read whole.
    """
    chunk = getattr(raw, "obj", None)  # rosbags' own reader hands out bytes
    if not isinstance(raw, memoryview) or not isinstance(chunk, LazyChunk):
        return deserialize(raw), _nothing
    end = _address(raw) - chunk.address + len(raw)
    if chunk.filled >= end:
        return deserialize(raw), _nothing
    try:
        msg = deserialize(raw)
    except Exception:  # a head longer than what is filled (see above)
        msg = None
    offset = _offset_in(getattr(msg, "data", None), chunk)  # None: no data array into the chunk
    if offset is None or offset > chunk.filled:
        chunk.fill(end)
        return deserialize(raw), _nothing
    return msg, lambda count: chunk.fill(offset + count)
