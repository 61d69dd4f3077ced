"""The wall map as ROS 2 messages: RViz sees it through zenoh-bridge-ros2dds with no code.

``{prefix}/markers`` carries a ``visualization_msgs/msg/MarkerArray`` and ``{prefix}/trajectory``
a ``nav_msgs/msg/Path``, CDR-encoded with rosbags' ROS 2 Humble typestore (no hand-written CDR).
zenoh-bridge-ros2dds maps a ROS topic ``/T`` to the Zenoh key ``T``: run it with the same
namespace as the prefix (docs/ros2.md) and ``/wallmap/markers`` appears in ROS 2.

One marker per confirmed wall: namespace ``walls``, ``id`` = the wall id, ``LINE_LIST`` whose
point pairs are the wall's segments in the map frame, in the order the map reply lists them.
Ids that were published and are no longer served (merged away, or no longer confirmed) get a
``DELETE`` once. The path is the keyframes of the poses the mapper used. The rooms go on
``{prefix}/rooms/markers`` (``RoomMarkers``): outlines, labels and doors.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from wallmap.common.map_records import MapReply, WallRecord
from wallmap.common.ros2_types import ros2_typestore
from wallmap.common.transport import Keys

NAMESPACE = "walls"
LINE_WIDTH = 0.05  # m
COLOUR = (0.85, 0.25, 0.15, 1.0)  # RGBA


def _msg(name: str) -> Any:
    """A ROS 2 message class by its type name."""
    return ros2_typestore().types[name]


def _time(stamp: float) -> Any:
    sec = math.floor(stamp)
    nanosec = min(round((stamp - sec) * 1e9), 999_999_999)
    return _msg("builtin_interfaces/msg/Time")(sec=int(sec), nanosec=int(nanosec))


def _header(stamp: float, frame: str) -> Any:
    return _msg("std_msgs/msg/Header")(stamp=_time(stamp), frame_id=frame)


def _point(x: float, y: float) -> Any:
    return _msg("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=0.0)


def _identity() -> Any:
    return _msg("geometry_msgs/msg/Pose")(
        position=_point(0.0, 0.0),
        orientation=_msg("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0),
    )


@dataclass(frozen=True)
class _Look:
    """How a kind of marker looks: its namespace, type name, line width (or text height), colour."""

    ns: str
    kind: str
    width: float
    colour: tuple[float, float, float, float]


WALLS = _Look(NAMESPACE, "LINE_LIST", LINE_WIDTH, COLOUR)
ROOMS = _Look("rooms", "LINE_STRIP", 0.03, (0.2, 0.45, 0.8, 1.0))
ROOM_LABELS = _Look("room_labels", "TEXT_VIEW_FACING", 0.3, (0.1, 0.1, 0.1, 1.0))
DOORS = _Look("doors", "LINE_LIST", 0.08, (0.18, 0.52, 0.35, 1.0))


def _marker(
    look: _Look,
    marker_id: int,
    action: int,
    points: list[Any],
    stamp: float,
    frame: str,
    at: tuple[float, float] = (0.0, 0.0),
    text: str = "",
) -> Any:
    marker_type = _msg("visualization_msgs/msg/Marker")
    pose = _identity()
    pose.position = _point(*at)
    red, green, blue, alpha = look.colour
    return marker_type(
        header=_header(stamp, frame),
        ns=look.ns,
        id=int(marker_id),
        type=getattr(marker_type, look.kind),
        action=action,
        pose=pose,
        scale=_msg("geometry_msgs/msg/Vector3")(
            x=look.width if look.kind != "TEXT_VIEW_FACING" else 0.0,
            y=0.0,
            z=look.width if look.kind == "TEXT_VIEW_FACING" else 0.0,
        ),
        color=_msg("std_msgs/msg/ColorRGBA")(r=red, g=green, b=blue, a=alpha),
        lifetime=_msg("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        frame_locked=False,
        points=points,
        colors=[],
        texture_resource="",
        texture=_msg("sensor_msgs/msg/CompressedImage")(
            header=_header(stamp, frame), format="", data=_empty_bytes()
        ),
        uv_coordinates=[],
        text=text,
        mesh_resource="",
        mesh_file=_msg("visualization_msgs/msg/MeshFile")(filename="", data=_empty_bytes()),
        mesh_use_embedded_materials=False,
    )


def _empty_bytes() -> Any:
    return np.zeros(0, dtype=np.uint8)


def markers(
    walls: Sequence[WallRecord], deleted: Iterable[int], stamp: float, frame: str = "map"
) -> bytes:
    """The CDR of a MarkerArray: an ADD for every wall record, a DELETE for every deleted id."""
    marker_type = _msg("visualization_msgs/msg/Marker")
    out = []
    for wall in walls:
        points = [_point(x, y) for seg in wall.segments for x, y in seg]
        out.append(_marker(WALLS, wall.id, marker_type.ADD, points, stamp, frame))
    out += [_marker(WALLS, wall_id, marker_type.DELETE, [], stamp, frame) for wall_id in deleted]
    message = _msg("visualization_msgs/msg/MarkerArray")(markers=out)
    return bytes(ros2_typestore().serialize_cdr(message, "visualization_msgs/msg/MarkerArray"))


def room_markers(
    rooms: dict[str, Any], deleted: dict[str, Iterable[int]], stamp: float, frame: str = "map"
) -> bytes:
    """The CDR of a MarkerArray of the rooms reply: outlines, labels and doors.

    Each room an outline (``LINE_STRIP``, closed, namespace ``rooms``) and a label with its id
    and area (``TEXT_VIEW_FACING``, ``room_labels``), each door a line across its opening
    (``doors``); ids per namespace are the rooms' and doors' ids. ``deleted``: ids gone, by
    namespace, each given a DELETE.
    """
    marker_type = _msg("visualization_msgs/msg/Marker")
    add, delete = marker_type.ADD, marker_type.DELETE
    out = []
    for room in rooms["rooms"]:
        ring = [_point(x, y) for x, y in [*room["polygon"], room["polygon"][0]]]
        out.append(_marker(ROOMS, room["id"], add, ring, stamp, frame))
        text = f"room {room['id']}: {room['area']:.1f} m²"
        centre = (float(room["centroid"][0]), float(room["centroid"][1]))
        out.append(_marker(ROOM_LABELS, room["id"], add, [], stamp, frame, centre, text))
    for door in rooms["doors"]:
        span = [_point(*door["p0"]), _point(*door["p1"])]
        out.append(_marker(DOORS, door["id"], add, span, stamp, frame))
    for look in (ROOMS, ROOM_LABELS, DOORS):
        out += [_marker(look, i, delete, [], stamp, frame) for i in deleted.get(look.ns, ())]
    message = _msg("visualization_msgs/msg/MarkerArray")(markers=out)
    return bytes(ros2_typestore().serialize_cdr(message, "visualization_msgs/msg/MarkerArray"))


class RoomMarkers:
    """``{prefix}/rooms/markers``: the rooms' MarkerArray, and the latest for late subscribers.

    Ids of rooms and doors no longer served get one DELETE, as walls do.
    """

    def __init__(self, session: zenoh.Session, keys: Keys, frame: str = "map") -> None:
        self._frame, self._key = frame, keys.room_markers
        self._shown: dict[str, set[int]] = {}
        self._latest: bytes | None = None
        self._publisher = session.declare_publisher(self._key)
        self._queryable = session.declare_queryable(self._key, self._answer)

    def _answer(self, query: zenoh.Query) -> None:  # Zenoh's thread: reply to this query only
        latest = self._latest
        if latest is not None:
            query.reply(query.key_expr, latest)

    def publish(self, rooms: dict[str, Any]) -> None:
        """The rooms reply as markers."""
        now = {
            ROOMS.ns: {r["id"] for r in rooms["rooms"]},
            ROOM_LABELS.ns: {r["id"] for r in rooms["rooms"]},
            DOORS.ns: {d["id"] for d in rooms["doors"]},
        }
        gone = {ns: sorted(self._shown.get(ns, set()) - ids) for ns, ids in now.items()}
        self._shown = now
        self._latest = room_markers(rooms, gone, rooms.get("stamp") or 0.0, self._frame)
        self._publisher.put(self._latest)

    def undeclare(self) -> None:
        """End the queryable and the publisher."""
        self._queryable.undeclare()
        self._publisher.undeclare()


def path(trajectory: Sequence[Sequence[float]], stamp: float, frame: str = "map") -> bytes:
    """The CDR of a Path through the keyframes ``[[stamp, x, y, yaw], …]``."""
    poses = []
    for t, x, y, yaw in trajectory:
        orientation = _msg("geometry_msgs/msg/Quaternion")(
            x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0)
        )
        pose = _msg("geometry_msgs/msg/Pose")(position=_point(x, y), orientation=orientation)
        poses.append(_msg("geometry_msgs/msg/PoseStamped")(header=_header(t, frame), pose=pose))
    message = _msg("nav_msgs/msg/Path")(header=_header(stamp, frame), poses=poses)
    return bytes(ros2_typestore().serialize_cdr(message, "nav_msgs/msg/Path"))


def decode(payload: bytes, msgtype: str) -> Any:
    """A published payload back as a rosbags message (for tests and tools)."""
    return ros2_typestore().deserialize_cdr(payload, msgtype)


def warm_up() -> None:
    """Load the typestore and make its serializers of what is published, with one of each.

    rosbags builds a typestore at import and a type's serializer at its first message, a few
    tenths of a second of CPU together: done here before the mapper says it is ready, as its
    compiled loops are, instead of among a recording's first frames.
    """
    room = {"id": 0, "polygon": [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], "area": 0.5}
    door = {"id": 0, "p0": [0.0, 0.0], "p1": [1.0, 0.0]}
    room_markers({"rooms": [{**room, "centroid": [0.3, 0.3]}], "doors": [door]}, {}, 0.0)
    path([[0.0, 0.0, 0.0, 0.0]], 0.0)


class MarkerState:
    """Which ids RViz was last told about, so that walls gone get exactly one DELETE."""

    def __init__(self) -> None:
        self._shown: set[int] = set()

    def payload(self, walls: Sequence[WallRecord], stamp: float, frame: str) -> bytes:
        """The MarkerArray for the served ``walls``, with DELETEs for ids no longer among them."""
        ids = {w.id for w in walls}
        gone = sorted(self._shown - ids)
        self._shown = ids
        return markers(walls, gone, stamp, frame)


class Ros2Outlet:
    """Publishes the markers and the path when the map changes, and answers late subscribers.

    Each key is a publisher and a queryable holding the latest payload: a subscriber that comes
    late (RViz started after the map; zenoh-bridge-ros2dds queries for a transient-local
    reader) gets the whole map at once, the way a transient-local ROS 2 topic would give it.
    """

    def __init__(self, session: zenoh.Session, keys: Keys, frame: str = "map") -> None:
        self._frame = frame
        self._state = MarkerState()
        self._latest: dict[str, bytes] = {}
        self._lock = threading.Lock()
        self._declared = []
        for key in (keys.markers, keys.trajectory):
            self._declared.append(session.declare_queryable(key, self._answer))
        self._markers = session.declare_publisher(keys.markers)
        self._path = session.declare_publisher(keys.trajectory)
        self._keys = keys

    def _answer(self, query: zenoh.Query) -> None:  # Zenoh's thread: reply to this query only
        with self._lock:
            payload = self._latest.get(str(query.key_expr))
        if payload is not None:
            query.reply(query.key_expr, payload)

    def publish(self, reply: MapReply) -> None:
        """The map reply (confirmed walls, with the trajectory) as markers and a path."""
        stamp = reply.stamp or 0.0
        markers_cdr = self._state.payload(reply.walls, stamp, self._frame)
        path_cdr = path(reply.trajectory or (), stamp, self._frame)
        with self._lock:
            self._latest[self._keys.markers] = markers_cdr
            self._latest[self._keys.trajectory] = path_cdr
        self._markers.put(markers_cdr)
        self._path.put(path_cdr)

    def undeclare(self) -> None:
        """End the queryables."""
        for queryable in self._declared:
            queryable.undeclare()
