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

from wallmap.common.codec import check_coordinates
from wallmap.common.fields import (
    Point,
    flag,
    integer,
    listed,
    matrix2,
    number,
    optional_number,
    point,
    refusal,
    required,
    string,
    table,
)
from wallmap.common.keyframes import Keyframe

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
        m = table(m, "walls")
        p0, p1 = point(required(m, "p0"), "p0"), point(required(m, "p1"), "p1")
        record = cls(
            id=integer(required(m, "id"), "id"),
            u=number(required(m, "u"), "u"),
            v=number(required(m, "v"), "v"),
            cov=matrix2(required(m, "cov"), "cov"),
            p0=p0,
            p1=p1,
            segments=_segments(_with_default(m.get("segments"), [[p0, p1]])),
            n_obs=integer(required(m, "n_obs"), "n_obs"),
            n_views=integer(m.get("n_views", 0), "n_views"),
            tentative=flag(m.get("tentative", False), "tentative"),
            first_seen=optional_number(m.get("first_seen"), "first_seen"),
            last_seen=optional_number(m.get("last_seen"), "last_seen"),
            sources=tuple(_source(x) for x in listed(m.get("sources", []), "sources")),
        )
        ends = [record.p0, record.p1, *(end for segment in record.segments for end in segment)]
        check_coordinates([(record.u, record.v), *ends], "a wall")
        return record


def _source(value: Any) -> tuple[str, int]:
    """A fleet wall's source: ``{"robot": prefix, "id": its wall id there}``."""
    source = table(value, "sources")
    robot = string(required(source, "robot", "sources.robot"), "sources.robot")
    if not robot:
        raise refusal("sources.robot", "a robot's prefix, not empty", robot)
    return robot, integer(required(source, "id", "sources.id"), "sources.id")


def _with_default(value: Any, default: Any) -> Any:
    """``value``, or ``default`` when it is missing or an empty list (not any falsy thing)."""
    return default if value is None or (isinstance(value, list) and not value) else value


def _segments(value: Any) -> tuple[Segment, ...]:
    """The stretches between doors: pairs of points."""
    segments = []
    for pair in listed(value, "segments"):
        a, b = listed(pair, "segments", 2, "points [[x, y], [x, y]]")
        segments.append((point(a, "segments"), point(b, "segments")))
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
    trajectory: tuple[Keyframe, ...] | None = None
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
        m = table(m)
        trajectory = m.get("trajectory")
        return cls(
            frame=str(m.get("frame", "map")),
            frames=integer(required(m, "frames"), "frames"),
            observations=integer(required(m, "observations"), "observations"),
            stamp=optional_number(m.get("stamp"), "stamp"),
            walls=tuple(WallRecord.from_map(w) for w in listed(required(m, "walls"), "walls")),
            merges=tuple(_merge(x) for x in listed(m.get("merges", []), "merges")),
            trajectory=None
            if trajectory is None
            else tuple(_keyframe(p) for p in listed(trajectory, "trajectory")),
            counters={k: m[k] for k in COUNTERS if k in m},
        )


def _merge(value: Any) -> tuple[int, int, float]:
    """Walls found to be one: ``[merged id, surviving id, stamp]``."""
    merged, surviving, stamp = listed(value, "merges", 3, "[merged, surviving, stamp]")
    return integer(merged, "merges"), integer(surviving, "merges"), number(stamp, "merges")


def _keyframe(value: Any) -> Keyframe:
    """A pose of the trajectory: ``[stamp, x, y, yaw]``."""
    row = listed(value, "trajectory", 4, "[stamp, x, y, yaw]")
    return Keyframe(*(number(v, "trajectory") for v in row))


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
        m = table(m)
        return cls(
            frames=integer(required(m, "frames"), "frames"),
            stamp=optional_number(m.get("stamp"), "stamp"),
            walls=tuple(WallRecord.from_map(w) for w in listed(m.get("walls", []), "walls")),
            removed=tuple(integer(i, "removed") for i in listed(m.get("removed", []), "removed")),
        )


def as_records(walls: Iterable[WallRecord | Mapping[str, Any]]) -> list[WallRecord]:
    """Wall records, typed, from typed ones or from the contract's JSON (a file, a script).

    Raises:
        MessageError: a record that is not one.
    """
    return [w if isinstance(w, WallRecord) else WallRecord.from_map(w) for w in walls]
