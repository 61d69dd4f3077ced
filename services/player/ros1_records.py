"""The header of a ROS 1 bag 2.0 record, read outside rosbags.

Every record of a ROS 1 bag starts with a header: its length (uint32, little-endian), then
fields, each its own length and ``name=value``. Two readers need one without rosbags: the mapped
reader (``mapped_bag``), which walks the records of a chunk itself, and ``wallmap doctor``,
which reads the header record of a bag rosbags may refuse (it says where the index should be).
Both read it here, as strictly as rosbags does, so a malformed header is one readable error.
"""

import struct
from collections.abc import Callable

from wallmap.services.player.errors import PlayerError

UINT32 = struct.Struct("<L")
OP_MSGDATA, OP_CONNECTION = b"\x02", b"\x07"  # record "op" codes of the bag format 2.0


def record_header(data: bytes | memoryview, pos: int) -> tuple[dict[str, bytes], int]:
    """The fields (name -> raw value) of the record header at ``pos``, and the position after it.

    Args:
        data: The bag's bytes (the whole file, or its head), a header starting at ``pos``.
        pos: Where the header's length field is.

    Raises:
        PlayerError: The header runs past the end of ``data``, or one of its fields past the
            header's end, or a field has no ``=``: one line, with the byte where it is.
    """
    start = pos + 4  # where the fields begin: the position the errors name
    length = _length(data, pos, len(data))
    if length is None:
        msg = f"a record header at byte {start} runs past the end of the file"
        raise PlayerError(msg)
    end = start + length
    fields: dict[str, bytes] = {}
    pos = start
    while pos < end:
        size = _length(data, pos, end)
        if size is None:
            msg = f"a field of the record header at byte {start} runs past the header's end"
            raise PlayerError(msg)
        name, equals, value = bytes(data[pos + 4 : pos + 4 + size]).partition(b"=")
        if not equals:
            msg = f"a field of the record header at byte {start} has no '=' (name=value)"
            raise PlayerError(msg)
        fields[name.decode("ascii", "replace")] = value
        pos += 4 + size
    return fields, end


def message_at(
    view: memoryview, pos: int, fill: Callable[[int], None] | None = None
) -> tuple[int, int, int]:
    """The message record at ``pos`` of a chunk: its connection id, where its data starts, ends.

    Connection records before it are skipped, as rosbags also allows. ``fill(n)``, if given, is
    called before the first ``n`` bytes of ``view`` are read (a chunk decompressed as read).

    Raises:
        PlayerError: No message record where the bag's index points.
    """
    while True:
        if fill is not None:  # the header's length, then the header and the data's length
            fill(pos + 4)
            length = _length(view, pos, len(view))
            fill(pos + 8 + (length or 0))
        fields, pos = record_header(view, pos)
        (size,) = UINT32.unpack_from(view, pos)
        pos += 4
        if fields.get("op") != OP_CONNECTION:
            break
        pos += size
    if fields.get("op") != OP_MSGDATA or pos + size > len(view):
        msg = f"no message data where the bag's index points (byte {pos})"
        raise PlayerError(msg)
    (conn,) = UINT32.unpack(fields["conn"])
    return conn, pos, pos + size


def _length(data: bytes | memoryview, pos: int, limit: int) -> int | None:
    """The length field at ``pos``, or None when it or the bytes it counts pass ``limit``."""
    if pos + 4 > limit:
        return None
    (length,) = UINT32.unpack_from(data, pos)
    return length if pos + 4 + length <= limit else None
