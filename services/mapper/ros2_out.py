"""The wall map as ROS 2 messages: RViz sees it through zenoh-bridge-ros2dds with no code.

``{prefix}/markers`` carries a ``visualization_msgs/msg/MarkerArray`` and ``{prefix}/trajectory``
a ``nav_msgs/msg/Path``, CDR-encoded with rosbags' ROS 2 Humble typestore (no hand-written CDR).
zenoh-bridge-ros2dds maps a ROS topic ``/T`` to the Zenoh key ``T``: run it with the same
namespace as the prefix (docs/ros2.md) and ``/wallmap/markers`` appears in ROS 2.

One marker per confirmed wall: namespace ``walls``, ``id`` = the wall id, ``LINE_LIST`` whose
point pairs are the wall's segments in the map frame, in the order the map reply lists them.
Ids that were published and are no longer served (merged away, or no longer confirmed) get a
``DELETE`` once. The path is the keyframes of the poses the mapper used.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence
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


def _marker(wall_id: int, action: int, points: list[Any], stamp: float, frame: str) -> Any:
    marker_type = _msg("visualization_msgs/msg/Marker")
    return marker_type(
        header=_header(stamp, frame),
        ns=NAMESPACE,
        id=int(wall_id),
        type=marker_type.LINE_LIST,
        action=action,
        pose=_identity(),
        scale=_msg("geometry_msgs/msg/Vector3")(x=LINE_WIDTH, y=0.0, z=0.0),
        color=_msg("std_msgs/msg/ColorRGBA")(r=COLOUR[0], g=COLOUR[1], b=COLOUR[2], a=COLOUR[3]),
        lifetime=_msg("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        frame_locked=False,
        points=points,
        colors=[],
        texture_resource="",
        texture=_msg("sensor_msgs/msg/CompressedImage")(
            header=_header(stamp, frame), format="", data=_empty_bytes()
        ),
        uv_coordinates=[],
        text="",
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
        out.append(_marker(wall.id, marker_type.ADD, points, stamp, frame))
    out += [_marker(wall_id, marker_type.DELETE, [], stamp, frame) for wall_id in deleted]
    message = _msg("visualization_msgs/msg/MarkerArray")(markers=out)
    return bytes(ros2_typestore().serialize_cdr(message, "visualization_msgs/msg/MarkerArray"))


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
