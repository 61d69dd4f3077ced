"""The wall map for people: a table, the contract's JSON."""

from __future__ import annotations

import json
from typing import Any

from wallmap.common.codec import SCHEMA_VERSION
from wallmap.common.map_records import MapReply


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
    how = "given" if found.get("latency_fixed") else "estimated"
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
