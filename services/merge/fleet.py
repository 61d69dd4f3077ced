"""The fleet's map: each robot's newest map, where its frame lies, the fused walls and their ids.

The merge service hands each robot's map reply in (``take``) and asks for the fleet's map
(``update``); nothing here knows Zenoh, so the tests drive it with maps made by the offline
pipeline. A robot's frame is searched for (``common.map_alignment.align``) until found, then
refined from where it was on every new map of it, and searched for afresh each time its map has
grown by half since: a better-seen map may show a first alignment was wrong. The first robot's
frame is the fleet's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common import se2
from wallmap.common.map_alignment import AlignConfig, Alignment, Walls, align, refine
from wallmap.common.map_fusion import (
    FleetIds,
    FuseConfig,
    Source,
    fused_wall,
    group_walls,
    place,
)
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply, MapUpdate, WallRecord
from wallmap.services.merge.rooms import fleet_rooms

Array = NDArray[np.float64]
GROWTH = 1.5  # a robot's frame is searched for afresh when its walls have grown this much


@dataclass
class Robot:
    """One robot of the fleet: its newest map and where its frame lies in the fleet's."""

    prefix: str
    reply: MapReply | None = None
    alignment: Alignment | None = None
    searched_at: int = 0  # walls in its map at the last full search that found its frame
    fresh: bool = False  # a new map since the last update

    @property
    def walls(self) -> Walls:
        """Its confirmed walls' segments, for alignment."""
        walls = self.reply.walls if self.reply is not None else ()
        segments = [s for w in walls if not w.tentative for s in w.segments]
        return Walls.of(np.array(segments, dtype=float).reshape(-1, 2, 2))


@dataclass
class Fleet:
    """The robots, the fused walls, their ids (see the module's doc)."""

    prefixes: list[str]
    align_config: AlignConfig = field(default_factory=AlignConfig)
    fuse_config: FuseConfig = field(default_factory=FuseConfig)
    robots: dict[str, Robot] = field(init=False)
    ids: FleetIds = field(default_factory=FleetIds)
    walls: dict[int, WallRecord] = field(default_factory=dict)
    rooms: dict[str, Any] = field(
        default_factory=lambda: {"frame": "map", "rooms": [], "doors": []}
    )
    _room_bodies: dict[str, dict[str, Any]] = field(default_factory=dict, repr=False)
    _room_ids: tuple[FleetIds, FleetIds] = field(
        default_factory=lambda: (FleetIds(), FleetIds()), repr=False
    )
    merges: list[tuple[int, int, float]] = field(default_factory=list)
    seconds: float = 0.0  # the last update's
    # What an update would compute again for walls that did not change: placed walls by
    # (robot, id) with the wall and frame they were placed from, fused walls by their members.
    _placed: dict[tuple[str, int], tuple[WallRecord, bytes, WallRecord]] = field(
        default_factory=dict, repr=False
    )
    _fused: dict[tuple[tuple[str, WallRecord], ...], tuple[WallRecord, tuple[Source, ...]]] = field(
        default_factory=dict, repr=False
    )

    def __post_init__(self) -> None:
        self.robots = {p: Robot(p) for p in self.prefixes}
        first = self.robots[self.prefixes[0]]
        first.alignment = Alignment(np.zeros(3), np.zeros((3, 3)), 0, 0.0, 0.0)

    def take(self, prefix: str, reply: MapReply) -> None:
        """A robot's newest map.

        One with fewer frames than the last is a new map (its mapper restarted without its state
        file, in a new frame): where its frame lay is searched for afresh.
        """
        robot = self.robots[prefix]
        if robot.reply is not None and reply.frames < robot.reply.frames:
            self._lost(robot)
        robot.reply, robot.fresh = reply, True

    def _lost(self, robot: Robot) -> None:
        """A robot's frame no longer known (not the first's: that one is the fleet's)."""
        if robot.prefix != self.prefixes[0]:
            robot.alignment, robot.searched_at = None, 0

    def take_rooms(self, prefix: str, body: dict[str, Any]) -> None:
        """A robot's newest rooms reply (the contract's payload)."""
        self._room_bodies[prefix] = body

    def update(self) -> MapUpdate | None:
        """Align, fuse and give ids; what changed since the last update (None: nothing)."""
        started = time.perf_counter()
        for robot in self.robots.values():
            if robot.fresh:
                self._align(robot)
                robot.fresh = False
        placed = self._place()
        groups = group_walls(placed, self.fuse_config)
        fused_by = {tuple(placed[k] for k in group) for group in groups}
        self._fused = {
            members: self._fused.get(members) or fused_wall(list(members)) for members in fused_by
        }
        fused = [self._fused[tuple(placed[k] for k in group)] for group in groups]
        ids, merged = self.ids.assign([sources for _, sources in fused])
        stamp = self.stamp
        self.merges += [(old, new, stamp or 0.0) for old, new in merged]
        walls = {
            fleet_id: replace(wall, id=fleet_id, sources=sources)
            for fleet_id, (wall, sources) in zip(ids, fused, strict=True)
        }
        changed = tuple(w for k, w in sorted(walls.items()) if self.walls.get(k) != w)
        removed = tuple(sorted(set(self.walls) - set(walls)))
        self.walls = walls
        aligned = {p: r.alignment.pose for p, r in self.robots.items() if r.alignment is not None}
        bodies = {p: b for p, b in self._room_bodies.items() if p in aligned}
        self.rooms = fleet_rooms(bodies, aligned, self.ids.of_source, self._room_ids)
        self.seconds = time.perf_counter() - started
        if not changed and not removed:
            return None
        return MapUpdate(self.frames, stamp, changed, removed)

    def _place(self) -> list[tuple[str, WallRecord]]:
        """Every aligned robot's walls in the fleet's frame.

        A wall placed before, from the same record and frame, is not placed again.
        """
        placed, kept = [], {}
        for robot in self.robots.values():
            if robot.reply is None or robot.alignment is None:
                continue
            frame = robot.alignment.pose.tobytes() + robot.alignment.cov.tobytes()
            for wall in robot.reply.walls:
                key = (robot.prefix, wall.id)
                before = self._placed.get(key)
                if before is not None and before[0] == wall and before[1] == frame:
                    moved = before[2]
                else:
                    moved = place(wall, robot.alignment.pose, robot.alignment.cov)
                kept[key] = (wall, frame, moved)
                placed.append((robot.prefix, moved))
        self._placed = kept
        return placed

    def _align(self, robot: Robot) -> None:
        """Find or refine where a robot's frame lies (the module's doc)."""
        if robot.prefix == self.prefixes[0] or robot.reply is None:
            return
        first = self.robots[self.prefixes[0]]
        if first.reply is None:
            return
        mine, theirs = robot.walls, first.walls
        if robot.alignment is None or len(mine.a) >= GROWTH * max(robot.searched_at, 1):
            found = align(theirs, mine, self.align_config)
            if found is not None:
                robot.alignment, robot.searched_at = found, len(mine.a)
                return
        if robot.alignment is not None:
            pose, cov, matched, overlap = refine(
                theirs.longer_than(self.align_config.min_length),
                mine.longer_than(self.align_config.min_length),
                robot.alignment.pose,
                self.align_config,
            )
            if matched >= self.align_config.min_matched:
                robot.alignment = Alignment(pose, cov, matched, overlap, robot.alignment.runner_up)
            else:  # its map no longer lies where it did (the first robot's moved): search again
                self._lost(robot)

    @property
    def frames(self) -> int:
        """Sensor frames integrated by all robots."""
        return sum(r.reply.frames for r in self.robots.values() if r.reply is not None)

    @property
    def stamp(self) -> float | None:
        """The newest stamp of any robot's map."""
        stamps = [r.reply.stamp for r in self.robots.values() if r.reply and r.reply.stamp]
        return max(stamps, default=None)

    def reply(self, query: MapQuery) -> MapReply:
        """The fleet's map as ``FLEET/map/walls`` answers it, the walls ``query`` selects."""
        walls = tuple(w for _, w in sorted(self.walls.items()) if _selected(w, query))
        return MapReply(
            frames=self.frames,
            observations=sum(r.reply.observations for r in self.robots.values() if r.reply),
            stamp=self.stamp,
            walls=walls,
            merges=tuple(self.merges),
        )

    def robots_reply(self) -> dict[str, Any]:
        """What ``FLEET/robots`` answers: where each robot's frame lies, and its path there."""
        robots = []
        for robot in self.robots.values():
            found = robot.alignment
            entry: dict[str, Any] = {"prefix": robot.prefix, "aligned": found is not None}
            if found is not None:
                x, y, yaw = (float(v) for v in found.pose)
                entry |= {
                    "x": x,
                    "y": y,
                    "yaw": yaw,
                    "cov": found.cov.tolist(),
                    "walls_matched": found.matched,
                    "trajectory": _placed_path(robot.reply, found.pose),
                }
            entry["frames"] = robot.reply.frames if robot.reply else 0
            robots.append(entry)
        return {"frame": "map", "robots": robots}


def _placed_path(reply: MapReply | None, pose: Array) -> list[list[float]]:
    """A robot's keyframes (stamp, x, y, yaw) in the fleet's frame."""
    if reply is None or not reply.trajectory:
        return []
    return [
        [stamp, *se2.compose(pose, np.array([x, y, yaw])).tolist()]
        for stamp, x, y, yaw in reply.trajectory
    ]


def _selected(wall: WallRecord, query: MapQuery) -> bool:
    """Whether the fleet's reply holds this wall (the map query's rules)."""
    if wall.n_obs < query.min_obs or (wall.tentative and not query.tentative):
        return False
    if query.since is not None and (wall.last_seen is None or wall.last_seen < query.since):
        return False
    return query.crosses(wall.segments)
