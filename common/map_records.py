"""The map on the wire: wall records, the map reply and the map update, typed and checked.

The mapper builds these and encodes them (``to_map``, then msgpack or JSON); every program that
reads the map (the command line, the view, Foxglove, ROS 2 out, the odometry, scripts) decodes
them with ``from_map``, which checks every field, so a malformed reply is one ``MessageError``
at the door, never a KeyError deep in a picture. The fields are the contract's
(docs/protocol.md): a wall's line as its closest point (u, v) to the map origin with its
covariance, its extent ``p0`` to ``p1`` and the ``segments`` between doors, how often and from how
many viewpoints it was seen, and whether it is still tentative.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from wallmap.common.codec import MessageError, check_coordinates

Point = tuple[float, float]
Segment = tuple[Point, Point]
COUNTERS = (
    "dropped",
    "dropped_reasons",
    "refused",
    "skipped",
    "lost",
    "missed",
    "slam",
    "pose_source",
)


def _number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise MessageError(f"field {name!r} must be a finite number, got {value!r}")
    return float(value)


def _integer(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise MessageError(f"field {name!r} must be an integer, got {value!r}")
    return value


def _stamp(value: Any, name: str) -> float | None:
    return None if value is None else _number(value, name)


def _point(value: Any, name: str) -> Point:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise MessageError(f"field {name!r} must be a point [x, y], got {value!r}")
    return _number(value[0], name), _number(value[1], name)


def _list(value: Any, name: str) -> list[Any]:
    if not isinstance(value, list | tuple):
        raise MessageError(f"field {name!r} must be a list, got {type(value).__name__}")
    return list(value)


def _table(value: Any, what: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise MessageError(f"{what} is a {type(value).__name__}, not a map")
    return value


@dataclass(frozen=True)
class WallRecord:
    """One wall as the map serves it, in the map frame (the contract's wall record).

    Attributes:
        id: Stable for the life of the map, across mapper restarts; a merged id is gone.
        u: The wall line's closest point to the map origin, x (the paper's parameters).
        v: ...and y.
        cov: The 2x2 covariance of (u, v).
        p0: One end of the extent seen.
        p1: The other end.
        segments: The stretches seen between doors and gaps, ``p0`` to ``p1``.
        n_obs: Observations that went into it.
        n_views: Distinct viewpoints it was seen from.
        tentative: Not yet confirmed, or a shadow of a better-seen wall.
        first_seen: Stamp of its first observation.
        last_seen: Stamp of its last observation.
        sources: In a fleet's map, each robot's wall fused into it: (robot prefix, its id).
    """

    id: int
    u: float
    v: float
    cov: tuple[Point, Point]
    p0: Point
    p1: Point
    segments: tuple[Segment, ...]
    n_obs: int
    n_views: int = 0
    tentative: bool = False
    first_seen: float | None = None
    last_seen: float | None = None
    sources: tuple[tuple[str, int], ...] = ()

    @property
    def length(self) -> float:
        """From ``p0`` to ``p1`` (m)."""
        return math.dist(self.p0, self.p1)

    def to_map(self) -> dict[str, Any]:
        """The contract's record, plain values for msgpack or JSON (``sources`` in a fleet's)."""
        sources = {"sources": [{"robot": r, "id": i} for r, i in self.sources]}
        return {
            "id": self.id,
            "u": self.u,
            "v": self.v,
            "cov": [list(row) for row in self.cov],
            "p0": list(self.p0),
            "p1": list(self.p1),
            "segments": [[list(a), list(b)] for a, b in self.segments],
            "n_obs": self.n_obs,
            "n_views": self.n_views,
            "tentative": self.tentative,
            "first_seen": self.first_seen,
            "last_seen": self.last_seen,
            **(sources if self.sources else {}),
        }

    @classmethod
    def from_segment(
        cls,
        wall_id: int,
        p0: Point,
        p1: Point,
        n_obs: int = 1,
        cov: tuple[Point, Point] = ((1e-4, 0.0), (0.0, 1e-4)),
    ) -> WallRecord:
        """A wall seen as one segment: (u, v) its line's closest point to the origin.

        For walls that come from elsewhere (a floor plan, another program's map), and for the
        tests and benchmarks that make maps by hand. The line must not pass through the origin.
        """
        (x0, y0), (x1, y1) = p0, p1
        length = math.hypot(x1 - x0, y1 - y0)
        nx, ny = (y0 - y1) / length, (x1 - x0) / length
        rho = nx * x0 + ny * y0
        ends = (float(x0), float(y0)), (float(x1), float(y1))
        return cls(wall_id, rho * nx, rho * ny, cov, *ends, (ends,), n_obs)

    @classmethod
    def from_map(cls, m: Any) -> WallRecord:
        """A received record, checked; MessageError names the field that is wrong."""
        m = _table(m, "a wall record")
        try:
            p0, p1 = _point(m["p0"], "p0"), _point(m["p1"], "p1")
            record = cls(
                id=_integer(m["id"], "id"),
                u=_number(m["u"], "u"),
                v=_number(m["v"], "v"),
                cov=_matrix2(m["cov"]),
                p0=p0,
                p1=p1,
                segments=_segments(_with_default(m.get("segments"), [[p0, p1]])),
                n_obs=_integer(m["n_obs"], "n_obs"),
                n_views=_integer(m.get("n_views", 0), "n_views"),
                tentative=m.get("tentative", False),
                first_seen=_stamp(m.get("first_seen"), "first_seen"),
                last_seen=_stamp(m.get("last_seen"), "last_seen"),
                sources=tuple(_source(x) for x in _list(m.get("sources", []), "sources")),
            )
        except KeyError as err:
            raise MessageError(f"wall record lacks {err}") from None
        if not isinstance(record.tentative, bool):
            raise MessageError("field 'tentative' must be true or false")
        ends = [record.p0, record.p1, *(end for segment in record.segments for end in segment)]
        check_coordinates([(record.u, record.v), *ends], "a wall")
        return record


def _source(value: Any) -> tuple[str, int]:
    """A fleet wall's source: ``{"robot": prefix, "id": its wall id there}``."""
    table = _table(value, "a wall's source")
    robot = table.get("robot")
    if not isinstance(robot, str) or not robot:
        raise MessageError(f"field 'sources' holds {value!r}, not a robot and an id")
    return robot, _integer(table.get("id"), "sources")


def _with_default(value: Any, default: Any) -> Any:
    """``value``, or ``default`` when it is missing or an empty list (not any falsy thing)."""
    return default if value is None or (isinstance(value, list) and not value) else value


def _matrix2(value: Any) -> tuple[Point, Point]:
    rows = _list(value, "cov")
    if len(rows) != 2:
        raise MessageError(f"field 'cov' must be a 2x2 matrix, got {value!r}")
    return _point(rows[0], "cov"), _point(rows[1], "cov")


def _segments(value: Any) -> tuple[Segment, ...]:
    segments = []
    for pair in _list(value, "segments"):
        ends = _list(pair, "segments")
        if len(ends) != 2:
            raise MessageError(f"field 'segments' holds {pair!r}, not a pair of points")
        segments.append((_point(ends[0], "segments"), _point(ends[1], "segments")))
    return tuple(segments)


@dataclass(frozen=True)
class MapReply:
    """The answer to ``{prefix}/map/walls``: the walls asked for and the map's counters.

    Attributes:
        frame: The map frame the walls are in.
        frames: Sensor frames the mapper has integrated.
        observations: Wall observations integrated.
        stamp: Stamp of the newest integrated frame (None before the first).
        walls: The walls asked for.
        merges: ``(merged id, surviving id, stamp)`` of walls found to be one.
        trajectory: Keyframes ``(stamp, x, y, yaw)`` of the poses used, when asked for.
        counters: The mapper's counters (dropped, refused, skipped, lost, missed, slam,
            pose_source: what the pose judge found of the source).
    """

    frame: str = "map"
    frames: int = 0
    observations: int = 0
    stamp: float | None = None
    walls: tuple[WallRecord, ...] = ()
    merges: tuple[tuple[int, int, float], ...] = ()
    trajectory: tuple[tuple[float, float, float, float], ...] | None = None
    counters: Mapping[str, Any] = field(default_factory=dict)

    def to_map(self) -> dict[str, Any]:
        """The contract's reply (the codec adds the schema version)."""
        body: dict[str, Any] = {
            "frame": self.frame,
            "frames": self.frames,
            "observations": self.observations,
            "stamp": self.stamp,
            "walls": [w.to_map() for w in self.walls],
            "merges": [list(m) for m in self.merges],
            **self.counters,
        }
        if self.trajectory is not None:
            body["trajectory"] = [list(p) for p in self.trajectory]
        return body

    @classmethod
    def from_map(cls, m: Any) -> MapReply:
        """A received reply, checked; MessageError says what is wrong."""
        m = _table(m, "the map reply")
        try:
            trajectory = m.get("trajectory")
            return cls(
                frame=str(m.get("frame", "map")),
                frames=_integer(m["frames"], "frames"),
                observations=_integer(m["observations"], "observations"),
                stamp=_stamp(m.get("stamp"), "stamp"),
                walls=tuple(WallRecord.from_map(w) for w in _list(m["walls"], "walls")),
                merges=tuple(_merge(x) for x in _list(m.get("merges", []), "merges")),
                trajectory=None
                if trajectory is None
                else tuple(_keyframe(p) for p in _list(trajectory, "trajectory")),
                counters={k: m[k] for k in COUNTERS if k in m},
            )
        except KeyError as err:
            raise MessageError(f"the map reply lacks {err}") from None


def _merge(value: Any) -> tuple[int, int, float]:
    row = _list(value, "merges")
    if len(row) != 3:
        raise MessageError(f"field 'merges' holds {value!r}, not [merged, surviving, stamp]")
    return _integer(row[0], "merges"), _integer(row[1], "merges"), _number(row[2], "merges")


def _keyframe(value: Any) -> tuple[float, float, float, float]:
    row = _list(value, "trajectory")
    if len(row) != 4:
        raise MessageError(f"field 'trajectory' holds {value!r}, not [stamp, x, y, yaw]")
    stamp, x, y, yaw = (_number(v, "trajectory") for v in row)
    return stamp, x, y, yaw


@dataclass(frozen=True)
class MapUpdate:
    """What changed in the map since the last update: ``{prefix}/map/updates``.

    Attributes:
        frames: Sensor frames integrated when it was taken.
        stamp: Stamp of the newest integrated frame.
        walls: The walls that changed (and their neighbours, whose corners may have moved).
        removed: Ids merged away or otherwise gone.
    """

    frames: int
    stamp: float | None
    walls: tuple[WallRecord, ...] = ()
    removed: tuple[int, ...] = ()

    def to_map(self) -> dict[str, Any]:
        """Plain values for msgpack."""
        return {
            "frames": self.frames,
            "stamp": self.stamp,
            "walls": [w.to_map() for w in self.walls],
            "removed": list(self.removed),
        }

    @classmethod
    def from_map(cls, m: Any) -> MapUpdate:
        """A received update, checked; MessageError says what is wrong."""
        m = _table(m, "a map update")
        try:
            return cls(
                frames=_integer(m["frames"], "frames"),
                stamp=_stamp(m.get("stamp"), "stamp"),
                walls=tuple(WallRecord.from_map(w) for w in _list(m.get("walls", []), "walls")),
                removed=tuple(
                    _integer(i, "removed") for i in _list(m.get("removed", []), "removed")
                ),
            )
        except KeyError as err:
            raise MessageError(f"the map update lacks {err}") from None


def as_records(walls: Iterable[WallRecord | Mapping[str, Any]]) -> list[WallRecord]:
    """Wall records, typed, from typed ones or from the contract's JSON (a file, a script).

    Raises:
        MessageError: a record that is not one.
    """
    return [w if isinstance(w, WallRecord) else WallRecord.from_map(w) for w in walls]
