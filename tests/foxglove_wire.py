"""A reader of protobuf's wire format, enough to check Foxglove's messages in the tests.

No protobuf library is needed: the descriptors travel in each channel's own schema (a
FileDescriptorSet), so messages decode into field name -> values, read by their Foxglove names.
"""

from __future__ import annotations

import struct
from collections import defaultdict
from typing import Any


def varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, i


def wire(data: bytes) -> dict[int, list[Any]]:
    """Field number -> raw values (ints, doubles, or bytes for length-delimited fields)."""
    out: dict[int, list[Any]] = defaultdict(list)
    i = 0
    while i < len(data):
        key, i = varint(data, i)
        kind = key & 7
        if kind == 0:
            value, i = varint(data, i)
        elif kind == 1:
            value, i = struct.unpack_from("<d", data, i)[0], i + 8
        elif kind == 2:
            n, i = varint(data, i)
            value, i = data[i : i + n], i + n
        elif kind == 5:
            value, i = struct.unpack_from("<f", data, i)[0], i + 4
        else:
            raise ValueError(f"wire type {kind}")
        out[key >> 3].append(value)
    return out


Types = dict[str, dict[int, tuple[str, int, str]]]


def descriptor_types(schema_data: bytes) -> Types:
    """Message name -> field number -> (name, type, message type) from a FileDescriptorSet."""
    types: Types = {}
    for file in map(wire, wire(schema_data)[1]):
        package = file[2][0].decode() if file[2] else ""
        for message in map(wire, file[4]):
            types[f"{package}.{message[1][0].decode()}"] = {
                f[3][0]: (f[1][0].decode(), f[5][0], f[6][0].decode().lstrip(".") if f[6] else "")
                for f in map(wire, message[2])
            }
    return types


def decode(data: bytes, name: str, types: Types) -> dict[str, list[Any]]:
    """A message as field name -> values (always a list; proto3 leaves zeros out)."""
    out: dict[str, list[Any]] = defaultdict(list)
    for number, values in wire(data).items():
        field, kind, message = types[name][number]
        for value in values:
            if kind == 11:  # a message
                out[field].append(decode(value, message, types))
            else:
                out[field].append(value.decode() if kind == 9 else value)
    return out


def one(message: dict[str, list[Any]], field: str) -> Any:
    return message[field][0] if message[field] else 0


def stamp_ns(message: dict[str, list[Any]]) -> int:
    stamp = one(message, "timestamp")
    return one(stamp, "seconds") * 1_000_000_000 + one(stamp, "nanos")
