"""Fetch the wall map over Zenoh and print it for people."""

from __future__ import annotations

import json
from typing import Any

import zenoh

from wallmap.common.codec import MessageError, decode
from wallmap.common.transport import Keys


class QueryError(RuntimeError):
    """No usable map came back; the message says why, in one line."""


def fetch_map(
    session: zenoh.Session, keys: Keys, *, timeout: float = 5.0, **parameters: object
) -> dict[str, Any]:
    """Query ``{prefix}/map/walls`` with selector parameters and return the decoded reply.

    Parameters are the mapper's (``min_obs``, ``tentative``, ``bbox``, ``since``,
    ``trajectory``); None leaves one out, booleans become true/false.
    """
    pairs = [
        f"{name}={str(value).lower() if isinstance(value, bool) else value}"
        for name, value in parameters.items()
        if value is not None
    ]
    selector = keys.map_walls + ("?" + ";".join(pairs) if pairs else "")
    for reply in session.get(selector, timeout=timeout):
        if reply.ok is None:
            msg = f"the mapper refused the query: {reply.err.payload.to_string()}"
            raise QueryError(msg)
        try:
            return decode(reply.ok.payload.to_bytes())
        except MessageError as err:
            msg = f"the map reply is unreadable: {err}"
            raise QueryError(msg) from err
    msg = f"no mapper answered on {keys.map_walls} within {timeout:.0f} s"
    raise QueryError(msg)


def format_table(reply: dict[str, Any]) -> str:
    """The map as a fixed-width table, with the counters above it."""
    walls = sorted(reply["walls"], key=lambda w: w["id"])
    lines = [
        f"{len(walls)} walls from {reply['frames']} frames and {reply['observations']} "
        f"observations (frame {reply['frame']})",
        f"{'id':>4} {'u':>8} {'v':>8} {'sigma':>7} {'x0':>8} {'y0':>8} {'x1':>8} {'y1':>8}"
        f" {'length':>7} {'n_obs':>6}",
    ]
    for w in walls:
        sigma = max(w["cov"][0][0], w["cov"][1][1]) ** 0.5
        (x0, y0), (x1, y1) = w["p0"], w["p1"]
        length = ((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5
        lines.append(
            f"{w['id']:>4} {w['u']:>8.3f} {w['v']:>8.3f} {sigma:>7.4f} {x0:>8.3f} {y0:>8.3f}"
            f" {x1:>8.3f} {y1:>8.3f} {length:>7.2f} {w['n_obs']:>6}"
        )
    return "\n".join(lines)


def to_json(reply: dict[str, Any]) -> str:
    """The reply as the contract's JSON document."""
    return json.dumps(reply, indent=1)
