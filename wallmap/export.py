"""The map reply as GeoJSON, for GIS tools and web maps.

Coordinates are metres in wallmap's map frame, not WGS 84 longitude and latitude as RFC 7946
expects: the collection says so in ``properties`` (a foreign member, which RFC 7946 allows) rather
than in the obsolete ``crs`` member. Tools that assume degrees will misplace it; ones that take
plain planar coordinates (QGIS with a local CRS, shapely, most web canvases) draw it as it is.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

WALL_PROPERTIES = ("id", "u", "v", "cov", "n_obs", "first_seen", "last_seen")


def _xy(point: Any) -> list[float]:
    return [float(point[0]), float(point[1])]


def _wall_feature(wall: dict[str, Any]) -> dict[str, Any]:
    """A wall as a LineString (p0 to p1) or, when it has segments, a MultiLineString of them."""
    segments = wall.get("segments")
    if segments:
        lines = [[_xy(a), _xy(b)] for a, b in segments]
        geometry = {"type": "MultiLineString", "coordinates": lines}
    else:
        lines = [[_xy(wall["p0"]), _xy(wall["p1"])]]
        geometry = {"type": "LineString", "coordinates": lines[0]}
    properties = {"kind": "wall", **{key: wall[key] for key in WALL_PROPERTIES}}
    properties["length"] = sum(math.dist(a, b) for a, b in lines)  # of the seen parts only
    return {"type": "Feature", "id": wall["id"], "geometry": geometry, "properties": properties}


def _trajectory_feature(rows: list[list[float]]) -> dict[str, Any]:
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


def to_geojson(reply: dict[str, Any]) -> dict[str, Any]:
    """A FeatureCollection: one feature per wall, then the trajectory if the reply has one."""
    features = [_wall_feature(w) for w in reply.get("walls", [])]
    if reply.get("trajectory"):
        features.append(_trajectory_feature(reply["trajectory"]))
    properties = {
        "frame": reply.get("frame", "map"),
        "units": "m",
        "note": "planar coordinates in metres in the map frame, not WGS 84",
        **{key: reply[key] for key in ("frames", "observations", "stamp") if key in reply},
    }
    return {"type": "FeatureCollection", "properties": properties, "features": features}


def write_geojson(path: Path, reply: dict[str, Any]) -> None:
    """Write ``to_geojson(reply)`` to a file (strict JSON: non-finite numbers are an error)."""
    text = json.dumps(to_geojson(reply), allow_nan=False, indent=1)
    Path(path).write_text(text + "\n", encoding="utf-8")
