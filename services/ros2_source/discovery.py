"""Which sensor topic a robot has, from what its bridge or rmw_zenoh announces on Zenoh.

zenoh-bridge-ros2dds lists each route it serves in its admin space: a ROS topic published on
the robot is the key ``@/<bridge id>/ros2/route/topic/pub/<Zenoh key>``, whose JSON value names
the topic's ``ros2_type`` and ``zenoh_key_expr`` (the topic under the bridge's namespace).
rmw_zenoh announces every publisher by a liveliness token
``@ros2_lv/<domain>/<session>/<node>/<entity>/MP/<enclave>/<namespace>/<node name>/<topic>/<type>/
<hash>/<qos>``, the topic's slashes as ``%`` and its type as DDS names it. Of the topics of the
robot's namespace, those of a type the source reads are the candidates; with exactly one, it is
the sensor; with none or several, the user is told which to give as ``--sensor``.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass

import zenoh

from wallmap.services.player.errors import PlayerError
from wallmap.services.ros2_source.settings import LIVE_TYPES, Ros2Settings, ros_type_name

BRIDGE_ROUTES = "@/*/ros2/route/topic/pub"  # the bridge's admin space: topics from the robot
RMW_PUBLISHERS = "@ros2_lv"  # rmw_zenoh's graph: one liveliness token per entity
RETRY = 0.5  # s between two looks while nothing is announced yet


@dataclass(frozen=True, order=True)
class Announced:
    """A topic the robot publishes: its name under the namespace (no slashes at its ends)."""

    topic: str
    msgtype: str

    def sensor(self) -> str:
        """As ``--sensor`` takes it."""
        return f"{self.topic}:{self.msgtype}"


def _under(name: str, namespace: str) -> str | None:
    """``name`` without the namespace in front; None when it is not under it."""
    name, namespace = name.strip("/"), namespace.strip("/")
    if not namespace:
        return name
    return name[len(namespace) + 1 :] if name.startswith(f"{namespace}/") else None


def from_bridge_routes(values: Iterable[bytes], namespace: str) -> list[Announced]:
    """The topics in the bridge's route entries (JSON); entries it cannot read are skipped."""
    found = []
    for value in values:
        try:
            route = json.loads(value)
            key, msgtype = route["zenoh_key_expr"], route["ros2_type"]
        except (ValueError, TypeError, KeyError):
            continue
        topic = _under(str(key), namespace) if isinstance(key, str) else None
        if topic and isinstance(msgtype, str):
            found.append(Announced(topic, msgtype))
    return found


def from_rmw_tokens(keys: Iterable[str], namespace: str) -> list[Announced]:
    """The published topics in rmw_zenoh's liveliness tokens (``MP``: a message publisher).

    The type is the first chunk after ``MP`` that reads as a DDS type name, and the topic the
    chunk before it, so the fields that vary between rmw_zenoh releases before them (enclave,
    namespace, node) do not matter.
    """
    found = []
    for key in keys:
        chunks = key.split("/")
        if "MP" not in chunks:
            continue
        after = chunks[chunks.index("MP") + 1 :]
        for i, chunk in enumerate(after[1:], start=1):
            if (msgtype := ros_type_name(chunk)) is not None:
                topic = _under(after[i - 1].replace("%", "/"), namespace)
                if topic:
                    found.append(Announced(topic, msgtype))
                break
    return found


def choose_sensor(announced: Iterable[Announced], where: str) -> str | None:
    """The one sensor topic among those announced, as ``TOPIC:TYPE``; None if there is none.

    Raises:
        PlayerError: Several candidates: the user chooses, and is told the choices.
    """
    candidates = sorted({a for a in announced if a.msgtype in LIVE_TYPES})
    if len(candidates) > 1:
        choices = " or ".join(f"--sensor {c.sensor()}" for c in candidates)
        raise PlayerError(f"{len(candidates)} sensor topics {where}; choose one: {choices}")
    return candidates[0].sensor() if candidates else None


def discover_sensor(session: zenoh.Session, ros2: Ros2Settings, stop: threading.Event) -> str:
    """The robot's sensor topic, from what is announced within ``ros2.discover_wait`` seconds.

    Raises:
        PlayerError: No sensor topic announced in time (nor any topic: the bridge not
            reached, or the namespace wrong), or several.
    """
    deadline, where = time.monotonic() + ros2.discover_wait, _where(ros2)
    while True:
        announced = _announced(session, ros2)
        if (sensor := choose_sensor(announced, where)) is not None:
            return sensor
        if time.monotonic() >= deadline or stop.wait(RETRY):
            seen = ", ".join(a.sensor() for a in sorted(set(announced))) or "no topic at all"
            raise PlayerError(
                f"no sensor topic {where} within {ros2.discover_wait:g} s "
                f"(seen: {seen}); give --sensor TOPIC:TYPE"
            )


def _where(ros2: Ros2Settings) -> str:
    via = "rmw_zenoh" if ros2.rmw_zenoh is not None else "the bridge"
    namespace = f" under {ros2.namespace.strip('/')!r}" if ros2.namespace.strip("/") else ""
    return f"announced by {via}{namespace}"


def _announced(session: zenoh.Session, ros2: Ros2Settings) -> list[Announced]:
    namespace = ros2.namespace.strip("/")
    if ros2.rmw_zenoh is None:
        selector = f"{BRIDGE_ROUTES}/{namespace}/**" if namespace else f"{BRIDGE_ROUTES}/**"
        replies = session.get(selector, timeout=2.0)
        values = [r.ok.payload.to_bytes() for r in replies if r.ok is not None]
        return from_bridge_routes(values, namespace)
    tokens = session.liveliness().get(f"{RMW_PUBLISHERS}/{ros2.rmw_zenoh}/**", timeout=2.0)
    keys = [str(r.ok.key_expr) for r in tokens if r.ok is not None]
    return from_rmw_tokens(keys, namespace)
