"""The wall map for people: a table, the contract's JSON; the rooms, fetched and printed."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common.codec import SCHEMA_VERSION, MessageError
from wallmap.common.map_records import MapReply
from wallmap.common.map_requests import ask_mapper
from wallmap.common.transport import Keys

if TYPE_CHECKING:
    import zenoh


def format_table(reply: MapReply) -> str:
    """The map as a fixed-width table, with the counters above it."""
    walls = sorted(reply.walls, key=lambda w: w.id)
    lines = [
        f"{_count(len(walls), 'wall')} from {_count(reply.frames, 'frame')} and "
        f"{_count(reply.observations, 'observation')} (frame {reply.frame})",
    ]
    judged = reply.counters.get("pose_source")
    if isinstance(judged, dict) and judged:
        lines.append(describe_pose_source(judged))
    if walls:
        lines.append(
            f"{'id':>4} {'u':>8} {'v':>8} {'sigma':>7} {'x0':>8} {'y0':>8} {'x1':>8} {'y1':>8}"
            f" {'length':>7} {'n_obs':>6}"
        )
    for w in walls:
        sigma = max(w.cov[0][0], w.cov[1][1]) ** 0.5
        (x0, y0), (x1, y1) = w.p0, w.p1
        lines.append(
            f"{w.id:>4} {w.u:>8.3f} {w.v:>8.3f} {sigma:>7.4f} {x0:>8.3f} {y0:>8.3f}"
            f" {x1:>8.3f} {y1:>8.3f} {w.length:>7.2f} {w.n_obs:>6}"
        )
    return "\n".join(lines)


def describe_pose_source(found: dict[str, Any]) -> str:
    """What the pose judge found of the pose source (the reply's ``pose_source``), one line."""
    if found.get("latency_fixed"):
        how = "given"
    else:  # older mappers did not say whether it was settled: theirs was estimated
        how = "estimated" if found.get("settled", True) else "not yet estimated: the guess"
    return (
        f"poses: latency {found['latency_s'] * 1e3:+.0f} ms ({how}), noise "
        f"{found['position_sd_m'] * 100:.1f} cm / {found['heading_sd_deg']:.2f} deg; frames "
        f"corrected {found['frames_corrected']}, recovered {found['frames_recovered']}, "
        f"refused {found['frames_refused']}, unjudged {found['frames_unjudged']}"
    )


def _count(n: int, thing: str) -> str:
    return f"{n} {thing}{'' if n == 1 else 's'}"


def to_json(reply: MapReply, **extra: Any) -> str:
    """The reply as the contract's JSON document (``extra`` fields added at its top)."""
    return json.dumps({"v": SCHEMA_VERSION, **reply.to_map(), **extra}, indent=1)


def fetch_robots(session: zenoh.Session, keys: Keys, *, timeout: float = 5.0) -> dict[str, Any]:
    """Ask a fleet's ``{prefix}/robots``: where each robot's frame lies, and its path there.

    Raises:
        QueryError: no merge service answered, it refused, or its reply is unreadable.
    """
    return ask_mapper(session, keys.robots, "robots", _robots_body, timeout)


def robot_paths(robots: dict[str, Any]) -> list[NDArray[np.float64]]:
    """Each aligned robot's path (stamp, x, y, yaw rows) from a fleet's robots reply."""
    return [
        np.asarray(r["trajectory"], dtype=float).reshape(-1, 4)
        for r in robots["robots"]
        if r.get("trajectory")
    ]


def _robots_body(body: Any) -> dict[str, Any]:
    """The fleet's robots reply, if it holds a list of robots; MessageError if not."""
    if not isinstance(body, dict) or not isinstance(body.get("robots"), list):
        raise MessageError("it has no 'robots' list")
    return body


def format_rooms(body: dict[str, Any]) -> str:
    """The rooms and doors as two fixed-width tables."""
    rooms, doors = body["rooms"], body["doors"]
    lines = [f"{_count(len(rooms), 'room')}, {_count(len(doors), 'door')} (frame map)"]
    if rooms:
        lines.append(f"{'id':>4} {'area':>7} {'cx':>8} {'cy':>8} {'closed':>6}  walls / doors")
    for r in rooms:
        cx, cy = r["centroid"]
        closed = "yes" if r["closed"] else "no"
        lines.append(
            f"{r['id']:>4} {r['area']:>7.2f} {cx:>8.3f} {cy:>8.3f} {closed:>6}  "
            f"{','.join(map(str, r['walls'])) or '-'} / {','.join(map(str, r['doors'])) or '-'}"
        )
    if doors:
        lines.append(f"{'door':>4} {'width':>7} {'cx':>8} {'cy':>8} {'wall':>6}  rooms")
    for d in doors:
        cx, cy = d["center"]
        joined = " - ".join(map(str, d["rooms"])) if len(d["rooms"]) > 1 else f"{d['rooms'][0]} - ?"
        lines.append(
            f"{d['id']:>4} {d['width']:>7.2f} {cx:>8.3f} {cy:>8.3f} {d['wall']:>6}  {joined}"
        )
    return "\n".join(lines)
