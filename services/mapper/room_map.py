"""The map's rooms and doors, kept current off the frame path, with ids that stay.

Frames hand over their free rays and pose (``add_frame``: an append, nothing computed); an
update (``update``, on the mapper's rooms worker, about once a second while the map grows)
draws them into the ``FreeSpace`` grid and segments the floor anew (``common.rooms``) from the
served walls. A segmentation does not know yesterday's ids, so each new room takes the id of
the old room it overlaps most (most shared cells, at least ``KEEP_SHARE`` of the smaller), and
each door the id of an old door within ``DOOR_REACH`` of its centre; the rest get new ids, never
reused. The grid, the rooms' cells and the counters go into the state file, so a mapper
restarted on it serves the same ids.
"""

from __future__ import annotations

import base64
import threading
import time
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common import compiled
from wallmap.common.free_space import FreeSpace
from wallmap.common.map_records import WallRecord
from wallmap.common.rooms import (
    Layout,
    Outlines,
    RoomsConfig,
    RoomShape,
    WallSegments,
    find_rooms,
)

Array = NDArray[np.float64]

KEEP_SHARE = 0.3  # of the smaller room's cells shared with an old room: the same room
DOOR_REACH = 0.5  # m between an old door's centre and a new one's: the same door
KEEP_MOVE = 0.1  # m the robot moves, or
KEEP_TURN = np.radians(5.0)  # it turns, before a frame's rays are drawn again


@dataclass(frozen=True)
class DoorRecord:
    """A door as served (the contract's door record)."""

    id: int
    center: tuple[float, float]
    width: float
    p0: tuple[float, float]
    p1: tuple[float, float]
    wall: int
    rooms: tuple[int, ...]

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding."""
        return {
            "id": self.id,
            "center": list(self.center),
            "width": self.width,
            "p0": list(self.p0),
            "p1": list(self.p1),
            "wall": self.wall,
            "rooms": list(self.rooms),
        }


@dataclass(frozen=True)
class RoomRecord:
    """A room as served (the contract's room record)."""

    id: int
    polygon: tuple[tuple[float, float], ...]
    area: float
    centroid: tuple[float, float]
    walls: tuple[int, ...]
    doors: tuple[int, ...]
    closed: bool

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding."""
        return {
            "id": self.id,
            "polygon": [list(p) for p in self.polygon],
            "area": self.area,
            "centroid": list(self.centroid),
            "walls": list(self.walls),
            "doors": list(self.doors),
            "closed": self.closed,
        }


@dataclass(frozen=True)
class RoomsReply:
    """What ``{prefix}/map/rooms`` answers and ``{prefix}/map/rooms/updates`` carries."""

    stamp: float | None
    rooms: tuple[RoomRecord, ...] = ()
    doors: tuple[DoorRecord, ...] = ()

    def to_map(self) -> dict[str, Any]:
        """The contract's payload."""
        return {
            "v": 1,
            "frame": "map",
            "stamp": self.stamp,
            "rooms": [r.to_map() for r in self.rooms],
            "doors": [d.to_map() for d in self.doors],
        }


@dataclass
class _Kept:
    """An id'd room between updates: its cells (global (i, j)), for overlap with the next."""

    id: int
    cells: NDArray[np.int64]


def _keys(cells: NDArray[np.int64]) -> NDArray[np.int64]:
    """Cells (i, j), each once, as single integers, sorted."""
    return np.sort((cells[:, 0] << 32) + (cells[:, 1] & 0xFFFFFFFF))


def _cells(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """Inverse of ``_keys``: the low 32 bits are j, signed."""
    j = keys & 0xFFFFFFFF
    return np.stack([keys >> 32, np.where(j >= 1 << 31, j - (1 << 32), j)], axis=1)


def _overlaps(kept: list[_Kept], cells: list[NDArray[np.int64]]) -> list[tuple[int, int, int]]:
    """(cells shared, new room, old id) of rooms sharing ``KEEP_SHARE`` of the smaller's cells.

    The old rooms are written into a grid of their indices (rooms do not overlap), every new
    cell looked up in it at once, and the shared cells counted per pair.
    """
    if not kept or not cells:
        return []
    oi, oj = np.concatenate([k.cells for k in kept]).T
    low, high = (int(oi.min()), int(oj.min())), (int(oi.max()), int(oj.max()))
    grid = np.full((high[0] - low[0] + 1, high[1] - low[1] + 1), -1, dtype=np.int64)
    grid[oi - low[0], oj - low[1]] = np.repeat(np.arange(len(kept)), [len(k.cells) for k in kept])
    ni, nj = np.concatenate(cells).T
    room = np.repeat(np.arange(len(cells)), [len(c) for c in cells])
    inside = (ni >= low[0]) & (ni <= high[0]) & (nj >= low[1]) & (nj <= high[1])
    owner = np.full(len(room), -1, dtype=np.int64)
    owner[inside] = grid[ni[inside] - low[0], nj[inside] - low[1]]
    hit = owner >= 0
    shared = np.bincount(room[hit] * len(kept) + owner[hit], minlength=len(cells) * len(kept))
    pairs = []
    for k, m in np.argwhere(shared.reshape(len(cells), len(kept)) > 0).tolist():
        count = int(shared[k * len(kept) + m])
        if count >= KEEP_SHARE * min(len(cells[k]), len(kept[m].cells)):
            pairs.append((count, k, kept[m].id))
    return pairs


def _pack(keys: NDArray[np.int64]) -> str:
    """Sorted cell keys for a state file: their differences, compressed (mostly ones)."""
    steps = np.diff(keys, prepend=0).astype("<i8")
    return base64.b64encode(zlib.compress(steps.tobytes(), 6)).decode("ascii")


def _unpack(text: str) -> NDArray[np.int64]:
    """Inverse of ``_pack``."""
    steps = np.frombuffer(zlib.decompress(base64.b64decode(text)), dtype="<i8")
    return np.cumsum(steps).astype(np.int64)


def _greedy(pairs: list[tuple[float, int, int]]) -> dict[int, int]:
    """New index -> old id, taking ``(score, new, old)`` pairs in order, each side once."""
    ids: dict[int, int] = {}
    taken: set[int] = set()
    for _, new, old in pairs:
        if new not in ids and old not in taken:
            ids[new] = old
            taken.add(old)
    return ids


def _pt(p: Array) -> tuple[float, float]:
    return (round(float(p[0]), 3), round(float(p[1]), 3))


def _pts(points: Array) -> tuple[tuple[float, float], ...]:
    """Points to the millimetre, as the contract's lists of pairs."""
    return tuple((x, y) for x, y in np.round(np.asarray(points, dtype=float), 3).tolist())


@dataclass
class RoomMap:
    """The floor seen, the rooms on it and their ids (see the module's doc)."""

    config: RoomsConfig = field(default_factory=RoomsConfig)
    free: FreeSpace = field(default_factory=FreeSpace)
    next_room: int = 0
    next_door: int = 0
    pending: list[tuple[Array, Array | None, Array | None]] = field(default_factory=list)
    kept: list[_Kept] = field(default_factory=list)
    doors: dict[int, Array] = field(default_factory=dict)  # id -> centre
    reply: RoomsReply = field(default_factory=lambda: RoomsReply(None))
    seconds: float = 0.0  # the last update's
    # Frames come from the mapping's thread, updates and saves from others: the pending list
    # and the grid are touched under this lock only.
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    _last: Array | None = field(default=None, repr=False)  # the pose of the last frame kept
    _outlines: Outlines = field(default_factory=dict, repr=False)  # the last update's rooms

    def add_frame(self, pose: Array, origin: Array | None, rays: Array | None) -> None:
        """A frame's pose (x, y, yaw) and its free rays (robot frame); drawn at the next update.

        Only a frame ``KEEP_MOVE`` or ``KEEP_TURN`` from the last one kept: at 30 frames a
        second a camera sees the same floor many times over, and each drawn frame costs.
        """
        pose = np.asarray(pose, dtype=float)
        last = self._last
        if last is not None:
            turn = abs((pose[2] - last[2] + np.pi) % (2 * np.pi) - np.pi)
            if np.hypot(*(pose[:2] - last[:2])) < KEEP_MOVE and turn < KEEP_TURN:
                return
        self._last = pose
        with self._lock:
            self.pending.append((pose, origin, rays))

    def _draw_pending(self) -> None:
        """The frames handed over, drawn into the grid. Call with the lock held."""
        pending, self.pending = self.pending, []
        self.free.add_frames(pending)

    def update(self, walls: tuple[WallRecord, ...], stamp: float | None) -> RoomsReply:
        """Draw the frames handed over, segment, give ids; the new reply (also ``self.reply``)."""
        with self._lock:
            return self._update(walls, stamp)

    def _update(self, walls: tuple[WallRecord, ...], stamp: float | None) -> RoomsReply:
        started = time.perf_counter()
        self._draw_pending()
        segments = [
            WallSegments(w.id, np.asarray(w.segments, dtype=float).reshape(-1, 2, 2))
            for w in walls
            if not w.tentative
        ]
        layout = find_rooms(segments, self.free, self.config, self._outlines)
        self.reply = self._records(layout, stamp)
        self.seconds = time.perf_counter() - started
        return self.reply

    def _records(self, layout: Layout, stamp: float | None) -> RoomsReply:
        p0 = np.array([d.p0 for d in layout.doors]).reshape(-1, 2)
        p1 = np.array([d.p1 for d in layout.doors]).reshape(-1, 2)
        room_ids = self._room_ids(layout.rooms)
        door_ids = self._door_ids((p0 + p1) / 2)
        widths = np.round(np.hypot(*(p1 - p0).T), 3).tolist()
        doors = tuple(
            DoorRecord(
                id=door_ids[k],
                center=centre,
                width=width,
                p0=start,
                p1=end,
                wall=d.wall,
                rooms=tuple(sorted(room_ids[r] for r in d.rooms)),
            )
            for k, (d, centre, width, start, end) in enumerate(
                zip(layout.doors, _pts((p0 + p1) / 2), widths, _pts(p0), _pts(p1), strict=True)
            )
        )
        doors_of: dict[int, list[int]] = {}
        for door in doors:
            for room in door.rooms:
                doors_of.setdefault(room, []).append(door.id)
        rooms = tuple(
            RoomRecord(
                id=room_ids[k],
                polygon=_pts(r.polygon),
                area=round(r.area, 3),
                centroid=_pt(r.centroid),
                walls=tuple(sorted(r.walls)),
                doors=tuple(sorted(doors_of.get(room_ids[k], []))),
                closed=r.closed,
            )
            for k, r in enumerate(layout.rooms)
        )
        return RoomsReply(stamp, tuple(sorted(rooms, key=lambda r: r.id)), doors)

    def _room_ids(self, rooms: list[RoomShape]) -> list[int]:
        """Each new room's id: the old room it overlaps most, else a new one.

        A room whose cells are the old room's, as most are between two updates of a large map,
        overlaps that one alone: it takes its id without the overlaps counted. Such a room
        comes with the very array of cells the old room had (``find_rooms`` keeps its outline,
        cells and all), so it is found by that; any other goes to the overlaps.
        """
        cells = [r.cells for r in rooms]
        old = {id(k.cells): k for k in self.kept}
        ids = {n: old.pop(id(mine)).id for n, mine in enumerate(cells) if id(mine) in old}
        rest = [n for n in range(len(cells)) if n not in ids]
        pairs = _overlaps(list(old.values()), [cells[n] for n in rest])
        ids |= {rest[n]: i for n, i in _greedy(sorted(pairs, reverse=True)).items()}
        for k in range(len(rooms)):
            if k not in ids:
                ids[k], self.next_room = self.next_room, self.next_room + 1
        self.kept = [_Kept(ids[k], mine) for k, mine in enumerate(cells)]
        return [ids[k] for k in range(len(rooms))]

    def _door_ids(self, centres: Array) -> list[int]:
        """Each new door's id, by its centre: an old door's near it, else a new one."""
        old_ids = list(self.doors)
        old = np.array([self.doors[i] for i in old_ids]).reshape(-1, 2)
        # Candidates by box (compiled), not every new door against every old one.
        new, was = compiled.room_kernels().near_pairs(
            compiled.plain(centres, np.float64), old - DOOR_REACH, old + DOOR_REACH
        )
        gaps = np.hypot(*(centres[new] - old[was]).T)
        near = gaps <= DOOR_REACH
        pairs = sorted(
            (gap, k, old_ids[m])
            for gap, k, m in zip(
                gaps[near].tolist(), new[near].tolist(), was[near].tolist(), strict=True
            )
        )
        ids = _greedy(pairs)
        for k in range(len(centres)):
            if k not in ids:
                ids[k], self.next_door = self.next_door, self.next_door + 1
        self.doors = {ids[k]: c for k, c in enumerate(centres)}
        return [ids[k] for k in range(len(centres))]

    def to_json(self) -> dict[str, Any]:
        """For the state file: the floor, the rooms' cells and ids, the doors, the counters."""
        with self._lock:
            self._draw_pending()
            return self._document()

    def _document(self) -> dict[str, Any]:
        return {
            "free": self.free.to_json(),
            "next_room": self.next_room,
            "next_door": self.next_door,
            "rooms": [{"id": k.id, "cells": _pack(_keys(k.cells))} for k in self.kept],
            "doors": [{"id": i, "center": c.tolist()} for i, c in self.doors.items()],
        }

    def restore(self, data: dict[str, Any]) -> None:
        """Go on where ``to_json`` left off; ValueError says what is wrong."""
        try:
            self.free = FreeSpace.from_json(data["free"])
            self.next_room, self.next_door = int(data["next_room"]), int(data["next_door"])
            self.kept = [_Kept(int(r["id"]), _cells(_unpack(r["cells"]))) for r in data["rooms"]]
            self.doors = {
                int(d["id"]): np.asarray(d["center"], dtype=float).reshape(2) for d in data["doors"]
            }
        except (KeyError, TypeError, ValueError, zlib.error) as err:
            msg = f"rooms: {err}"
            raise ValueError(msg) from err
