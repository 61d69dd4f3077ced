"""Rooms and doors through real processes: `wallmap up --json-out`, `wallmap query --rooms`.

A generated strip of three rooms joined by two doorways, played --fast through router, player,
detector and mapper; the rooms and doors the mapper serves against the plan's truth.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from conftest import free_port, run_wallmap

from wallmap.common.link_settings import ZenohSettings
from wallmap.common.transport import Keys, open_session
from wallmap.room_evaluation import iou
from wallmap.scene import load_truth, write_scene_bag
from wallmap.scene.floorplan import glass_wall_plan
from wallmap.services.mapper import ros2_out

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def strip(scene_bags):
    """Seed 1: three rooms, two doorways; glass in two outer walls (the rooms there open)."""
    return scene_bags("rooms.bag", seed=1, n_frames=900, fmt="ros1", sensor="depth16")


def _assert_rooms_match(body: dict, truth_path) -> None:
    plan = load_truth(truth_path)[0]
    assert body["v"] == 1
    assert body["frame"] == "map"
    rooms = {r["id"]: r for r in body["rooms"]}
    assert len(rooms) == len(plan.rooms), "no false, split or missed room"
    truth_of = {}
    for room_id, room in rooms.items():
        score, truth_of[room_id] = max((iou(room["polygon"], t.polygon), t.id) for t in plan.rooms)
        assert score >= 0.7, (room_id, score)
        assert room["area"] == pytest.approx(abs(_area(room["polygon"])), rel=1e-2)
    assert len(set(truth_of.values())) == len(rooms), "one to one"
    assert max(iou(r["polygon"], plan.rooms[truth_of[i]].polygon) for i, r in rooms.items()) > 0.9
    assert len(body["doors"]) == len(plan.doors)
    for door in plan.doors:
        centre = np.add(door.p0, door.p1) / 2
        found = min(body["doors"], key=lambda d: np.hypot(*(np.array(d["center"]) - centre)))
        assert np.hypot(*(np.array(found["center"]) - centre)) < 0.3
        assert abs(found["width"] - np.hypot(*np.subtract(door.p1, door.p0))) < 0.3
        assert sorted(truth_of[r] for r in found["rooms"]) == sorted(door.rooms)
        assert all(found["id"] in rooms[r]["doors"] for r in found["rooms"])


def _own_router() -> tuple[str, str]:
    """A free loopback port for `wallmap up`'s router: the default one is the docs' alone."""
    return ("--connect", f"tcp/127.0.0.1:{free_port()}")


def _area(polygon: list) -> float:
    x, y = np.asarray(polygon).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def test_up_writes_the_rooms_and_doors_of_the_building(strip, tmp_path) -> None:
    out = tmp_path / "map.json"
    run_wallmap(
        *("up", *_own_router()),
        str(strip.path),
        "--fast",
        "--exit-when-done",
        "--json-out",
        str(out),
        *_own_router(),
    )
    _assert_rooms_match(json.loads(out.read_text())["rooms"], strip.truth_path)


def test_query_plot_and_export_show_the_live_mappers_rooms(stack, strip, tmp_path) -> None:
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    stack.run("player", str(strip.path), "--fast", *stack.zenoh_args)
    done = stack.run("query", "--rooms", "--json", *stack.zenoh_args, timeout=30)
    _assert_rooms_match(json.loads(done.stdout), strip.truth_path)
    table = stack.run("query", "--rooms", *stack.zenoh_args, timeout=30).stdout
    assert table.startswith("3 rooms, 2 doors")

    svg, geojson = tmp_path / "map.svg", tmp_path / "map.geojson"
    stack.run("plot", str(svg), *stack.zenoh_args, timeout=30)
    drawn = svg.read_text()
    assert drawn.count('<polygon class="room"') == 3
    assert drawn.count('class="door"') == 2
    assert drawn.count('class="room-label"') == 3
    stack.run("export", str(geojson), *stack.zenoh_args, timeout=30)
    features = json.loads(geojson.read_text())["features"]
    polygons = [f for f in features if f["properties"]["kind"] == "room"]
    doors = [f for f in features if f["properties"]["kind"] == "door"]
    assert [f["geometry"]["type"] for f in polygons] == ["Polygon"] * 3
    assert [f["geometry"]["type"] for f in doors] == ["LineString"] * 2
    ring = polygons[0]["geometry"]["coordinates"][0]
    assert ring[0] == ring[-1], "a closed ring"
    # ROS 2 out: the rooms' markers, held for a late subscriber as a transient-local topic.
    keys = Keys(stack.prefix)
    with open_session(ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)) as session:
        replies = list(session.get(keys.room_markers, timeout=5.0))
        # Asked as JSON, each of the map's queryables answers JSON with the schema version; a
        # format neither msgpack nor JSON is refused, saying why.
        for key, part in ((keys.map_rooms, "rooms"), (keys.map_walls, "walls")):
            (reply,) = session.get(f"{key}?format=json", timeout=5.0)
            body = json.loads(reply.ok.payload.to_bytes())
            assert body["v"] == 1
            assert len(body[part]) >= 3, body
            assert str(reply.ok.encoding).startswith("application/json")
            (refused,) = session.get(f"{key}?format=xml", timeout=5.0)
            assert refused.ok is None
            assert "format must be msgpack or json" in refused.err.payload.to_string()
    array = ros2_out.decode(replies[0].ok.payload.to_bytes(), "visualization_msgs/msg/MarkerArray")
    assert sorted({m.ns for m in array.markers}) == ["doors", "room_labels", "rooms"]
    assert sum(m.ns == "rooms" for m in array.markers) == 3


def test_a_glass_stretch_in_a_wall_is_one_wall_and_no_door(tmp_path) -> None:
    """3.6 m of floor-to-ceiling glass in the middle of a 10 m wall, solid wall either side."""
    info = write_scene_bag(
        tmp_path / "glass.bag",
        seed=2,
        n_frames=600,
        fmt="ros1",
        sensor="depth16",
        plan=glass_wall_plan(2, glass=3.6),
    )
    out = tmp_path / "map.json"
    done = run_wallmap(
        "up",
        str(info.path),
        "--fast",
        "--exit-when-done",
        "--json-out",
        str(out),
        "--truth",
        str(info.truth_path),
    )
    scored = re.search(r"precision ([\d.]+) .*recall ([\d.]+) .*duplicates (\d+)", done.stdout)
    assert scored, done.stdout
    precision, recall, duplicates = float(scored[1]), float(scored[2]), int(scored[3])
    assert duplicates == 0, done.stdout
    assert precision >= 0.98
    assert recall >= 0.95
    body = json.loads(out.read_text())
    assert len([w for w in body["walls"] if not w["tentative"]]) == 4
    assert body["rooms"]["doors"] == []
    (room,) = body["rooms"]["rooms"]
    assert room["closed"]
    assert room["area"] == pytest.approx(60.0, rel=0.03)
    assert "rooms entered 1 of 1 found" in done.stdout
