"""The raw messages of a ROS 1 bag as views, copying nothing: over a memory map, or over a chunk.

rosbags reads a whole chunk into memory and copies each message out of it: every byte is copied
twice, 2.3 ms for one 640x480 cloud (10 MB) here. The player needs only the image rows the
detector searches, so for an uncompressed bag it maps the file and hands rosbags' deserializer a
view: only the pages under those rows are ever read. An LZ4 chunk is decompressed only as far as
it is read (``lz4_chunks``). A bz2 chunk must be decompressed whole, but once: its messages are
views over it, and the next chunk is decompressed meanwhile on a worker thread (the decompressor
lets go of the interpreter), so a player no longer decompresses, copies and decodes one frame
after the other on one core. rosbags' own index (the chunk and message positions it parsed when
it opened the bag) says where each message lies, and rosbags still deserializes it; ROS 2 bags
go through rosbags' reader.
"""

from __future__ import annotations

import heapq
import mmap
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

from wallmap.services.player.lz4_chunks import lazy_messages
from wallmap.services.player.ros1_records import message_at

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection

Raw = tuple["Connection", int, memoryview]  # connection, receive time (ns), the message's bytes
DONTNEED = getattr(mmap, "MADV_DONTNEED", None)  # Linux, macOS: Windows has no madvise


def mapped_messages(
    reader: AnyReader,
    connections: Sequence[Connection],
    start: int | None = None,
    stop: int | None = None,
    *,
    heads: frozenset[int] = frozenset(),
) -> Iterator[Raw] | None:
    """(connection, stamp ns, raw message view) in time order, or None for bags it cannot read.

    Only a single ROS 1 bag qualifies; the caller then reads with rosbags. As with rosbags,
    ``start`` and ``stop`` (ns) keep the messages with ``start <= time < stop``. ``heads``: ids
    of connections whose messages an LZ4 bag may hand out read only as far as their head, for
    the caller to read more of as it needs (``lz4_chunks.deserialize_head``).
    """
    # Imported here: the bag's reader has loaded them, and a process that reads no bag (the
    # mapper, whose configuration names the player's settings) need not.
    from rosbags.rosbag1 import Reader as Reader1  # noqa: PLC0415 - see above

    if len(reader.readers) != 1 or not isinstance(reader.readers[0], Reader1):
        return None
    bag = reader.readers[0]
    entries = [
        entry
        for entry in heapq.merge(*(bag.indexes[c.id] for c in connections))
        if (start is None or entry.time >= start) and (stop is None or entry.time < stop)
    ]
    with bag.path.open("rb") as file:  # the map keeps its own reference to the file
        mapped = mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ)
    # Not closed here: deserialized messages are views into it, and it goes when they do.
    by_id = {c.id: c for c in connections}
    kinds = {compression(bag.chunks[pos]) for pos in {entry.chunk_pos for entry in entries}}
    if kinds <= {"none"}:
        return _mapped(mapped, bag.chunks, entries, by_id)
    if kinds == {"lz4"}:
        return lazy_messages(mapped, bag.chunks, entries, by_id, heads, _ReadPages(mapped).let_go)
    return _unpacked(mapped, bag.chunks, entries, by_id)


def compression(chunk: Any) -> str:
    """How one of rosbags' ROS 1 chunks is compressed: ``none``, ``lz4`` or ``bz2``."""
    from rosbags.rosbag1.reader import decompressors  # noqa: PLC0415 - see mapped_messages

    return next(name for name, fn in decompressors.items() if fn is chunk.decompressor)


def _mapped(
    mapped: mmap.mmap, chunks: dict[int, Any], entries: list[Any], by_id: dict[int, Connection]
) -> Iterator[Raw]:
    view = memoryview(mapped)
    read = _ReadPages(mapped)
    for entry in entries:
        pos = chunks[entry.chunk_pos].datapos + entry.offset
        conn, start, end = message_at(view, pos)
        yield by_id[conn], entry.time, view[start:end]
        read.let_go(pos, end)


class _ReadPages:
    """Unmaps the pages of the bag read so far from this process, as reading goes on.

    Else every page read stays in the process's resident set, file-backed: 3 MB a VGA cloud,
    1.3 GB over a 450-frame bag, which looks like a leak to anyone watching the player. The
    pages stay in the page cache (nothing is read again), and a view still held into them
    reads them back from there (the map is read-only).

    A message's own pages are not enough. The kernel maps a whole large folio of the page
    cache (up to a page table's reach, 2 MB) on a fault, so reading a message maps pages of its
    neighbours, behind it as well as ahead. With only each message's own pages let go, a
    player reading the band's rows of a VGA cloud bag kept 25 KB a frame (11 MB over 450
    frames, 2.7 GB over an hour at 30 Hz), and a message read out of file order (a pose stamped
    after the cloud but written before it) kept its folio for good. So each time, everything
    from the page-table block before the message (or before the last one's end, if further
    back) up to the message's last whole page is let go.
    """

    BLOCK = mmap.PAGESIZE * (mmap.PAGESIZE // 8)  # what one page table maps: 2 MB on x86-64

    def __init__(self, mapped: mmap.mmap) -> None:
        self.mapped = mapped
        self.done = 0  # where the last message read ends, to the page

    def let_go(self, start: int, end: int) -> None:
        """The message in ``[start, end)`` was read: let go of its pages and what lies before."""
        first = min(start, self.done) // self.BLOCK * self.BLOCK
        last = max(end // mmap.PAGESIZE * mmap.PAGESIZE, self.done)
        if last > first and DONTNEED is not None:
            self.mapped.madvise(DONTNEED, first, last - first)
        self.done = last


def _unpacked(
    mapped: mmap.mmap, chunks: dict[int, Any], entries: list[Any], by_id: dict[int, Connection]
) -> Iterator[Raw]:
    """The messages of bz2 chunks (or mixed kinds): each decompressed once, the next meanwhile.

    Chunks are decompressed in the order the messages first need them, one ahead of the one
    read once a second message is asked for, and let go after their last message (what was
    deserialized from one keeps it alive).
    """
    order = list(dict.fromkeys(entry.chunk_pos for entry in entries))
    rank = {pos: k for k, pos in enumerate(order)}
    last = {entry.chunk_pos: k for k, entry in enumerate(entries)}

    view = memoryview(mapped)
    read = _ReadPages(mapped)  # the worker's alone

    def unpack(pos: int) -> memoryview:
        chunk = chunks[pos]
        end = chunk.datapos + chunk.datasize
        unpacked = memoryview(chunk.decompressor(view[chunk.datapos : end]))
        if unpacked.obj is not mapped:  # a compressed chunk's pages are read once
            read.let_go(chunk.datapos, end)
        return unpacked

    worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="unpack")
    ready: dict[int, Future[memoryview]] = {}
    try:
        for k, entry in enumerate(entries):
            # The next chunk from the second message on: a reader after one (the survey's
            # ``first``) does not set a chunk decompressing for nothing.
            for pos in order[rank[entry.chunk_pos] : rank[entry.chunk_pos] + (2 if k else 1)]:
                if pos not in ready and last[pos] >= k:
                    ready[pos] = worker.submit(unpack, pos)
            unpacked = ready[entry.chunk_pos].result()
            conn, start, end = message_at(unpacked, entry.offset)
            if last[entry.chunk_pos] == k:
                del ready[entry.chunk_pos]
            yield by_id[conn], entry.time, unpacked[start:end]
    finally:  # a reader that stopped early (the survey's first frame) waits for no chunk
        worker.shutdown(wait=False, cancel_futures=True)
