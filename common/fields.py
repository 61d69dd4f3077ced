"""Field validators for everything received: the wire messages and the map's records.

One module, so that a fault reads the same whichever message carried it: the field, what was
expected, what came (``field 'stamp' must be a finite number, got 'abc'``; ``field 'p0' is
missing``). Every fault is a :class:`~wallmap.common.codec.MessageError`.

The checks run on every frame and on every wall of a map reply, so the accepting path is a few
type tests in plain Python; describing what came, which may be large, is left to the refusal.
A nested field is named by its path (``free.ends``), an element of a list by the list's name.
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common.codec import MessageError

Point = tuple[float, float]

# What a refusal quotes of the value: enough to recognise it, never a whole cloud in a log line.
_QUOTE = reprlib.Repr()
_QUOTE.maxlevel, _QUOTE.maxlist, _QUOTE.maxtuple, _QUOTE.maxdict = 3, 4, 4, 4
_QUOTE.maxstring, _QUOTE.maxother, _QUOTE.maxlong = 40, 40, 40


def shown(value: Any) -> str:
    """``value`` as a refusal quotes it: short, whatever was sent (an array by dtype and shape)."""
    if isinstance(value, np.ndarray):
        return f"a {value.dtype} array of shape {value.shape}"
    if isinstance(value, bytes | bytearray | memoryview):
        return f"{len(value)} bytes"
    return _QUOTE.repr(value)


def refusal(name: str | None, expected: str, value: Any) -> MessageError:
    """The one wording of a fault: which field, what was expected, what came.

    ``name`` None is the message (or record) itself. Returned, not raised, so that the caller's
    ``raise`` shows where a check ends.
    """
    subject = "the message" if name is None else f"field {name!r}"
    return MessageError(f"{subject} must be {expected}, got {shown(value)}")


def required(m: Mapping[str, Any], key: str, name: str | None = None) -> Any:
    """``m[key]``; a missing one is named (by ``name``, its path, when it is nested)."""
    try:
        return m[key]
    except KeyError:
        msg = f"field {name or key!r} is missing"
        raise MessageError(msg) from None


def table(value: Any, name: str | None = None) -> Mapping[str, Any]:
    """A map (msgpack's, JSON's object); ``name`` None for the message itself."""
    if isinstance(value, Mapping):
        return value
    raise refusal(name, "a map", value)


def _finite(value: Any) -> bool:
    """A finite number; not a boolean (msgpack keeps them apart, so must we)."""
    if type(value) is float:  # nearly every one: spare the general test
        return math.isfinite(value)
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def number(value: Any, name: str) -> float:
    """A finite number, as a float."""
    if type(value) is float and math.isfinite(value):  # nearly every one: spare the general test
        return value
    if _finite(value):
        return float(value)
    raise refusal(name, "a finite number", value)


def optional_number(value: Any, name: str) -> float | None:
    """A finite number or None (a stamp before the first frame)."""
    return None if value is None else number(value, name)


def integer(value: Any, name: str) -> int:
    """An integer, not a boolean."""
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    raise refusal(name, "an integer", value)


def count(value: Any, name: str) -> int:
    """A non-negative integer (a sequence number, a tally)."""
    if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
        return value
    raise refusal(name, "a non-negative integer", value)


def string(value: Any, name: str) -> str:
    """A string."""
    if isinstance(value, str):
        return value
    raise refusal(name, "a string", value)


def flag(value: Any, name: str) -> bool:
    """A boolean: true or false, not 0 or 1."""
    if isinstance(value, bool):
        return value
    raise refusal(name, "true or false", value)


def listed(value: Any, name: str, length: int | None = None, layout: str = "") -> list[Any]:
    """A list (a tuple too), of ``length`` items when given; ``layout`` says what they are."""
    if isinstance(value, list | tuple) and (length is None or len(value) == length):
        return list(value)
    expected = "a list" if length is None else f"a list of {length} {layout}".rstrip()
    raise refusal(name, expected, value)


def _pair(value: Any) -> Point | None:
    """Two finite numbers as floats, or None: the caller words the fault."""
    if isinstance(value, list | tuple) and len(value) == 2:
        x, y = value
        if _finite(x) and _finite(y):
            return float(x), float(y)
    return None


def point(value: Any, name: str) -> Point:
    """A point ``[x, y]`` of finite numbers, or an array of two (the codec sends numpy ones)."""
    pair = _pair(value)
    if pair is None and isinstance(value, np.ndarray):  # its float32 items are no Python floats
        pair = _pair(value.tolist())
    if pair is None:
        raise refusal(name, "a point [x, y] of finite numbers", value)
    return pair


def plain_matrix2(value: Any) -> tuple[Point, Point] | None:
    """Two rows of two finite numbers (not booleans) as floats, or None: the caller words it."""
    if isinstance(value, list | tuple) and len(value) == 2:
        first, second = _pair(value[0]), _pair(value[1])
        if first is not None and second is not None:
            return first, second
    return None


def matrix2(value: Any, name: str) -> tuple[Point, Point]:
    """A 2x2 matrix of finite numbers as two rows, in plain Python; worded as :func:`array`.

    For a wall's covariance, on every wall of a map reply, where numpy's cost per call would be
    most of the check.
    """
    rows = plain_matrix2(value)
    if rows is None:
        raise refusal(name, "finite numbers of shape (2, 2)", value)
    return rows


def array(value: Any, shape: tuple[int, ...], name: str) -> NDArray[np.float64]:
    """An array of finite numbers of ``shape``, as float64 (a new array, never the one sent)."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise refusal(name, f"finite numbers of shape {shape}", value) from None
    if arr.shape != shape or not np.isfinite(arr).all():
        raise refusal(name, f"finite numbers of shape {shape}", value)
    return arr
