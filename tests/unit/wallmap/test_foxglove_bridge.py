"""The Foxglove bridge: poses, observations and the map as Foxglove messages.

The Foxglove messages are protobuf; no protobuf library is needed to check them: a small reader
of the wire format decodes them with the descriptors that travel in their own schemas, so the
tests read fields by their Foxglove names.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from foxglove_wire import decode, descriptor_types, one, stamp_ns

from wallmap.common.map_records import MapReply, MapUpdate
from wallmap.common.messages import Observations, Pose, WallObservation


def _xyz(point: dict[str, list[Any]]) -> tuple[float, float, float]:
    return one(point, "x"), one(point, "y"), one(point, "z")


def _fox(message: Any) -> dict[str, list[Any]]:
    """A foxglove message object, encoded and read back."""
    schema = message.get_schema()
    return decode(message.encode(), schema.name, descriptor_types(schema.data))


def _wall(wall_id: int, *, tentative: bool = False, x: float = 1.0) -> dict[str, Any]:
    return {
        "id": wall_id,
        "u": x,
        "v": 0.0,
        "cov": [[1e-4, 0.0], [0.0, 1e-4]],
        "p0": [x, -1.0],
        "p1": [x, 2.0],
        "segments": [[[x, -1.0], [x, 0.5]], [[x, 1.0], [x, 2.0]]],
        "n_obs": 5,
        "n_views": 3,
        "tentative": tentative,
        "first_seen": 1.0,
        "last_seen": 2.0,
    }


def _obs(stamp: float, *segments: tuple[tuple[float, float], tuple[float, float]]) -> Observations:
    walls = [
        WallObservation(
            closest=np.array([p0[0], 0.5]),  # not used for drawing
            cov=np.eye(2) * 1e-4,
            p0=np.array(p0),
            p1=np.array(p1),
            n_points=40,
            rms=0.01,
        )
        for p0, p1 in segments
    ]
    return Observations(run="r", seq=0, stamp=stamp, frame="base_link", walls=walls)


def test_stamps_become_exact_nanoseconds() -> None:
    fb = pytest.importorskip("wallmap.foxglove_bridge")
    # A double holds an epoch stamp to about 0.2 us; the conversion adds no error of its own.
    assert fb.nanoseconds(1700000002.73) == 1_700_000_002_730_000_019
    assert fb.nanoseconds(12.0) == 12_000_000_000
    ts = fb.timestamp(1_700_000_002_730_000_001)
    assert (ts.sec, ts.nsec) == (1_700_000_002, 730_000_001)


def test_a_pose_becomes_a_pose_in_frame_and_a_transform() -> None:
    fb = pytest.importorskip("wallmap.foxglove_bridge")
    outs = fb.Bridge().pose(Pose(stamp=5.25, x=1.0, y=2.0, yaw=math.pi / 2))
    assert [o.topic for o in outs] == ["/wallmap/pose", "/tf"]
    assert {o.log_time for o in outs} == {5_250_000_000}
    pose = _fox(outs[0].message)
    assert one(pose, "frame_id") == "map"
    assert stamp_ns(pose) == 5_250_000_000
    assert _xyz(one(one(pose, "pose"), "position")) == (1.0, 2.0, 0.0)
    q = one(one(pose, "pose"), "orientation")
    assert one(q, "z") == pytest.approx(math.sqrt(0.5))
    assert one(q, "w") == pytest.approx(math.sqrt(0.5))
    (tf,) = _fox(outs[1].message)["transforms"]
    assert (one(tf, "parent_frame_id"), one(tf, "child_frame_id")) == ("map", "base_link")
    assert _xyz(one(tf, "translation")) == (1.0, 2.0, 0.0)


def test_every_wall_map_message_is_the_whole_map() -> None:
    fb = pytest.importorskip("wallmap.foxglove_bridge")
    bridge = fb.Bridge()
    reply = {
        "frame": "map",
        "frames": 10,
        "observations": 20,
        "stamp": 3.0,
        "walls": [_wall(1), _wall(2, tentative=True)],
        "trajectory": [[1.0, 0.0, 0.0, 0.0], [2.0, 0.5, 0.0, 0.1]],
    }
    outs = bridge.map_reply(MapReply.from_map(reply))
    assert [(o.topic, o.log_time) for o in outs] == [
        ("/wallmap/trajectory", 2_000_000_000),
        ("/wallmap/walls", 3_000_000_000),
    ]
    assert len(_fox(outs[0].message)["poses"]) == 2
    scene = _fox(outs[1].message)
    assert one(one(scene, "deletions"), "type") == 1  # ALL: the message replaces the scene
    first, second = scene["entities"]
    assert [one(e, "id") for e in (first, second)] == ["wall/1", "wall/2"]
    metadata = {one(kv, "key"): one(kv, "value") for kv in first["metadata"]}
    assert metadata["id"] == "1"
    assert metadata["tentative"] == "false"
    assert one(one(first, "texts"), "text") == "1"
    (line,) = first["lines"]
    assert one(line, "type") == 2  # LINE_LIST: one pair of points per segment
    assert [_xyz(p)[:2] for p in line["points"]] == [
        (1.0, -1.0),
        (1.0, 0.5),
        (1.0, 1.0),
        (1.0, 2.0),
    ]
    assert one(second["lines"][0], "color") != one(line, "color")  # tentative stands out

    update = {"frames": 12, "stamp": 4.0, "walls": [_wall(3, x=2.0)], "removed": [1]}
    (out,) = bridge.map_update(MapUpdate.from_map(update))
    assert out.log_time == 4_000_000_000
    assert [one(e, "id") for e in _fox(out.message)["entities"]] == ["wall/2", "wall/3"]
    assert set(bridge.latest) == {"/wallmap/walls", "/wallmap/trajectory"}
    assert bridge.latest["/wallmap/walls"] is out


def test_an_empty_map_sends_nothing() -> None:
    fb = pytest.importorskip("wallmap.foxglove_bridge")
    reply = {"frame": "map", "frames": 0, "observations": 0, "stamp": None, "walls": []}
    assert fb.Bridge().map_reply(MapReply.from_map({**reply, "trajectory": []})) == []


def test_observations_are_placed_with_the_pose_at_their_stamp() -> None:
    fb = pytest.importorskip("wallmap.foxglove_bridge")
    bridge = fb.Bridge()
    segment = ((1.0, 0.0), (1.0, 1.0))
    assert bridge.observations(_obs(0.0, segment)) == []  # no pose yet: it waits for one
    first = bridge.pose(Pose(stamp=0.0, x=0.0, y=0.0, yaw=math.pi / 2))
    assert [out.topic for out in first] == ["/wallmap/pose", "/tf", "/wallmap/observations"]
    assert len(bridge.pose(Pose(stamp=0.1, x=1.0, y=0.0, yaw=math.pi / 2))) == 2  # sent once
    bridge.pose(Pose(stamp=0.2, x=2.0, y=0.0, yaw=math.pi / 2))

    def points(stamp: float) -> list[tuple[float, float, float]]:
        (out,) = bridge.observations(_obs(stamp, segment))
        assert out.topic == "/wallmap/observations"
        assert out.log_time == fb.nanoseconds(stamp)
        (entity,) = _fox(out.message)["entities"]
        assert one(entity, "frame_id") == "map"
        return [tuple(round(c, 9) for c in _xyz(p)) for p in one(entity, "lines")["points"]]

    # At 0.1 the robot was at x = 1 facing +y: base (1, 0) is map (1, 1), base (1, 1) is (0, 1).
    assert points(0.1) == [(1.0, 1.0, 0.02), (0.0, 1.0, 0.02)]
    assert points(0.15)[0] == (1.5, 1.0, 0.02)  # interpolated, not the latest pose
    assert points(9.0)[0] == (2.0, 1.0, 0.02)  # beyond every pose: the latest stands in
    (out,) = bridge.observations(_obs(0.2))
    assert _fox(out.message)["entities"][0]["lines"] == []  # a frame without walls clears them


def test_rooms_are_outlines_labelled_with_id_and_area_and_doors_are_spans() -> None:
    fb = pytest.importorskip("wallmap.foxglove_bridge")
    square = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]
    room = {"id": 3, "polygon": square, "area": 16.0, "centroid": [2.0, 2.0], "walls": [1, 2]}
    room |= {"doors": [0], "closed": True}
    door = {"id": 0, "center": [4.0, 2.0], "width": 1.0, "p0": [4.0, 1.5], "p1": [4.0, 2.5]}
    door |= {"wall": 2, "rooms": [3]}
    body = {"v": 1, "frame": "map", "stamp": 5.0, "rooms": [room], "doors": [door]}
    (out,) = fb.Bridge().rooms(body)
    assert (out.topic, out.log_time) == ("/wallmap/rooms", 5_000_000_000)
    scene = _fox(out.message)
    assert one(one(scene, "deletions"), "type") == 1  # ALL: the message replaces the scene
    room, door = scene["entities"]
    assert (one(room, "id"), one(door, "id")) == ("room/3", "door/0")
    assert one(one(room, "texts"), "text") == "R3 16.0 m²"
    (outline,) = room["lines"]
    assert one(outline, "type") == 1  # LINE_LOOP: the outline closes on itself
    assert [_xyz(p)[:2] for p in outline["points"]] == [tuple(p) for p in square]
    metadata = {one(kv, "key"): one(kv, "value") for kv in room["metadata"]}
    assert (metadata["area"], metadata["closed"], metadata["walls"]) == ("16.0", "true", "[1, 2]")
    assert [_xyz(p)[:2] for p in one(door, "lines")["points"]] == [(4.0, 1.5), (4.0, 2.5)]


def test_a_rooms_reply_without_the_contract_fields_is_refused() -> None:
    fb = pytest.importorskip("wallmap.foxglove_bridge")
    with pytest.raises(KeyError):
        fb.Bridge().rooms({"rooms": [{"id": 1}], "doors": []})
