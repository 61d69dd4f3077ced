"""`wallmap view`: serve a live picture of the wall map on localhost.

Two halves share one :class:`~wallmap.view.live.LiveMap`. The Zenoh half follows the map:
subscribers on the map updates, the poses and the observations, each with a FIFO channel drained
by its own thread (Zenoh's callbacks only enqueue), and a thread that queries the whole map every
few seconds for the trajectory and to heal anything an update missed. The HTTP half is the
standard library's threading server: the page and its script (shipped in ``static/``) and a small
JSON API the page polls (docs/view.md).
"""

from __future__ import annotations

import argparse
import errno
import json
import logging
import socket
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import replace
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

import zenoh

from wallmap.common.codec import MessageError, decode
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply, MapUpdate
from wallmap.common.map_requests import MalformedReplyError, QueryError, fetch_map, fetch_rooms
from wallmap.common.messages import unpack_observations, unpack_pose
from wallmap.common.runtime import Stats, drain, setup_logging, stop_on_signals
from wallmap.common.transport import (
    Keys,
    open_session,
)
from wallmap.config import Config
from wallmap.view.live import LiveMap

REQUERY_PERIOD = 2.0  # s between whole-map queries (the trajectory is not in the updates)
QUERY_TIMEOUT = 5.0  # s
ROUTER_WAIT = 3.0  # s to reach the router at start, then fail in one line
QUEUE_DEPTH = 64  # per subscriber; its thread does little more than decode
STATIC = {  # URL path -> file in static/, and its content type: nothing else is served
    "/": ("index.html", "text/html; charset=utf-8"),
    "/view.js": ("view.js", "text/javascript; charset=utf-8"),
    "/view.css": ("view.css", "text/css; charset=utf-8"),
}


def load_static() -> dict[str, tuple[bytes, str]]:
    """The page's files, read once from the package, keyed by URL path.

    Raises:
        OSError: a file is missing, e.g. an install made without the package data.
    """
    folder = resources.files(__package__).joinpath("static")
    out = {}
    for path, (name, content_type) in STATIC.items():
        try:
            out[path] = (folder.joinpath(name).read_bytes(), content_type)
        except OSError as err:
            msg = f"the page's file {name} is missing from the installed package ({err})"
            raise OSError(msg) from err
    return out


class ViewServer(ThreadingHTTPServer):
    """The HTTP server, holding what the handlers read."""

    daemon_threads = True

    def __init__(self, host: str, port: int, live: LiveMap, static: dict[str, Any]) -> None:
        self.address_family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.live = live
        self.static = static
        try:
            super().__init__((host, port), _Handler)
        except OSError as err:
            hint = "another --port" if err.errno in (errno.EADDRINUSE, errno.EACCES) else "--host"
            msg = f"cannot serve on {host}:{port}: {err.strerror or err} (check {hint})"
            raise OSError(msg) from err

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A page closed mid-reply is routine; anything else is printed with its traceback."""
        if not isinstance(sys.exc_info()[1], ConnectionError):
            super().handle_error(request, client_address)

    @property
    def url(self) -> str:
        """Where the page is, with the port actually bound (``--port 0`` picks one)."""
        host, port = self.server_address[:2]
        return f"http://[{host}]:{port}/" if ":" in str(host) else f"http://{host}:{port}/"


class _Handler(BaseHTTPRequestHandler):
    server: ViewServer
    protocol_version = "HTTP/1.1"  # keep-alive: the page polls twice a second

    def do_GET(self) -> None:
        url = urlsplit(self.path)
        if url.path in self.server.static:
            body, content_type = self.server.static[url.path]
            self._send(HTTPStatus.OK, body, content_type)
        elif url.path == "/api/map":
            try:
                since = int(parse_qs(url.query).get("since", ["0"])[0])
            except ValueError:
                self._json(HTTPStatus.BAD_REQUEST, {"error": "since must be an integer"})
                return
            self._json(HTTPStatus.OK, self.server.live.delta(since))
        elif url.path == "/api/latest":
            self._json(HTTPStatus.OK, self.server.live.latest())
        else:
            self._json(HTTPStatus.NOT_FOUND, {"error": f"no such path: {url.path}"})

    def _json(self, status: HTTPStatus, body: dict[str, Any]) -> None:
        data = json.dumps(body, separators=(",", ":"), allow_nan=False).encode()
        self._send(status, data, "application/json")

    def _send(self, status: HTTPStatus, body: bytes, content_type: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:
        """Requests go to the debug log: the page polls twice a second."""
        logging.getLogger("wallmap.view").debug(format, *args)


class Feed:
    """The Zenoh half: subscribers drained by their own threads, and the periodic map query."""

    def __init__(self, session: zenoh.Session, keys: Keys, live: LiveMap, stats: Stats) -> None:
        self._session = session
        self._keys = keys
        self._live = live
        self._stats = stats
        self._stop = threading.Event()
        # Declared before the first query, so no change falls between the two.
        self._subscribers = [
            session.declare_subscriber(key, zenoh.handlers.FifoChannel(QUEUE_DEPTH))
            for key in (keys.map_updates, keys.pose, keys.observations, keys.map_rooms_updates)
        ]
        handlers: list[Callable[[bytes], None]] = [
            self._update,
            self._pose,
            self._observations,
            self._rooms,
        ]
        self._threads = [
            threading.Thread(target=self._drain, args=(sub.handler, handle), daemon=True)
            for sub, handle in zip(self._subscribers, handlers, strict=True)
        ]
        self._threads.append(threading.Thread(target=self._query_loop, daemon=True))
        for thread in self._threads:
            thread.start()

    def close(self) -> None:
        """Stop the query loop and end the drains by undeclaring their subscribers."""
        self._stop.set()
        for sub in self._subscribers:
            sub.undeclare()
        for thread in self._threads:
            thread.join(timeout=QUERY_TIMEOUT + 1)

    def _drain(self, channel: zenoh.handlers.Handler[zenoh.Sample], handle: Any) -> None:
        for sample in drain(channel):
            try:
                handle(sample.payload.to_bytes())
            except MessageError as err:
                self._stats.refuse(str(sample.key_expr), str(err))

    def _update(self, payload: bytes) -> None:
        self._live.apply_update(MapUpdate.from_map(decode(payload)))

    def _pose(self, payload: bytes) -> None:
        self._live.add_pose(unpack_pose(payload))

    def _observations(self, payload: bytes) -> None:
        self._live.set_observations(unpack_observations(payload))

    def _rooms(self, payload: bytes) -> None:
        body = decode(payload)
        if not isinstance(body, dict):
            raise MessageError("a rooms update is a map")
        self._live.set_rooms(body)

    def _query_loop(self) -> None:
        for reply in self._replies():
            self._live.replace(reply)
            try:
                self._live.set_rooms(fetch_rooms(self._session, self._keys, timeout=QUERY_TIMEOUT))
            except MalformedReplyError as err:
                self._stats.refuse(self._keys.map_rooms, str(err))
            except QueryError:
                pass  # a mapper from before rooms: the walls alone

    def _replies(self) -> Iterator[MapReply]:
        """The whole map now and every REQUERY_PERIOD seconds; the page shows why when not."""
        while not self._stop.is_set():
            try:
                query = MapQuery(tentative=True, trajectory=True)
                reply = fetch_map(self._session, self._keys, query, timeout=QUERY_TIMEOUT)
            except MalformedReplyError as err:
                self._stats.refuse(self._keys.map_walls, str(err))
                self._live.set_status(str(err))
            except QueryError as err:
                self._live.set_status(str(err))
            else:
                self._live.set_status(None)
                yield reply
            self._stop.wait(REQUERY_PERIOD)


def run(_: argparse.Namespace, config: Config) -> int:
    """Serve the page until SIGINT or SIGTERM; the ``func`` of ``wallmap view``."""
    log = setup_logging("view")
    stop = stop_on_signals()
    settings = replace(config.zenoh, wait_for_router=ROUTER_WAIT)
    live = LiveMap()
    # The port first: a port in use fails at once, without waiting for the router.
    with (
        ViewServer(config.view.host, config.view.port, live, load_static()) as httpd,
        open_session(settings) as session,
    ):
        feed = Feed(session, Keys(settings.prefix), live, Stats(log))
        threading.Thread(target=httpd.serve_forever, daemon=True).start()
        print(f"wallmap view: {httpd.url} (map of {settings.prefix!r})", flush=True)
        stop.wait()
        httpd.shutdown()
        feed.close()
    return 0
