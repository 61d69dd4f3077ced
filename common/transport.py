"""Zenoh sessions from one set of settings, and the key space.

Every subcommand that talks Zenoh takes the same settings (the ``zenoh`` section of the
configuration: ``--connect``, ``--prefix``, ``--zenoh-config``; env ``WALLMAP_CONNECT``,
``WALLMAP_PREFIX``). The Zenoh json5 file is applied first and the settings override it.
Multicast scouting is off unless that file turns it on, so nothing joins a stranger's network by
accident.
"""

from __future__ import annotations

import json
import logging
import math
import re
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import zenoh

from wallmap.common.link_settings import DEFAULT_PREFIX, TransportError, ZenohSettings

# How often a client tries its router again once the link is lost. Zenoh's default starts at
# 1 s and doubles to 4 s, which adds up to 4 s of loss after the router is back; a connect
# attempt to a loopback or LAN router costs next to nothing.
RECONNECT = "{period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2}"
# Zenoh's shared-memory transport (on by default, for messages over 3 kB): a router and every
# subscriber keep about 20 MB of each publishing session's segments after that session ends, so
# a long-running router and detector grew with every bag played (460 and 580 MB after 20). A
# session that comes and goes (the player) sends without it; the services that stay keep it (a
# live robot's big clouds cross a busy machine without loss through it).
SHARED_MEMORY = "transport/shared_memory/enabled"


class StoppedWaiting(Exception):  # noqa: N818 - a stop asked for, not an error
    """A stop (SIGINT, SIGTERM) came while the session was still waiting for its router."""


def zenoh_reason(err: Exception) -> str:
    """Zenoh's error text as one line: the position and reason of a parse error, no source path."""
    text = re.sub(r" at /\S+\.rs:\d+\.?", "", str(err)).strip()
    message = re.search(r'Json5Err\(Message \{ msg: "((?:[^"\\]|\\.)*)"', text)
    if message:  # a value Zenoh refused, in Rust's debug form
        return message[1]
    position = re.search(r"-->\s*(\d+):(\d+)", text)
    reason = re.search(r"^\s*= (.+)$", text, re.MULTILINE)
    if position and reason:
        return f"line {position[1]}, column {position[2]}: {reason[1].strip()}"
    return " ".join(text.split())


def key_expression(value: str, flag: str) -> str:
    """A key expression checked by Zenoh, so a typo fails in one line at start."""
    try:
        zenoh.KeyExpr(value)
    except zenoh.ZError as err:
        msg = f"invalid {flag} {value!r}: {zenoh_reason(err)}"
        raise TransportError(msg) from err
    return value


def make_config(
    settings: ZenohSettings,
    *,
    mode: str = "client",
    listen: tuple[str, ...] = (),
    join: tuple[str, ...] = (),
    shared_memory: bool = True,
) -> zenoh.Config:
    """Build the Zenoh config: file first, then what the flags say.

    A router listens on ``listen`` and joins the routers at ``join`` (a mesh: a router reaches
    another only through its own ``connect/endpoints``); it never connects to itself. Without
    ``shared_memory`` the session sends without Zenoh's shared memory, unless the file speaks of
    it (``SHARED_MEMORY``).
    """
    if settings.config_file is not None:
        if not settings.config_file.is_file():
            msg = f"zenoh config {settings.config_file} does not exist"
            raise TransportError(msg)
        try:
            conf = zenoh.Config.from_file(str(settings.config_file))
        except zenoh.ZError as err:
            msg = f"zenoh config {settings.config_file} is invalid: {zenoh_reason(err)}"
            raise TransportError(msg) from err
        text = settings.config_file.read_text(encoding="utf-8")
        # Zenoh's default turns multicast on: keep it off unless the file speaks of it.
        if "multicast" not in text:
            conf.insert_json5("scouting/multicast/enabled", "false")
        if "retry" not in text:
            conf.insert_json5("connect/retry", RECONNECT)
        shared_memory = shared_memory or "shared_memory" in text
    else:
        conf = zenoh.Config()
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("connect/retry", RECONNECT)
    if not shared_memory:
        conf.insert_json5(SHARED_MEMORY, "false")
    conf.insert_json5("mode", json.dumps(mode))
    if mode == "router":
        _insert_endpoints(conf, "listen", listen)
        if itself := sorted(set(join) & set(listen)):
            msg = f"a router cannot join itself: --connect {itself[0]} is one of its --listen"
            raise TransportError(msg)
        if join:
            _insert_endpoints(conf, "connect", join)
    else:
        _insert_endpoints(conf, "connect", settings.connect)
        if settings.wait_for_router:
            wait = settings.wait_for_router
            timeout_ms = -1 if math.isinf(wait) else round(wait * 1000)
            conf.insert_json5("connect/timeout_ms", str(timeout_ms))
    return conf


@contextmanager
def open_session(
    settings: ZenohSettings,
    *,
    mode: str = "client",
    listen: tuple[str, ...] = (),
    join: tuple[str, ...] = (),
    count: Callable[[str], None] | None = None,
    stop: threading.Event | None = None,
    shared_memory: bool = True,
) -> Iterator[zenoh.Session]:
    """A session for the ``with`` block, Zenoh's errors turned into one readable line.

    A router listens on ``listen`` and joins the routers at ``join`` (``make_config``).

    A client's link to its router is watched (see ``RouterWatch``); ``count`` is told of each
    loss and recovery (``router_lost``, ``router_back``), for the service's counters. ``stop``
    (set by SIGINT or SIGTERM) ends a wait for the router with ``StoppedWaiting``.
    """
    conf = make_config(settings, mode=mode, listen=listen, join=join, shared_memory=shared_memory)
    where = ", ".join(listen if mode == "router" else settings.connect)
    try:
        session = zenoh.open(conf) if stop is None else _open_unless_stopped(conf, stop, where)
    except zenoh.ZError as err:
        verb = "listen on" if mode == "router" else "reach a Zenoh router at"
        msg = f"cannot {verb} {where} ({zenoh_reason(err)})"
        raise TransportError(msg) from err
    watch = RouterWatch(session, settings.connect, count) if mode != "router" else None
    try:
        yield session
    finally:
        if watch is not None:
            watch.close()
        _close(session)


def _insert_endpoints(conf: zenoh.Config, what: str, endpoints: tuple[str, ...]) -> None:
    """``listen`` or ``connect`` endpoints; one that Zenoh refuses is one line naming it."""
    try:
        conf.insert_json5(f"{what}/endpoints", json.dumps(list(endpoints)))
    except zenoh.ZError as err:
        msg = f"invalid --{what} {', '.join(endpoints)!r}: {zenoh_reason(err)}"
        raise TransportError(msg) from err


def _open_unless_stopped(conf: zenoh.Config, stop: threading.Event, where: str) -> zenoh.Session:
    """``zenoh.open`` on a thread of its own, so that a stop is heard while it waits.

    A client waiting for its router blocks in ``zenoh.open`` (``connect/timeout_ms``), and a
    signal's Python handler runs only once the main thread is back in Python: Ctrl-C and
    SIGTERM would go unheard until a router came. The thread left waiting is a daemon.
    """
    opened: list[zenoh.Session] = []
    failed: list[zenoh.ZError] = []

    def opening() -> None:
        try:
            opened.append(zenoh.open(conf))
        except zenoh.ZError as err:
            failed.append(err)

    thread = threading.Thread(target=opening, name="zenoh-open", daemon=True)
    thread.start()
    while thread.is_alive():
        if stop.is_set():
            msg = f"stopped while waiting for a Zenoh router at {where}"
            raise StoppedWaiting(msg)
        thread.join(0.1)
    if failed:
        raise failed[0]
    return opened[0]


def _close(session: zenoh.Session) -> None:
    """Close a session; a close that fails is one line (the work is done by then)."""
    try:
        session.close()
    except zenoh.ZError as err:
        msg = f"the Zenoh session did not close cleanly ({zenoh_reason(err)})"
        raise TransportError(msg) from err


class RouterWatch:
    """Says when a client loses its router and when it is back, once each, with how long.

    Zenoh reconnects by itself and declares the session's subscribers, queryables, publishers
    and liveliness tokens again on the new link; what was sent while the link was down is lost
    (nothing raises), so the outage must at least be visible in the logs and the counters.
    """

    def __init__(
        self,
        session: zenoh.Session,
        endpoints: tuple[str, ...],
        count: Callable[[str], None] | None = None,
    ) -> None:
        self._log = logging.getLogger("wallmap.link")
        self._where = ", ".join(endpoints)
        self._count = count
        self._lock = threading.Lock()
        self._routers: set[str] = {str(zid) for zid in session.info.routers_zid()}
        self._lost_at: float | None = None
        # A callback, not a channel: two set operations and a log line, never blocking.
        self._listener = session.info.declare_transport_events_listener(self._on_event)

    def _on_event(self, event: zenoh.TransportEvent) -> None:
        if event.transport.whatami != zenoh.WhatAmI.ROUTER:
            return
        zid = str(event.transport.zid)
        with self._lock:
            if event.kind == zenoh.SampleKind.PUT:
                self._routers.add(zid)
                lost_at, self._lost_at = self._lost_at, None
                if lost_at is None:
                    return
                outage = time.monotonic() - lost_at
                self._log.warning("reconnected to the Zenoh router after %.1f s", outage)
                event_name = "router_back"
            else:
                self._routers.discard(zid)
                if self._routers or self._lost_at is not None:
                    return
                self._lost_at = time.monotonic()
                self._log.warning(
                    "lost the Zenoh router at %s; reconnecting (what is sent meanwhile is lost)",
                    self._where,
                )
                event_name = "router_lost"
        if self._count is not None:
            self._count(event_name)

    def close(self) -> None:
        """Stop watching (before the session closes, which ends every link)."""
        self._listener.undeclare()


@dataclass(frozen=True)
class Keys:
    """The key expressions under one prefix (see docs/protocol.md)."""

    prefix: str = DEFAULT_PREFIX

    @property
    def frames(self) -> str:
        """Sensor frames, player -> detector."""
        return f"{self.prefix}/sensor/frames"

    @property
    def pose(self) -> str:
        """Robot poses in the map frame (the contract's pose key)."""
        return f"{self.prefix}/pose"

    @property
    def pose_corrected(self) -> str:
        """The mapper's corrected pose under --slam (a contract pose)."""
        return f"{self.prefix}/pose/corrected"

    @property
    def pose_correction(self) -> str:
        """The map -> odom correction under --slam (a contract pose, child ``odom``)."""
        return f"{self.prefix}/pose/correction"

    @property
    def observations(self) -> str:
        """Wall observations, detector -> mapper."""
        return f"{self.prefix}/walls/observations"

    @property
    def detector_rows(self) -> str:
        """Queryable of the detector: the row selection, so players send only that row."""
        return f"{self.prefix}/detector/rows"

    @property
    def markers(self) -> str:
        """ROS 2 out: visualization_msgs/msg/MarkerArray (CDR), as zenoh-bridge-ros2dds names it."""
        return f"{self.prefix}/markers"

    @property
    def trajectory(self) -> str:
        """ROS 2 out: nav_msgs/msg/Path (CDR) of the poses the mapper used."""
        return f"{self.prefix}/trajectory"

    @property
    def map_walls(self) -> str:
        """Queryable: the current wall map (the contract's map key)."""
        return f"{self.prefix}/map/walls"

    @property
    def map_updates(self) -> str:
        """Walls that changed, published by the mapper as they change (rate-limited)."""
        return f"{self.prefix}/map/updates"

    @property
    def room_markers(self) -> str:
        """ROS 2 out: visualization_msgs/msg/MarkerArray (CDR) of the rooms and doors."""
        return f"{self.prefix}/rooms/markers"

    @property
    def map_rooms(self) -> str:
        """Queryable: the rooms and the doors between them (``services.mapper.room_map``)."""
        return f"{self.prefix}/map/rooms"

    @property
    def map_rooms_updates(self) -> str:
        """The rooms' payload again, published by the mapper when the rooms changed."""
        return f"{self.prefix}/map/rooms/updates"

    @property
    def robots(self) -> str:
        """Queryable of a fleet's merge service: where each robot's map frame lies."""
        return f"{self.prefix}/robots"

    @property
    def progress(self) -> str:
        """Mapper acknowledgements of the frames of each player run."""
        return f"{self.prefix}/mapper/progress"

    @property
    def detector_diagnostics(self) -> str:
        """Per frame, why the detector found the walls it found (or none)."""
        return f"{self.prefix}/detector/diagnostics"

    @property
    def player_control(self) -> str:
        """Queryable of the player: pause, resume, step, seek, rate."""
        return f"{self.prefix}/player/control"

    @property
    def player_progress(self) -> str:
        """The player's position in its bag, published as it plays."""
        return f"{self.prefix}/player/progress"

    def stats(self, service: str = "*") -> str:
        """Queryable of a running service: its counters, for ``wallmap status``."""
        return f"{self.prefix}/stats/{service}"

    def health(self, service: str = "*") -> str:
        """Liveliness token of a running service."""
        return f"{self.prefix}/health/{service}"
