"""The rooms' ids: kept while the map grows, and across a restart on the state file."""

from __future__ import annotations

import json

import numpy as np

from wallmap.common.map_records import WallRecord
from wallmap.scene.floorplan import free_rays, generate_floorplan, smooth_route
from wallmap.services.mapper.room_map import RoomMap, _cells, _keys


def _records(plan) -> tuple[WallRecord, ...]:
    return tuple(
        WallRecord(
            id=w.id,
            u=0.0,
            v=0.0,
            cov=((1e-4, 0.0), (0.0, 1e-4)),
            p0=w.p0,
            p1=w.p1,
            segments=((w.p0, w.p1),),
            n_obs=10,
        )
        for w in plan.walls
    )


def _drive(rooms: RoomMap, plan, route: np.ndarray) -> None:
    for at in route:
        rooms.add_frame(np.array([*at, 0.0]), np.zeros(2), free_rays(plan, at))


def test_ids_stay_as_the_map_grows_and_across_a_restart() -> None:
    plan = generate_floorplan(1, glass_fraction=0.0)
    route = smooth_route(plan.route)[::3]
    rooms = RoomMap()
    _drive(rooms, plan, route[: len(route) // 2])
    first = rooms.update(_records(plan), 1.0)
    _drive(rooms, plan, route[len(route) // 2 :])
    second = rooms.update(_records(plan), 2.0)
    assert len(second.rooms) == 3
    assert len(second.doors) == 2
    kept = {r.id: r.centroid for r in first.rooms}
    for room in second.rooms:
        if room.id in kept:
            assert np.hypot(*np.subtract(room.centroid, kept[room.id])) < 2.0
    assert {r.id for r in first.rooms} <= {r.id for r in second.rooms}, "no id given up"
    assert rooms.update(_records(plan), 2.0) == second, "nothing new: the same rooms and ids"
    body = second.to_map()
    assert body["v"] == 1
    assert body["frame"] == "map"
    assert all(set(d["rooms"]) <= {r["id"] for r in body["rooms"]} for d in body["doors"])

    restarted = RoomMap()
    restarted.restore(json.loads(json.dumps(rooms.to_json())))
    again = restarted.update(_records(plan), 3.0)
    assert [(r.id, r.polygon) for r in again.rooms] == [(r.id, r.polygon) for r in second.rooms]
    assert [(d.id, d.center) for d in again.doors] == [(d.id, d.center) for d in second.doors]
    more = restarted.update(_records(plan)[:-1], 4.0)  # a wall gone: the rooms may change
    assert max(r.id for r in more.rooms) < restarted.next_room
    back = restarted.update(_records(plan), 5.0)
    assert (back.rooms, back.doors) == (again.rooms, again.doors), "the wall back: as before"


def test_cells_come_back_from_their_keys_on_every_side_of_the_origin() -> None:
    """The state file keeps a room's cells as sorted integer keys, negative indices too."""
    cells = np.array([[3, -5], [-2, 7], [0, 0], [-1, -1], [100_000, -(2**31)], [5, 2**31 - 1]])
    back = _cells(_keys(cells))
    assert sorted(map(tuple, back.tolist())) == sorted(map(tuple, cells.tolist()))
