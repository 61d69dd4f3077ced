"""msgpack payloads with numpy arrays carried as raw bytes.

An array travels as ``{"__nd__": [dtype, shape, bytes]}``: packing takes a memoryview of the
array's buffer (no copy for contiguous arrays) and unpacking wraps the received bytes in a
read-only ``np.frombuffer`` view (no copy either). Every payload is a map with ``"v"``, the schema
version; anything else is refused with a :class:`MessageError` that says why.
"""

from __future__ import annotations

import json
import math
from typing import Any

import msgpack
import numpy as np

SCHEMA_VERSION = 1
# Whole 1280x720 clouds are 11 MB; anything far larger is a mistake or an attack.
MAX_PAYLOAD_BYTES = 64 * 1024 * 1024
# A map coordinate or distance beyond this (m) is no building's: refused, also because the
# geometry would square it into an overflow.
MAX_COORDINATE = 1e6
_ND = "__nd__"
_ALLOWED_DTYPES = frozenset({"<f4", "<f8", "<i4", "<i8", "<u2", "|u1", "|i1", "<u4"})


class MessageError(ValueError):
    """A payload that cannot be accepted; the message is the reason, for logs and counters."""


def check_coordinates(values: Any, what: str) -> None:
    """MessageError if any of ``values`` (finite numbers, any shape) is beyond MAX_COORDINATE."""
    if isinstance(values, tuple):  # plain floats: a wall's (u, v), thousands a second
        beyond = any(abs(value) > MAX_COORDINATE for value in values)
    else:
        beyond = float(np.max(np.abs(values), initial=0.0)) > MAX_COORDINATE
    if beyond:
        msg = f"{what} lies beyond {MAX_COORDINATE:.0e} m of the origin"
        raise MessageError(msg)


def _pack_default(obj: object) -> object:
    if isinstance(obj, np.ndarray):
        arr = obj if obj.dtype.byteorder != ">" else obj.astype(obj.dtype.newbyteorder("<"))
        arr = np.ascontiguousarray(arr)
        return {_ND: [arr.dtype.str, list(arr.shape), memoryview(arr).cast("B")]}
    if isinstance(obj, np.generic):
        return obj.item()
    msg = f"cannot encode {type(obj).__name__}"
    raise TypeError(msg)


def _unpack_hook(obj: dict[Any, Any]) -> object:
    if _ND not in obj:
        return obj
    try:
        dtype_str, shape, data = obj[_ND]
    except (TypeError, ValueError) as err:
        msg = "malformed array: expected [dtype, shape, bytes]"
        raise MessageError(msg) from err
    if dtype_str not in _ALLOWED_DTYPES:
        msg = f"array dtype {dtype_str!r} is not accepted"
        raise MessageError(msg)
    if not isinstance(shape, list) or not all(isinstance(d, int) and d >= 0 for d in shape):
        msg = f"malformed array shape {shape!r}"
        raise MessageError(msg)
    if not isinstance(data, bytes):
        msg = "array data must be bytes"
        raise MessageError(msg)
    dtype = np.dtype(dtype_str)
    count = math.prod(shape)  # Python ints: a crafted shape cannot overflow into a match
    if count * dtype.itemsize != len(data):
        msg = f"array of shape {shape} and dtype {dtype_str} does not match {len(data)} bytes"
        raise MessageError(msg)
    return np.frombuffer(data, dtype=dtype).reshape(shape)


def encode(message: dict[str, Any]) -> bytes:
    """Pack a message map, adding the schema version."""
    return msgpack.packb({"v": SCHEMA_VERSION, **message}, default=_pack_default, use_bin_type=True)


def encode_as(message: dict[str, Any], fmt: str) -> bytes:
    """A reply in the format its query asked for: msgpack (``encode``) or ``json``.

    Either way with the schema version. ``message`` holds plain values (JSON has no arrays).
    """
    if fmt == "json":
        return json.dumps({"v": SCHEMA_VERSION, **message}).encode()
    return encode(message)


def decode(payload: bytes) -> dict[str, Any]:
    """Unpack a message map and check its schema version.

    Raises:
        MessageError: not msgpack, not a map, or a missing or unknown version.
    """
    if len(payload) > MAX_PAYLOAD_BYTES:
        msg = f"payload of {len(payload)} bytes is over the limit of {MAX_PAYLOAD_BYTES}"
        raise MessageError(msg)
    try:
        obj = msgpack.unpackb(payload, object_hook=_unpack_hook, raw=False, strict_map_key=True)
    except MessageError:
        raise
    except Exception as err:  # msgpack raises many types for garbage; all mean the same here
        msg = f"not a msgpack payload ({type(err).__name__}: {err})"
        raise MessageError(msg) from err
    if not isinstance(obj, dict):
        msg = f"payload is a {type(obj).__name__}, not a map"
        raise MessageError(msg)
    version = obj.get("v")
    if type(version) is not int or version != SCHEMA_VERSION:  # not True, not an array
        msg = f"unsupported schema version {version!r} (this build speaks v{SCHEMA_VERSION})"
        raise MessageError(msg)
    return obj
