"""One wording for a fault, whichever message carried it: a detector's wall on the wire and a
wall record of the map reply refuse the same fault in the same words."""

from __future__ import annotations

import math
from typing import Any

import msgpack
import numpy as np
import pytest

from wallmap.common import codec, fields
from wallmap.common.codec import MessageError
from wallmap.common.map_records import MapReply, MapUpdate, WallRecord
from wallmap.common.messages import (
    Frame,
    Observations,
    Pose,
    WallObservation,
    unpack_frame,
    unpack_observations,
    unpack_pose,
)

MISSING = object()
WALL = WallObservation(
    np.array([0.0, 2.0]), np.eye(2) * 1e-4, np.array([-1.0, 2.0]), np.array([1.0, 2.0]), 30, 0.01
)
RECORD = WallRecord.from_segment(4, (-1.0, 2.0), (1.0, 2.0), n_obs=3)


def _with(m: dict[str, Any], key: str, value: object) -> dict[str, Any]:
    changed = {k: v for k, v in m.items() if k != key}
    return changed if value is MISSING else {**changed, key: value}


def _refusal(unpack: Any, payload: Any) -> str:
    with pytest.raises(MessageError) as err:
        unpack(payload)
    return str(err.value)


def _wire_wall(key: str, value: object) -> str:
    """The fault in a wall of the detector's observations, packed and unpacked as on the wire."""
    wall = _with(WALL.to_map(), key, value)
    body = {**Observations("run", 1, 2.0, "base_link").to_map(), "walls": [wall]}
    return _refusal(unpack_observations, codec.encode(body))


def _map_wall(key: str, value: object) -> str:
    """The fault in a wall record of a map reply, through msgpack as the map client gets it."""
    record = _with(RECORD.to_map(), key, value)
    body = {**MapReply(walls=(RECORD,)).to_map(), "walls": [record]}
    return _refusal(MapReply.from_map, msgpack.unpackb(msgpack.packb(body)))


@pytest.mark.parametrize(
    ("key", "value", "reason"),
    [
        ("u", "abc", "field 'u' must be a finite number, got 'abc'"),  # wrong type
        ("u", True, "field 'u' must be a finite number, got True"),  # a boolean is no number
        ("v", None, "field 'v' must be a finite number, got None"),
        ("u", math.nan, "field 'u' must be a finite number, got nan"),  # non-finite
        ("v", -math.inf, "field 'v' must be a finite number, got -inf"),
        ("p0", MISSING, "field 'p0' is missing"),  # missing
        ("cov", MISSING, "field 'cov' is missing"),
        (
            "p1",
            [1.0, 2.0, 3.0],
            "field 'p1' must be a point [x, y] of finite numbers, got [1.0, 2.0, 3.0]",
        ),  # wrong length
        (
            "p0",
            [1.0, math.nan],
            "field 'p0' must be a point [x, y] of finite numbers, got [1.0, nan]",
        ),
        ("p0", "ab", "field 'p0' must be a point [x, y] of finite numbers, got 'ab'"),
        (
            "cov",
            [[1e-4, 0.0], [0.0]],
            "field 'cov' must be finite numbers of shape (2, 2), got [[0.0001, 0.0], [0.0]]",
        ),
        (
            "cov",
            [[1e-4, 0.0], [0.0, math.inf]],
            "field 'cov' must be finite numbers of shape (2, 2), got [[0.0001, 0.0], [0.0, inf]]",
        ),
    ],
)
def test_a_wall_s_fault_reads_the_same_on_the_wire_and_in_the_map(
    key: str, value: object, reason: str
) -> None:
    assert _wire_wall(key, value) == reason
    assert _map_wall(key, value) == reason


@pytest.mark.parametrize(
    ("value", "expected"),
    [(1.5, "an integer, got 1.5"), ("7", "an integer, got '7'"), (False, "an integer, got False")],
)
def test_an_integer_s_fault_reads_the_same_in_either(value: object, expected: str) -> None:
    """The wire's wall counts ``n_points``, the map's ``n_obs``: the same words but the name."""
    assert _wire_wall("n_points", value) == f"field 'n_points' must be {expected}"
    assert _map_wall("n_obs", value) == f"field 'n_obs' must be {expected}"


def test_a_stamp_a_list_and_the_message_itself_read_the_same_in_either() -> None:
    pose = Pose(1.0, 0.0, 0.0, 0.0).to_map()
    reply = MapReply(stamp=1.0).to_map()
    stamp = "field 'stamp' must be a finite number, got 'now'"
    assert _refusal(unpack_pose, codec.encode({**pose, "stamp": "now"})) == stamp
    assert _refusal(MapReply.from_map, {**reply, "stamp": "now"}) == stamp
    assert _refusal(MapUpdate.from_map, {"frames": 1, "stamp": "now"}) == stamp
    observations = Observations("run", 1, 2.0, "base_link").to_map()
    walls = "field 'walls' must be a list, got 'none'"
    assert _refusal(unpack_observations, codec.encode({**observations, "walls": "none"})) == walls
    assert _refusal(MapReply.from_map, {**reply, "walls": "none"}) == walls
    missing = "field 'walls' is missing"
    assert (
        _refusal(unpack_observations, codec.encode(_with(observations, "walls", MISSING)))
        == missing
    )
    assert _refusal(MapReply.from_map, _with(reply, "walls", MISSING)) == missing
    not_a_map = "the message must be a map, got [1, 2]"
    assert _refusal(Pose.from_map, [1, 2]) == not_a_map
    assert _refusal(MapReply.from_map, [1, 2]) == not_a_map
    flag = "field '{}' must be true or false, got 'yes'"
    frame = Frame("run", 1, 2.0, "camera", np.zeros((1, 2, 3), np.float32), np.eye(4)).to_map()
    assert _refusal(unpack_frame, codec.encode({**frame, "lossless": "yes"})) == flag.format(
        "lossless"
    )
    assert _map_wall("tentative", "yes") == flag.format("tentative")


def test_a_refusal_quotes_what_came_briefly() -> None:
    """A log line names the fault; it never holds a whole cloud, however much was sent."""
    long = fields.refusal("free.ends", "a list", list(range(100_000)))
    assert str(long) == "field 'free.ends' must be a list, got [0, 1, 2, 3, ...]"
    deep = fields.shown([[[[[1.0]]]]])
    assert len(deep) < 40
    text = fields.shown("x" * 10_000)
    assert "..." in text
    assert len(text) <= 40
    assert (
        fields.shown(np.zeros((480, 640, 3), np.float32))
        == "a float32 array of shape (480, 640, 3)"
    )
    assert fields.shown(b"\x00" * 1000) == "1000 bytes"


def test_the_accepting_path_returns_plain_values() -> None:
    assert fields.number(3, "x") == 3.0
    assert type(fields.number(3, "x")) is float
    assert fields.point((1, 2.5), "p") == (1.0, 2.5)
    assert fields.matrix2([[1, 0], (0, 2.0)], "cov") == ((1.0, 0.0), (0.0, 2.0))
    assert fields.optional_number(None, "stamp") is None
    assert fields.listed((1, 2), "l", 2) == [1, 2]
    assert fields.count(0, "seq") == 0
    np.testing.assert_array_equal(fields.array([[1, 2]], (1, 2), "a"), [[1.0, 2.0]])
    with pytest.raises(MessageError, match=r"field 'seq' must be a non-negative integer, got -1"):
        fields.count(-1, "seq")
    with pytest.raises(MessageError, match=r"field 'run' must be a string, got 5"):
        fields.string(5, "run")
    with pytest.raises(MessageError, match=r"field 'free.ends' is missing"):
        fields.required({}, "ends", "free.ends")


def test_a_wall_s_ends_may_come_as_arrays_as_before() -> None:
    """The codec turns a packed array into numpy: a sender that packs ``p0`` so is not refused."""
    body = {
        **Observations("run", 1, 2.0, "base_link").to_map(),
        "walls": [{**WALL.to_map(), "p0": np.array([-1.0, 2.0], np.float32)}],
    }
    wall = unpack_observations(codec.encode(body)).walls[0]
    np.testing.assert_array_equal(wall.p0, [-1.0, 2.0])
    assert wall.p0.dtype == np.float64
    bad = {**body, "walls": [{**WALL.to_map(), "p0": np.zeros(3)}]}
    reason = (
        "field 'p0' must be a point [x, y] of finite numbers, got a float64 array of shape (3,)"
    )
    assert _refusal(unpack_observations, codec.encode(bad)) == reason
