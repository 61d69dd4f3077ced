"""What the live source hears of the robot: each topic's messages, rate and silence. Pure.

A robot integrator's first question is whether the topics arrive at all: the bridge's namespace
wrong by one letter, the camera not started, ``tf_static`` never latched. ``wallmap status``
shows, per topic, how many messages came, at what rate lately, and how long since the last;
and which of the topics the source needs it has not heard from.
"""

from __future__ import annotations

import collections
from typing import Any

RATE_WINDOW = 5.0  # s over which the rate is measured
SILENT = 2.0  # s without a message: a topic that was heard is reported silent


class TopicWatch:
    """Arrival times of each topic's messages (the service's clock, seconds)."""

    def __init__(self, keys: dict[str, str]) -> None:
        """``keys``: the topics' Zenoh keys, by what they are (sensor, tf, tf_static, ...)."""
        self._keys = keys
        self._count: collections.Counter[str] = collections.Counter()
        self._times: dict[str, collections.deque[float]] = {
            kind: collections.deque(maxlen=2048) for kind in keys
        }

    def heard(self, kind: str, now: float) -> None:
        """One message of ``kind`` arrived at ``now``."""
        self._count[kind] += 1
        self._times[kind].append(now)

    def report(self, now: float) -> dict[str, Any]:
        """Per topic: messages, recent rate and silence; and what is missing.

        The rate is over the last RATE_WINDOW s; missing is a topic never heard, or silent for
        SILENT s (but ``tf_static``, which is sent once).
        """
        topics, missing = {}, []
        for kind, key in self._keys.items():
            times = self._times[kind]
            recent = sum(1 for t in times if now - t <= RATE_WINDOW)
            last = now - times[-1] if times else None
            topics[key] = {
                "messages": self._count[kind],
                "hz": round(recent / RATE_WINDOW, 1),
                "last_s": None if last is None else round(last, 1),
            }
            if last is None:
                missing.append(f"{key}: nothing heard")
            elif last > SILENT and kind != "tf_static":  # a static transform is sent once
                missing.append(f"{key}: silent for {last:.0f} s")
        return {"topics": topics, "missing": missing}
