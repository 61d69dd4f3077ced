"""The fleet's map as the merge service keeps it: robots placed when their maps overlap enough,
each wall once, ids that stay, the replies the contract asks for."""

from __future__ import annotations

import math

import numpy as np

from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply, WallRecord
from wallmap.scene.floorplan import generate_floorplan
from wallmap.services.merge.fleet import Fleet

FRAME_B = np.array([4.0, -3.0, 1.1])  # where robot B's map frame lies in A's


def _records(segments: np.ndarray, first_id: int) -> tuple[WallRecord, ...]:
    return tuple(
        WallRecord.from_segment(first_id + k, p, q, n_obs=5) for k, (p, q) in enumerate(segments)
    )


def _maps() -> tuple[np.ndarray, np.ndarray]:
    """The building's solid walls as A has them, and as B has them in its own frame."""
    world = np.array([[w.p0, w.p1] for w in generate_floorplan(2).walls if not w.glass])
    c, s = math.cos(FRAME_B[2]), math.sin(FRAME_B[2])
    return world, (world - FRAME_B[:2]) @ np.array([[c, -s], [s, c]])


def test_a_robot_is_placed_once_its_map_overlaps_and_its_walls_fuse_with_the_first_ones() -> None:
    world, seen_by_b = _maps()
    fleet = Fleet(["A", "B"])
    fleet.take("A", MapReply(frames=10, walls=_records(world, 0)))
    fleet.take("B", MapReply(frames=4, walls=_records(seen_by_b[:2], 100)))  # two walls: too few
    changes = fleet.update()
    assert changes is not None
    assert len(changes.walls) == len(world), "A's walls, as they are"
    robots = {r["prefix"]: r for r in fleet.robots_reply()["robots"]}
    assert robots["A"]["aligned"]
    assert robots["A"]["x"] == robots["A"]["y"] == robots["A"]["yaw"] == 0.0
    assert robots["B"] == {"prefix": "B", "aligned": False, "frames": 4}
    ids_before = {w.sources: i for i, w in fleet.walls.items()}

    fleet.take("B", MapReply(frames=9, walls=_records(seen_by_b, 100)))
    changes = fleet.update()
    robots = {r["prefix"]: r for r in fleet.robots_reply()["robots"]}
    assert robots["B"]["aligned"]
    found = np.array([robots["B"][k] for k in ("x", "y", "yaw")])
    assert np.allclose(found, FRAME_B, atol=1e-6)
    assert robots["B"]["walls_matched"] == len(world)
    reply = fleet.reply(MapQuery())
    assert len(reply.walls) == len(world), "each wall once"
    assert all({r for r, _ in w.sources} == {"A", "B"} for w in reply.walls)
    assert reply.frames == 19
    for wall in reply.walls:  # A's ids stay: each wall keeps the id it had
        (a_source,) = [s for s in wall.sources if s[0] == "A"]
        assert ids_before[(a_source,)] == wall.id
    assert changes is not None
    assert changes.removed == ()
    assert fleet.update() is None, "nothing new: nothing to say"


def test_the_fleets_reply_is_the_contracts_with_sources_and_selects_as_a_map_query() -> None:
    world, seen_by_b = _maps()
    fleet = Fleet(["A", "B"])
    fleet.take("A", MapReply(frames=1, walls=_records(world, 0)))
    fleet.take("B", MapReply(frames=1, walls=_records(seen_by_b, 0)))
    fleet.update()
    body = fleet.reply(MapQuery()).to_map()
    assert {"frames", "observations", "stamp", "walls", "merges"} <= set(body)
    assert all(len(w["sources"]) == 2 for w in body["walls"])
    assert WallRecord.from_map(body["walls"][0]).sources == fleet.walls[0].sources
    assert fleet.reply(MapQuery(min_obs=11)).walls == ()
    box = fleet.reply(MapQuery(bbox=(-100.0, -100.0, -99.0, -99.0)))
    assert box.walls == (), "no wall crosses a box far away"


def test_a_robot_whose_map_starts_again_is_placed_again() -> None:
    """B's mapper restarted without its state file, switched on elsewhere: fewer frames, a new
    frame. Where it lies is searched for afresh, and its old walls leave the fleet's map."""
    world, seen_by_b = _maps()
    fleet = Fleet(["A", "B"])
    fleet.take("A", MapReply(frames=10, walls=_records(world, 0)))
    fleet.take("B", MapReply(frames=50, walls=_records(seen_by_b, 0)))
    fleet.update()
    moved = np.array([-2.0, 5.0, -0.4])
    c, s = math.cos(moved[2]), math.sin(moved[2])
    again = (world - moved[:2]) @ np.array([[c, -s], [s, c]])
    fleet.take("B", MapReply(frames=3, walls=_records(again[:2], 0)))  # a new map, two walls yet
    fleet.update()
    robots = {r["prefix"]: r for r in fleet.robots_reply()["robots"]}
    assert not robots["B"]["aligned"]
    assert all(w.sources == (("A", w.sources[0][1]),) for w in fleet.walls.values())
    fleet.take("B", MapReply(frames=9, walls=_records(again, 0)))
    fleet.update()
    found = fleet.robots["B"].alignment
    assert found is not None
    assert np.allclose(found.pose, moved, atol=1e-6)
    assert len(fleet.walls) == len(world), "no wall twice"
