"""The header of a ROS 1 bag 2.0 record, read outside rosbags.

Every record of a ROS 1 bag starts with a header: its length (uint32, little-endian), then
fields, each its own length and ``name=value``. Two readers need one without rosbags: the mapped
reader (``mapped_bag``), which walks the records of a chunk itself, and ``wallmap doctor``,
which reads the header record of a bag rosbags may refuse (it says where the index should be).
Both read it here, as strictly as rosbags does, so a malformed header is one readable error.
"""

import struct

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


def _length(data: bytes | memoryview, pos: int, limit: int) -> int | None:
    """The length field at ``pos``, or None when it or the bytes it counts pass ``limit``."""
    if pos + 4 > limit:
        return None
    (length,) = UINT32.unpack_from(data, pos)
    return length if pos + 4 + length <= limit else None
