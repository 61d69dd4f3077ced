"""A ROS 1 record header is read field by field, and a malformed one is one readable error."""

import struct

import pytest

from wallmap.services.player.errors import PlayerError
from wallmap.services.player.ros1_records import OP_MSGDATA, record_header


def field(name: bytes, value: bytes) -> bytes:
    data = name + b"=" + value
    return struct.pack("<L", len(data)) + data


def header(*fields: bytes) -> bytes:
    data = b"".join(fields)
    return struct.pack("<L", len(data)) + data


def test_a_header_s_fields_and_the_position_after_it() -> None:
    conn = struct.pack("<L", 3)
    data = b"junk" + header(field(b"op", OP_MSGDATA), field(b"conn", conn), field(b"x", b"a=b"))
    fields, end = record_header(data + b"data", 4)
    assert fields == {"op": OP_MSGDATA, "conn": conn, "x": b"a=b"}  # split at the first '='
    assert end == len(data)
    assert record_header(memoryview(data), 4) == (fields, end)


def test_an_empty_header_has_no_fields() -> None:
    assert record_header(header(), 0) == ({}, 4)


@pytest.mark.parametrize(
    "data",
    [
        b"\x05\x00",  # not even its length
        header(field(b"op", OP_MSGDATA))[:-1],  # its length says more than there is
    ],
)
def test_a_truncated_header_is_one_readable_error(data: bytes) -> None:
    with pytest.raises(PlayerError, match=r"^a record header at byte 4 runs past the end of the"):
        record_header(data, 0)


def test_a_field_longer_than_its_header_is_one_readable_error() -> None:
    overlong = struct.pack("<L", 9) + b"op=\x02"  # says 9 bytes, the header holds 4
    data = header(field(b"conn", b"1"), overlong) + b"more bytes after it"
    with pytest.raises(PlayerError, match=r"^a field of the record header at byte 4 runs past"):
        record_header(data, 0)


def test_a_field_without_equals_is_one_readable_error() -> None:
    data = header(field(b"op", OP_MSGDATA), struct.pack("<L", 4) + b"conn")
    with pytest.raises(PlayerError, match=r"^a field of the record header at byte 4 has no '='"):
        record_header(data, 0)
