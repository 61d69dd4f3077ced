"""The fleet's rooms: each robot's rooms and doors placed in the fleet's frame, each room once.

A robot's mapper divides the floor it saw into rooms (``common.rooms``); the merge service has no
floor of its own, so it takes the robots' rooms as they come, placed where each robot's frame
lies. Rooms of two robots that cover each other (``SAME_ROOM`` of the smaller one's floor) are
one room: its outline the better one's (closed before open, then the larger), its walls both
robots' (as fleet wall ids). Doors of two robots whose centres lie within ``DOOR_REACH`` are one
door. Room and door ids stay from update to update by their sources, as the walls' do
(``FleetIds``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common import se2
from wallmap.common.grid_labels import inside_polygon
from wallmap.common.map_fusion import FleetIds, Source

Array = NDArray[np.float64]
SAME_ROOM = 0.5  # share of the smaller room's floor that two robots' rooms share to be one
DOOR_REACH = 0.5  # m between two robots' door centres: one door
CELL = 0.1  # m: the grid rooms' floors are compared on


def fleet_rooms(
    rooms: Mapping[str, dict[str, Any]],
    poses: Mapping[str, Array],
    wall_ids: Mapping[Source, int],
    ids: tuple[FleetIds, FleetIds],
) -> dict[str, Any]:
    """The fleet's rooms payload (the contract's, in the fleet's frame) from each robot's.

    Args:
        rooms: each aligned robot's rooms reply, by prefix.
        poses: where each robot's frame lies in the fleet's.
        wall_ids: fleet wall id of each robot's wall.
        ids: the room ids and the door ids, kept by the caller between updates.
    """
    placed = [
        _placed(robot, room, poses[robot], wall_ids)
        for robot in rooms
        for room in rooms[robot]["rooms"]
    ]
    groups = _same_rooms(placed)
    room_ids, _ = ids[0].assign([tuple(placed[k]["source"] for k in g) for g in groups])
    fleet_room = {placed[k]["source"]: room_ids[n] for n, g in enumerate(groups) for k in g}
    doors = _doors(rooms, poses, wall_ids, fleet_room, ids[1])
    out = []
    for n, group in enumerate(groups):
        best = max((placed[k] for k in group), key=lambda r: (r["closed"], r["area"]))
        mine = sorted(d["id"] for d in doors if room_ids[n] in d["rooms"])
        walls = sorted({w for k in group for w in placed[k]["walls"]})
        polygon = best["polygon"].round(3).tolist()
        centroid = best["centroid"].round(3).tolist()
        out.append(
            {
                "id": room_ids[n],
                "polygon": polygon,
                "area": best["area"],
                "centroid": centroid,
                "walls": walls,
                "doors": mine,
                "closed": best["closed"],
            }
        )
    stamps = [r.get("stamp") for r in rooms.values() if r.get("stamp") is not None]
    return {
        "frame": "map",
        "stamp": max(stamps, default=None),
        "rooms": sorted(out, key=lambda r: r["id"]),
        "doors": doors,
    }


def _placed(robot: str, room: dict[str, Any], pose: Array, wall_ids: Mapping[Source, int]) -> dict:
    """A robot's room in the fleet's frame, with its floor's cells there."""
    polygon = se2.transform_points(np.asarray(room["polygon"], dtype=float).reshape(-1, 2), pose)
    return {
        "source": (robot, int(room["id"])),
        "polygon": polygon,
        "centroid": se2.transform_points(np.asarray(room["centroid"], dtype=float), pose),
        "area": float(room["area"]),
        "closed": bool(room["closed"]),
        "walls": [wall_ids[(robot, w)] for w in room["walls"] if (robot, w) in wall_ids],
        "cells": _cells(polygon),
    }


def _cells(polygon: Array) -> NDArray[np.int64]:
    """The grid cells (as single integers, sorted) whose centres lie inside a polygon."""
    if len(polygon) < 3:
        return np.zeros(0, dtype=np.int64)
    low = np.floor(polygon.min(axis=0) / CELL).astype(np.int64)
    high = np.ceil(polygon.max(axis=0) / CELL).astype(np.int64)
    i, j = np.meshgrid(np.arange(low[0], high[0]), np.arange(low[1], high[1]), indexing="ij")
    centres = (np.stack([i.ravel(), j.ravel()], axis=1) + 0.5) * CELL
    inside = inside_polygon(centres, polygon)
    return np.sort(i.ravel()[inside] * 1_000_003 + j.ravel()[inside])


def _same_rooms(placed: list[dict]) -> list[list[int]]:
    """Indices of the rooms that are one, most shared first, never two of one robot."""
    pairs = []
    for a in range(len(placed)):
        for b in range(a + 1, len(placed)):
            ra, rb = placed[a], placed[b]
            if ra["source"][0] == rb["source"][0]:
                continue
            shared = len(np.intersect1d(ra["cells"], rb["cells"], assume_unique=True))
            smaller = max(min(len(ra["cells"]), len(rb["cells"])), 1)
            if shared >= SAME_ROOM * smaller:
                pairs.append((-shared / smaller, a, b))
    members = {k: [k] for k in range(len(placed))}
    owner = list(range(len(placed)))
    for _, a, b in sorted(pairs):
        ga, gb = owner[a], owner[b]
        robots_a = {placed[k]["source"][0] for k in members[ga]}
        if ga == gb or robots_a & {placed[k]["source"][0] for k in members[gb]}:
            continue
        for k in members[gb]:
            owner[k] = ga
        members[ga] += members.pop(gb)
    return list(members.values())


def _doors(
    rooms: Mapping[str, dict[str, Any]],
    poses: Mapping[str, Array],
    wall_ids: Mapping[Source, int],
    fleet_room: Mapping[Source, int],
    door_ids: FleetIds,
) -> list[dict[str, Any]]:
    """The robots' doors placed, one door where two robots' centres nearly meet."""
    groups: list[list[tuple[str, dict[str, Any], Array]]] = []
    for robot, body in rooms.items():
        for door in body["doors"]:
            ends = se2.transform_points(
                np.array([door["p0"], door["p1"]], dtype=float), poses[robot]
            )
            centre = ends.mean(axis=0)
            near = [
                g
                for g in groups
                if robot not in {r for r, _, _ in g}
                and np.hypot(*(g[0][2].mean(axis=0) - centre)) <= DOOR_REACH
            ]
            if near:
                near[0].append((robot, door, ends))
            else:
                groups.append([(robot, door, ends)])
    door_list, _ = door_ids.assign([tuple((r, int(d["id"])) for r, d, _ in g) for g in groups])
    out = []
    for fleet_id, group in zip(door_list, groups, strict=True):
        robot, door, ends = group[0]
        joined = sorted(
            {fleet_room[(r, x)] for r, d, _ in group for x in d["rooms"] if (r, x) in fleet_room}
        )
        out.append(
            {
                "id": fleet_id,
                "center": ends.mean(axis=0).round(3).tolist(),
                "width": float(door["width"]),
                "p0": ends[0].round(3).tolist(),
                "p1": ends[1].round(3).tolist(),
                "wall": wall_ids.get((robot, int(door["wall"])), -1),
                "rooms": joined,
            }
        )
    return sorted(out, key=lambda d: d["id"])
