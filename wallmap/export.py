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


def to_geojson(reply: MapReply) -> dict[str, Any]:
    """A FeatureCollection: one feature per wall, then the trajectory if the reply has one."""
    features = [_wall_feature(w) for w in reply.walls]
    if reply.trajectory:
        features.append(_trajectory_feature(reply.trajectory))
    properties = {
        "frame": reply.frame,
        "units": "m",
        "note": "planar coordinates in metres in the map frame, not WGS 84",
        "frames": reply.frames,
        "observations": reply.observations,
        "stamp": reply.stamp,
    }
    return {"type": "FeatureCollection", "properties": properties, "features": features}


def write_geojson(path: Path, reply: MapReply) -> None:
    """Write ``to_geojson(reply)`` to a file (strict JSON: non-finite numbers are an error)."""
    text = json.dumps(to_geojson(reply), allow_nan=False, indent=1)
    Path(path).write_text(text + "\n", encoding="utf-8")
