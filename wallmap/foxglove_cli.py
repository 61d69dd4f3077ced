"""``wallmap record`` and ``wallmap foxglove``: a running wallmap system, seen in Foxglove.

Both follow the robot poses, the detector's observations and the map (one query, then its
updates), turn them into Foxglove messages (:mod:`wallmap.foxglove_bridge`) and log them: into
an MCAP file, or live through the foxglove-sdk WebSocket server. Both need the ``foxglove``
extra, imported only when one of them runs, so ``wallmap`` works and ``wallmap --help`` lists
them without it; without it they fail in one line.
"""

from __future__ import annotations

import argparse
import logging
import queue
import sys
import threading
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any

import zenoh

from wallmap import __version__
from wallmap.arg_types import port, positive
from wallmap.common.codec import MessageError, decode
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapUpdate
from wallmap.common.map_requests import QueryError, fetch_map, fetch_rooms
from wallmap.common.messages import unpack_observations, unpack_pose
from wallmap.common.runtime import Stats, drain, setup_logging, stop_on_signals
from wallmap.common.transport import Keys, open_session
from wallmap.config import Config, to_toml
from wallmap.options import ZENOH, add_command

EXTRA_MISSING = "the foxglove extra is not installed: pip install 'wallmap[foxglove]'"
WAIT_FOR_ROUTER = 5.0  # s: a person runs these, so a missing router fails soon, in one line
QUEUE_DEPTH = 256  # per subscriber; a thread empties each at once into the relay's inbox
POLL = 0.1  # s between checks of the stop conditions while nothing arrives
# What a bad message can raise on its way through the bridge: it is refused and counted.
REFUSALS = (MessageError, KeyError, TypeError, ValueError, OverflowError)


def add_commands(sub: Any) -> None:
    """Add ``record`` and ``foxglove`` to the ``wallmap`` subcommands (``add_subparsers()``)."""
    p = add_command(
        sub, "record", "record a running system to an MCAP file for Foxglove", _cmd_record, ZENOH
    )
    p.add_argument("out", type=Path, metavar="OUT", help="MCAP file to write (must not exist)")
    p.add_argument("--duration", type=positive, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--until-idle",
        type=positive,
        metavar="S",
        help="stop once no message came for S seconds, counted from the first one (e.g. after "
        "a --fast playback; the map fetched at start does not count)",
    )

    p = add_command(
        sub, "foxglove", "serve a running system live to Foxglove (WebSocket)", _cmd_foxglove, ZENOH
    )
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument(
        "--port", type=port, default=8765, help="WebSocket port (default 8765; 0: any free one)"
    )


def _bridge() -> ModuleType | None:
    """The bridge module, or None when the extra is not installed."""
    try:
        from wallmap import foxglove_bridge  # noqa: PLC0415 - the optional extra
    except ImportError as err:
        if (err.name or "").split(".")[0] != "foxglove":
            raise  # a broken wallmap, not a missing extra
        return None
    return foxglove_bridge


def _missing(args: argparse.Namespace) -> int:
    print(f"wallmap {args.command}: error: {EXTRA_MISSING}", file=sys.stderr)
    return 1


def _cmd_record(args: argparse.Namespace, config: Config) -> int:
    bridge = _bridge()
    if bridge is None:
        return _missing(args)
    import foxglove  # noqa: PLC0415 - the optional extra

    if args.out.exists():
        msg = f"{args.out} exists; choose a new path"
        raise FileExistsError(msg)
    log = setup_logging("record")
    stop = stop_on_signals()
    settings = replace(config.zenoh, wait_for_router=WAIT_FOR_ROUTER)
    context = foxglove.Context()
    with open_session(settings, stop=stop) as session:  # first: no router, no empty file
        relay = _Relay(bridge, context, log)
        with foxglove.open_mcap(args.out, context=context) as writer:
            writer.write_metadata("wallmap", {"version": __version__, "prefix": settings.prefix})
            writer.write_metadata("wallmap-config", {"toml": to_toml(config)})
            relay.run(
                session, Keys(settings.prefix), "record", stop, args.duration, args.until_idle
            )
    print(f"wrote {args.out}: {relay.summary()}")
    return 0


def _cmd_foxglove(args: argparse.Namespace, config: Config) -> int:
    bridge = _bridge()
    if bridge is None:
        return _missing(args)
    import foxglove  # noqa: PLC0415 - the optional extra

    log = setup_logging("foxglove")
    stop = stop_on_signals()
    settings = replace(config.zenoh, wait_for_router=WAIT_FOR_ROUTER)
    context = foxglove.Context()
    relay = _Relay(bridge, context, log)
    try:
        server = foxglove.start_server(
            name="wallmap",
            host=args.host,
            port=args.port,
            context=context,
            server_listener=_listener(relay),
        )
    except RuntimeError as err:  # the SDK's FoxgloveError, e.g. the port is taken
        msg = f"cannot serve Foxglove on {args.host}:{args.port} ({err})"
        raise OSError(msg) from err
    try:
        with open_session(settings, stop=stop) as session:
            print(f"Foxglove: open a connection to ws://{args.host}:{server.port}", flush=True)
            relay.run(session, Keys(settings.prefix), "foxglove", stop)
    finally:
        server.stop()
    print(f"published {relay.summary()}")
    return 0


def _listener(relay: _Relay) -> Any:
    """The WebSocket server's listener: a subscription asks the relay to send the map again."""
    from foxglove.websocket import ServerListener  # noqa: PLC0415 - the optional extra

    class Listener(ServerListener):  # the protocol's other callbacks do nothing
        def on_subscribe(self, client: Any, channel: Any) -> None:
            relay.resend(channel.topic)

    return Listener()


class _Relay:
    """Zenoh in, Foxglove out: subscribers drained by threads into one inbox, one converter.

    The converter runs in the calling thread, so the bridge needs no lock and nothing blocks a
    Zenoh callback, nor the WebSocket server's: a viewer that subscribes to the map has the
    latest map sent again (:meth:`resend`), at once instead of at the next update.
    """

    def __init__(self, bridge: ModuleType, context: Any, log: logging.Logger) -> None:
        self.bridge = bridge.Bridge()
        self.latched = bridge.LATCHED
        self.channels = bridge.make_channels(context)
        self.inbox: queue.Queue[tuple[str, bytes | str]] = queue.Queue()
        self.counts: Counter[str] = Counter()
        self.stats = Stats(log)
        self.log = log
        self.last_message: float | None = None  # when the latest Zenoh message came (monotonic)

    def resend(self, topic: str) -> None:
        """Ask for the latest message of ``topic`` again, if it is a latched one; never blocks."""
        if topic in self.latched:
            self.inbox.put(("resend", topic))

    def run(
        self,
        session: zenoh.Session,
        keys: Keys,
        service: str,
        stop: threading.Event,
        duration: float | None = None,
        idle: float | None = None,
    ) -> None:
        """Relay until ``stop``, for ``duration`` s, or until ``idle`` s pass without a message.

        Its liveliness token ``{prefix}/health/{service}`` lets a player ``--wait-for`` it.
        """
        subscribers = {
            kind: session.declare_subscriber(key, zenoh.handlers.FifoChannel(QUEUE_DEPTH))
            for kind, key in (
                ("pose", keys.pose),
                ("observations", keys.observations),
                ("map", keys.map_updates),
                ("rooms", keys.map_rooms_updates),
            )
        }
        token = session.liveliness().declare_token(keys.health(service))
        self._first_map(session, keys, subscribers["map"].handler)
        self._first_rooms(session, keys)
        threads = [
            threading.Thread(target=self._forward, args=(sub.handler, kind), daemon=True)
            for kind, sub in subscribers.items()
        ]
        for thread in threads:
            thread.start()
        self.log.info("relaying %s", ", ".join(str(s.key_expr) for s in subscribers.values()))
        start = time.monotonic()
        while not stop.is_set():
            now = time.monotonic()
            if duration is not None and now - start >= duration:
                break
            quiet = 0.0 if self.last_message is None else now - self.last_message
            if idle is not None and quiet >= idle:
                break
            try:
                kind, payload = self.inbox.get(timeout=POLL)
            except queue.Empty:
                continue
            self._handle(kind, payload)
        token.undeclare()
        for sub in subscribers.values():
            sub.undeclare()
        for thread in threads:
            thread.join(timeout=5.0)

    def _forward(self, channel: zenoh.handlers.Handler[zenoh.Sample], kind: str) -> None:
        for sample in drain(channel):
            self.inbox.put((kind, sample.payload.to_bytes()))

    def _first_map(
        self, session: zenoh.Session, keys: Keys, updates: zenoh.handlers.Handler[zenoh.Sample]
    ) -> None:
        """The map so far, with the path driven; then only the updates newer than it.

        The subscriber was declared first so no update is missed; those that arrived during the
        query and are already in the reply are dropped, or they would bring back merged walls.
        """
        try:
            query = MapQuery(tentative=True, trajectory=True)
            reply = fetch_map(session, keys, query, timeout=2.0)
            self._write(self.bridge.map_reply(reply))
        except QueryError as err:
            self.log.warning("%s: the walls come with the mapper's updates", err)
            return
        except REFUSALS as err:
            self.stats.refuse("map", str(err))
            return
        while (sample := updates.try_recv()) is not None:
            payload = sample.payload.to_bytes()
            try:
                if MapUpdate.from_map(decode(payload)).frames <= reply.frames:
                    continue
            except REFUSALS:
                pass  # refused, with its reason, where it is handled
            self.inbox.put(("map", payload))

    def _first_rooms(self, session: zenoh.Session, keys: Keys) -> None:
        """The rooms so far (a mapper segments them at most once a second, so they may lag)."""
        try:
            self._write(self.bridge.rooms(fetch_rooms(session, keys, timeout=2.0)))
        except QueryError as err:
            self.log.warning("%s: the rooms come with the mapper's updates", err)
        except REFUSALS as err:
            self.stats.refuse("rooms", str(err))

    def _handle(self, kind: str, payload: bytes | str) -> None:
        if isinstance(payload, str):  # a viewer subscribed to this latched topic
            out = self.bridge.latest.get(payload)
            self._write([out] if out else [])
            return
        self.last_message = time.monotonic()
        try:
            if kind == "pose":
                outs = self.bridge.pose(unpack_pose(payload))
            elif kind == "observations":
                outs = self.bridge.observations(unpack_observations(payload))
            elif kind == "rooms":
                outs = self.bridge.rooms(decode(payload))
            else:
                outs = self.bridge.map_update(MapUpdate.from_map(decode(payload)))
        except REFUSALS as err:
            self.stats.refuse(kind, str(err))
            return
        self._write(outs)

    def _write(self, outs: list[Any]) -> None:
        for out in outs:
            self.channels[out.topic].log(out.message, log_time=out.log_time)
            self.counts[out.topic] += 1

    def summary(self) -> str:
        """One line: messages per topic, and refusals if any."""
        per_topic = ", ".join(f"{topic} {n}" for topic, n in sorted(self.counts.items()))
        line = f"{self.counts.total()} messages ({per_topic or 'none'})"
        refused = self.stats.snapshot().get("refused", 0)
        return line + (f"; refused {refused} malformed" if refused else "")
