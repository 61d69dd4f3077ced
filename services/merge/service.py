"""The merge service: one map of several robots, served under the fleet's prefix.

Each robot runs its own player, detector and mapper under its own prefix, in its own map frame,
usually behind its own router; routers link (``wallmap router --connect``) and this service,
anywhere on the mesh, reads each robot's map: one query at start and another whenever that
robot's ``{robot}/map/updates`` says its map changed (at most once per ``period``). A callback only
notes which robot spoke; the worker queries, aligns, fuses (``services.merge.fleet``) and
publishes what changed on ``FLEET/map/updates`` (and ``FLEET/map/rooms/updates``, and as a
mapper does for RViz, ``FLEET/markers`` and ``FLEET/rooms/markers``). ``FLEET/map/walls`` (the
walls' payload, each wall with its ``sources``), ``FLEET/map/rooms`` and ``FLEET/robots`` (where
each robot's frame lies, and its path there) answer from the last fusion.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from typing import Any

import zenoh

from wallmap.common.codec import encode, encode_as
from wallmap.common.link_settings import TransportError, ZenohSettings, plain_prefix
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply
from wallmap.common.map_requests import (
    MalformedReplyError,
    QueryError,
    answer_map_queries,
    fetch_map,
    fetch_rooms,
    reply_in_format,
)
from wallmap.common.runtime import Presence, Stats, drain, exempt_startup_objects, setup_logging
from wallmap.common.transport import Keys, key_expression, open_session
from wallmap.services.mapper.ros2_out import RoomMarkers, Ros2Outlet
from wallmap.services.merge.fleet import Fleet

LOG = logging.getLogger("wallmap.merge")
PERIOD = 1.0  # s: the robots' maps are read at most this often, and at least every 5 periods
QUERY_TIMEOUT = 2.0


def run(settings: ZenohSettings, robots: list[str], stop: threading.Event) -> Stats:
    """Serve the fleet of ``robots`` (the first one's frame the fleet's) until ``stop``."""
    robots = [plain_prefix(robot, "robot prefix", "--robots") for robot in robots]
    for robot in robots:
        key_expression(robot, "--robots")
    if settings.prefix in robots:
        msg = f"--prefix {settings.prefix!r} is one of the robots: the fleet needs its own"
        raise TransportError(msg)
    log = setup_logging("merge")
    keys = Keys(settings.prefix)
    stats = Stats(log)
    fleet = Fleet(robots)
    served = _Served(fleet)
    spoke: queue.SimpleQueue[str] = queue.SimpleQueue()
    log.info("connecting to %s (fleet %r of %s)", ", ".join(settings.connect), keys.prefix, robots)
    with open_session(settings, count=stats.add, stop=stop) as session:
        listeners = [
            session.declare_subscriber(Keys(r).map_updates, lambda _s, r=r: spoke.put(r))
            for r in robots
        ]
        updates = session.declare_publisher(keys.map_updates)
        rooms_updates = session.declare_publisher(keys.map_rooms_updates)
        walls = session.declare_queryable(keys.map_walls, zenoh.handlers.FifoChannel(64))
        rooms = session.declare_queryable(keys.map_rooms, zenoh.handlers.FifoChannel(64))
        placed = session.declare_queryable(keys.robots, zenoh.handlers.FifoChannel(64))
        ros2 = (Ros2Outlet(session, keys), RoomMarkers(session, keys))  # RViz, as a mapper's
        token = Presence(session, keys, "merge", stats, served.details)
        answering = [
            threading.Thread(
                target=answer_map_queries,
                args=(walls.handler, served.walls, stats.add),
                daemon=True,
            ),
            threading.Thread(target=_answer, args=(placed.handler, served.robots), daemon=True),
            threading.Thread(target=_answer, args=(rooms.handler, served.rooms), daemon=True),
        ]
        for thread in answering:
            thread.start()
        exempt_startup_objects()
        log.info("ready: %s -> %s", ", ".join(robots), keys.map_walls)
        _work(session, fleet, served, spoke, (updates, rooms_updates), ros2, stats, stop)
        log.info("stopping: %s", stats.snapshot())
        token.undeclare()
        for resource in [*listeners, walls, placed, rooms, *ros2]:
            resource.undeclare()
        for thread in answering:
            thread.join(timeout=5.0)
    return stats


class _Served:
    """The last fusion's replies, encoded once, under a lock the answering threads share."""

    def __init__(self, fleet: Fleet) -> None:
        self._fleet, self._lock = fleet, threading.Lock()
        self._robots: dict[str, Any] = fleet.robots_reply()
        self._rooms: dict[str, Any] = fleet.rooms

    def refresh(self) -> bool:
        """After an update: the robots' placements and rooms as they now are.

        Returns whether the rooms changed (they go out on ``FLEET/map/rooms/updates``).
        """
        with self._lock:
            self._robots = self._fleet.robots_reply()
            changed = self._fleet.rooms != self._rooms
            self._rooms = self._fleet.rooms
        return changed

    def reply(self) -> MapReply:
        """The fleet's confirmed walls, for RViz."""
        with self._lock:
            return self._fleet.reply(MapQuery())

    def walls(self, query: MapQuery, fmt: str) -> bytes:
        with self._lock:
            body = self._fleet.reply(query).to_map()
        return encode_as(body, fmt)

    def robots(self) -> dict[str, Any]:
        with self._lock:
            return self._robots

    def rooms(self) -> dict[str, Any]:
        with self._lock:
            return self._rooms

    def details(self) -> dict[str, Any]:
        """For ``wallmap status``: robots aligned, walls served, the last update's cost."""
        robots = self.robots()["robots"]
        aligned = [r["prefix"] for r in robots if r["aligned"]]
        return {"robots": len(robots), "aligned": aligned, "walls": len(self._fleet.walls)}

    @property
    def lock(self) -> threading.Lock:
        return self._lock


def _work(
    session: zenoh.Session,
    fleet: Fleet,
    served: _Served,
    spoke: queue.SimpleQueue[str],
    publishers: tuple[zenoh.Publisher, zenoh.Publisher],
    ros2: tuple[Ros2Outlet, RoomMarkers],
    stats: Stats,
    stop: threading.Event,
) -> None:
    """Read the robots whose maps changed, fuse, publish the changes, until ``stop``."""
    due = set(fleet.prefixes)  # every robot at start
    quiet, silent = 0, set[str]()
    while not stop.wait(PERIOD):
        while not spoke.empty():
            due.add(spoke.get_nowait())
        quiet += 1
        if quiet >= 5:  # a robot started after us, or an update lost: read every robot now and then
            due, quiet = set(fleet.prefixes), 0
        read = [r for r in sorted(due) if _read(session, fleet, r, stats, silent)]
        due -= set(read)
        if not read:
            continue
        with served.lock:
            changes = fleet.update()
        rooms_changed = served.refresh()
        stats.add("fusions")
        if changes is not None:
            publishers[0].put(encode(changes.to_map()))
            ros2[0].publish(served.reply())
            stats.add("updates")
        if rooms_changed:
            publishers[1].put(encode(served.rooms()))
            ros2[1].publish(served.rooms())


def _read(session: zenoh.Session, fleet: Fleet, robot: str, stats: Stats, silent: set[str]) -> bool:
    """A robot's map, into the fleet; False when no mapper of it answered.

    A robot that stops answering (not started yet, stopped, its link down) is said once, and
    once when it answers again; the fleet keeps its last map meanwhile.
    """
    try:
        reply = fetch_map(session, Keys(robot), MapQuery(trajectory=True), timeout=QUERY_TIMEOUT)
    except MalformedReplyError as err:
        stats.refuse(f"{robot}'s map", str(err))
        return True
    except QueryError as err:
        stats.add(f"unanswered.{robot}")
        if robot not in silent:
            silent.add(robot)
            LOG.warning("no map from %r: %s (asked again every second)", robot, err)
        return False
    if robot in silent:
        silent.discard(robot)
        LOG.info("%r answers again", robot)
    fleet.take(robot, reply)
    stats.add("maps_read")
    try:
        fleet.take_rooms(robot, fetch_rooms(session, Keys(robot), timeout=QUERY_TIMEOUT))
    except MalformedReplyError as err:
        stats.refuse(f"{robot}'s rooms", str(err))
    except QueryError:
        pass  # a mapper without rooms (an older one): the fleet has its walls
    return True


def _answer(channel: zenoh.handlers.Handler[zenoh.Query], body: Callable[[], dict]) -> None:
    """Answer each query with ``body()``, msgpack or (``format=json``) JSON."""
    for query in drain(channel):
        with query:
            reply_in_format(query, lambda fmt: encode_as(body(), fmt))
