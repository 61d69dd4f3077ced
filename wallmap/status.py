"""``wallmap status``: the services that are live under a prefix, and their counters."""

from __future__ import annotations

import json
from typing import Any

import zenoh

from wallmap.common.codec import MessageError, decode
from wallmap.common.transport import Keys
from wallmap.map_client import describe_pose_source


def fetch_status(session: zenoh.Session, keys: Keys, timeout: float = 2.0) -> list[dict[str, Any]]:
    """One entry per live service (its liveliness token), with its counters when it answers.

    A service without counters (a player, an outside pose publisher) is listed as live alone.
    """
    live = sorted(
        str(reply.ok.key_expr).rsplit("/", 1)[-1]
        for reply in session.liveliness().get(keys.health("*"), timeout=timeout)
        if reply.ok is not None
    )
    counters: dict[str, dict[str, Any]] = {}
    replies = session.get(
        keys.stats("*"),
        target=zenoh.QueryTarget.ALL,  # every service answers, not only the nearest
        consolidation=zenoh.ConsolidationMode.NONE,
        timeout=timeout,
    )
    for reply in replies:
        if reply.ok is None:
            continue
        try:
            body = decode(reply.ok.payload.to_bytes())
            counters[str(body["service"])] = body
        except (MessageError, KeyError, TypeError):
            continue  # a stranger on our key: not ours to list
    return [
        {
            "service": name,
            "live": True,
            "uptime": counters.get(name, {}).get("uptime"),
            "counters": counters.get(name, {}).get("counters", {}),
            **({"pose_source": s} if (s := counters.get(name, {}).get("pose_source")) else {}),
            **{
                k: counters[name][k]
                for k in ("run", "topics", "missing")
                if k in counters.get(name, {})
            },
        }
        for name in live
    ]


def format_status(services: list[dict[str, Any]], prefix: str) -> str:
    """A table people can read: service, uptime, then its counters by name."""
    if not services:
        return f"no wallmap service is live under prefix {prefix!r}"
    width = max(len(s["service"]) for s in services)
    lines = [f"{'service':<{width}}  {'uptime':>8}  counters"]
    for entry in services:
        uptime = "-" if entry["uptime"] is None else f"{entry['uptime']:.0f} s"
        counters = ", ".join(f"{k} {v}" for k, v in sorted(entry["counters"].items())) or "-"
        lines.append(f"{entry['service']:<{width}}  {uptime:>8}  {counters}")
        if isinstance(entry.get("pose_source"), dict):
            lines.append(f"{'':<{width}}  {'':>8}  {describe_pose_source(entry['pose_source'])}")
        for key, seen in dict(entry.get("topics") or {}).items():  # a live source's topics
            last = "never" if seen["last_s"] is None else f"last {seen['last_s']} s ago"
            lines.append(
                f"{'':<{width}}  {'':>8}  {key}: {seen['messages']} messages, "
                f"{seen['hz']} Hz, {last}"
            )
        for problem in entry.get("missing") or ():
            lines.append(f"{'':<{width}}  {'':>8}  missing: {problem}")
    return "\n".join(lines)


def to_json(services: list[dict[str, Any]]) -> str:
    """The same as JSON, for scripts."""
    return json.dumps(services, indent=2, sort_keys=True)
