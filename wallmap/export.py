"""The map reply as GeoJSON, for GIS tools and web maps.

Coordinates are metres in wallmap's map frame, not WGS 84 longitude and latitude as RFC 7946
expects: the collection says so in ``properties`` (a foreign member, which RFC 7946 allows) rather
than in the obsolete ``crs`` member. Tools that assume degrees will misplace it; ones that take
plain planar coordinates (QGIS with a local CRS, shapely, most web canvases) draw it as it is.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from wallmap.common.map_records import MapReply, WallRecord

WALL_PROPERTIES = ("id", "u", "v", "cov", "n_obs", "first_seen", "last_seen")


def _xy(point: Any) -> list[float]:
    return [float(point[0]), float(point[1])]


def _wall_feature(wall: WallRecord) -> dict[str, Any]:
    """A wall as a MultiLineString: the segments seen, between doors and gaps."""
    lines = [[_xy(a), _xy(b)] for a, b in wall.segments]
    geometry = {"type": "MultiLineString", "coordinates": lines}
    record = wall.to_map()
    properties = {"kind": "wall", **{key: record[key] for key in WALL_PROPERTIES}}
    properties["length"] = sum(math.dist(a, b) for a, b in lines)  # of the seen parts only
    return {"type": "Feature", "id": wall.id, "geometry": geometry, "properties": properties}


def _trajectory_feature(rows: Sequence[Sequence[float]]) -> dict[str, Any]:
    """The keyframes [stamp, x, y, yaw] as a LineString (a Point if there is only one)."""
    coordinates = [_xy(row[1:3]) for row in rows]
    geometry = (
        {"type": "LineString", "coordinates": coordinates}
        if len(coordinates) > 1
        else {"type": "Point", "coordinates": coordinates[0]}
    )
    properties = {
        "kind": "trajectory",
        "stamps": [float(row[0]) for row in rows],
        "yaws": [float(row[3]) for row in rows],
    }
    return {"type": "Feature", "geometry": geometry, "properties": properties}


def _room_feature(room: dict[str, Any]) -> dict[str, Any]:
    """A room as a Polygon: its outline, closed (first point again last), counter-clockwise."""
    ring = [_xy(p) for p in room["polygon"]]
    geometry = {"type": "Polygon", "coordinates": [[*ring, ring[0]]] if ring else []}
    properties = {
        "kind": "room",
        **{k: room[k] for k in ("id", "area", "walls", "doors", "closed")},
    }
    properties["centroid"] = _xy(room["centroid"])
    return _feature(f"room-{room['id']}", geometry, properties)


def _door_feature(door: dict[str, Any]) -> dict[str, Any]:
    """A door as a LineString across its opening, jamb to jamb."""
    geometry = {"type": "LineString", "coordinates": [_xy(door["p0"]), _xy(door["p1"])]}
    properties = {"kind": "door", **{k: door[k] for k in ("id", "width", "wall", "rooms")}}
    properties["center"] = _xy(door["center"])
    return _feature(f"door-{door['id']}", geometry, properties)


def _feature(
    feature_id: str, geometry: dict[str, Any], properties: dict[str, Any]
) -> dict[str, Any]:
    """A GeoJSON Feature; room and door ids are prefixed, as walls own the plain numbers."""
    return {"type": "Feature", "id": feature_id, "geometry": geometry, "properties": properties}


def to_geojson(reply: MapReply, rooms: dict[str, Any] | None = None) -> dict[str, Any]:
    """A FeatureCollection: one feature per wall, the trajectory if the reply has one.

    Then a Polygon per room and a LineString per door of ``rooms`` (the mapper's rooms reply).
    """
    features = [_wall_feature(w) for w in reply.walls]
    if reply.trajectory:
        features.append(_trajectory_feature(reply.trajectory))
    if rooms is not None:
        features += [_room_feature(r) for r in rooms.get("rooms", ())]
        features += [_door_feature(d) for d in rooms.get("doors", ())]
    properties = {
        "frame": reply.frame,
        "units": "m",
        "note": "planar coordinates in metres in the map frame, not WGS 84",
        "frames": reply.frames,
        "observations": reply.observations,
        "stamp": reply.stamp,
    }
    return {"type": "FeatureCollection", "properties": properties, "features": features}


def write_geojson(path: Path, reply: MapReply, rooms: dict[str, Any] | None = None) -> None:
    """Write ``to_geojson(reply, rooms)`` to a file (strict JSON: non-finite is an error)."""
    text = json.dumps(to_geojson(reply, rooms), allow_nan=False, indent=1)
    Path(path).write_text(text + "\n", encoding="utf-8")
