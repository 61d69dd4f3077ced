"""``{prefix}/map/rooms`` and its updates: the mapper's rooms, segmented off the frame path.

A worker segments the floor (``RoomMap.update``) at most every ``ROOMS_PERIOD`` while the map
changes, outside the map's lock: frames are integrated meanwhile, and a query is answered from
the last reply, already encoded, or from a new one when the map changed since (a query after
the last frame gets the rooms of the final map). A new reply whose rooms or doors differ from
the last goes out on ``{prefix}/map/rooms/updates`` (the same payload), and with ROS 2 out
as markers on ``{prefix}/rooms/markers``.
"""

from __future__ import annotations

import threading

import zenoh

from wallmap.common import compiled
from wallmap.common.codec import encode_as
from wallmap.common.map_requests import reply_in_format
from wallmap.common.runtime import Stats, drain
from wallmap.common.transport import Keys
from wallmap.services.mapper import serving
from wallmap.services.mapper.mapping import Mapping
from wallmap.services.mapper.room_map import RoomsReply
from wallmap.services.mapper.ros2_out import RoomMarkers

ROOMS_PERIOD = 1.0  # s between two segmentations of a changing map, at least
BUSY_SHARE = 10.0  # ...and this many times the last one's duration
FAST_RATE = 100.0  # frames/s: faster than a sensor, a recording played --fast...
MAX_DEFER = 10.0  # s: ...is not held up for its rooms for longer than this


class RoomsServer:
    """The rooms' queryable, their updates' publisher, and the worker keeping them current."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        lock: threading.Condition,
        mapping: Mapping,
        stats: Stats,
        ros2_out: bool = False,
    ) -> None:
        self._lock, self._mapping, self._stats = lock, mapping, stats
        self._markers = RoomMarkers(session, keys) if ros2_out else None
        self._queryable = session.declare_queryable(keys.map_rooms)
        self._updates = session.declare_publisher(keys.map_rooms_updates)
        self._encoded = self._encode(mapping.rooms.reply)
        self._seen: tuple[object, ...] | None = None  # the map state last segmented
        self._refreshing = threading.Lock()  # the worker, the answerer and undeclare take turns
        self._closed = False

    @staticmethod
    def _encode(reply: RoomsReply) -> dict[str, bytes]:
        body = reply.to_map()
        return {fmt: encode_as(body, fmt) for fmt in ("msgpack", "json")}

    def workers(self, stop: threading.Event) -> list[threading.Thread]:
        """The threads to start: the segmenting worker and the query answerer."""
        return [
            threading.Thread(target=self._keep_current, args=(stop,), daemon=True),
            threading.Thread(target=self._answer, daemon=True),
        ]

    def undeclare(self) -> None:
        """Stop answering (the answerer's channel closes) and publishing.

        Taken between two segmentations: one under way would publish on what is undeclared.
        """
        with self._refreshing:
            self._closed = True
            self._queryable.undeclare()
            self._updates.undeclare()
            if self._markers is not None:
                self._markers.undeclare()

    def _keep_current(self, stop: threading.Event) -> None:
        # The rooms' compiled loops, loaded as the worker starts (0.05 s, before frames come as
        # a rule): else the first to draw the floor loads them, and that may be a state save,
        # which holds the map's lock while frames wait.
        compiled.room_kernels().warm_up()
        # A big building takes a while to segment: at most a tenth of the time is spent on it,
        # so the frames, which share the interpreter, keep going. Frames coming faster than any
        # sensor gives them (a recording played --fast) are left to go first, up to MAX_DEFER:
        # the rooms follow once they pause, and a query gets them current anyway.
        frames, deferred = self._frames(), 0.0
        while not stop.wait(period := max(ROOMS_PERIOD, BUSY_SHARE * self._mapping.rooms.seconds)):
            now = self._frames()
            rate, frames = (now - frames) / period, now
            if rate > FAST_RATE and deferred < MAX_DEFER:
                deferred += period
                continue
            deferred = 0.0
            self._refresh()

    def _frames(self) -> int:
        return self._mapping.map.frames

    def _refresh(self) -> None:
        """Segment again if the map changed since the last time; publish what changed."""
        with self._refreshing:
            if self._closed:
                return
            with self._lock:
                wall_map = self._mapping.map
                state = (id(wall_map), wall_map.version)
                if state == self._seen:
                    return
                self._seen = state
                walls = serving.reply(wall_map).walls
                stamp = wall_map.stamp
            before = self._mapping.rooms.reply
            reply = self._mapping.rooms.update(walls, stamp)
            self._stats.add("room_updates")
            self._encoded = self._encode(reply)
            if (reply.rooms, reply.doors) != (before.rooms, before.doors):
                self._updates.put(self._encoded["msgpack"])
                if self._markers is not None:
                    self._markers.publish(reply.to_map())

    def _answer(self) -> None:
        for query in drain(self._queryable.handler):
            self._refresh()
            with query:
                if not reply_in_format(query, self._encoded.__getitem__):
                    continue
            self._stats.add("room_queries")
