"""Both ends of ``{prefix}/map/walls``: which walls a query asks for, and asking.

A query's selector parameters (``min_obs``, ``tentative``, ``bbox``, ``since``, ``trajectory``,
``format``) are parsed and checked here for the mapper (``MapQuery.from_parameters``), and
written here for clients (``MapQuery.to_selector``, ``fetch_map``), so the two cannot drift
apart. A wrong parameter is refused with a reply that says which one and why.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import zenoh

from wallmap.common.codec import MessageError, decode
from wallmap.common.map_records import MapReply
from wallmap.common.runtime import drain
from wallmap.common.transport import Keys

T = TypeVar("T")


@dataclass(frozen=True)
class MapQuery:
    """Which walls a reply holds: the selector parameters of ``{prefix}/map/walls``.

    Attributes:
        min_obs: walls seen at least this many times.
        tentative: also walls not yet confirmed (possible phantoms).
        bbox: (xmin, ymin, xmax, ymax): walls whose extent crosses this box.
        since: walls seen at or after this stamp.
        trajectory: add the keyframe trajectory.
    """

    min_obs: int = 1
    tentative: bool = False
    bbox: tuple[float, float, float, float] | None = None
    since: float | None = None
    trajectory: bool = False

    @classmethod
    def from_parameters(cls, params: Mapping[str, str]) -> MapQuery:
        """Parse selector parameters; ValueError says which one is wrong and why."""
        unknown = set(params) - {"min_obs", "tentative", "bbox", "since", "trajectory", "format"}
        if unknown:
            msg = f"unknown parameter {sorted(unknown)[0]!r}"
            raise ValueError(msg)
        try:
            min_obs = int(params.get("min_obs") or 1)
        except ValueError:
            msg = f"min_obs must be an integer, got {params.get('min_obs')!r}"
            raise ValueError(msg) from None
        bbox = None
        if params.get("bbox"):
            try:
                xmin, ymin, xmax, ymax = (float(v) for v in params["bbox"].split(","))
            except ValueError:
                msg = f"bbox must be xmin,ymin,xmax,ymax in metres, got {params['bbox']!r}"
                raise ValueError(msg) from None
            if not (xmin <= xmax and ymin <= ymax):
                msg = f"bbox must have xmin <= xmax and ymin <= ymax, got {params['bbox']!r}"
                raise ValueError(msg)
            bbox = (xmin, ymin, xmax, ymax)
        since = None
        if params.get("since"):
            try:
                since = float(params["since"])
            except ValueError:
                msg = f"since must be a stamp in seconds, got {params['since']!r}"
                raise ValueError(msg) from None
        flags = {}
        for name in ("tentative", "trajectory"):
            value = params.get(name, "false")
            if value not in ("true", "false"):
                msg = f"{name} must be true or false, got {value!r}"
                raise ValueError(msg)
            flags[name] = value == "true"
        return cls(min_obs, flags["tentative"], bbox, since, flags["trajectory"])

    def to_parameters(self) -> dict[str, str]:
        """The selector parameters that ask for this selection (defaults left out)."""
        params: dict[str, str] = {}
        if self.min_obs != 1:
            params["min_obs"] = str(self.min_obs)
        if self.tentative:
            params["tentative"] = "true"
        if self.bbox is not None:
            params["bbox"] = ",".join(repr(v) for v in self.bbox)
        if self.since is not None:
            params["since"] = repr(self.since)
        if self.trajectory:
            params["trajectory"] = "true"
        return params


class QueryError(RuntimeError):
    """No usable map came back; the message says why, in one line."""


class MalformedReplyError(QueryError):
    """A mapper answered with a reply that does not decode: refused, and counted by callers."""


def fetch_map(
    session: zenoh.Session, keys: Keys, query: MapQuery | None = None, *, timeout: float = 5.0
) -> MapReply:
    """Ask ``{prefix}/map/walls`` for the walls ``query`` selects; the reply, checked.

    Raises:
        QueryError: no mapper answered, it refused the query, or its reply is unreadable.
    """
    params = (query or MapQuery()).to_parameters()
    selector = keys.map_walls + (
        "?" + ";".join(f"{k}={v}" for k, v in params.items()) if params else ""
    )
    return ask_mapper(session, selector, "map", MapReply.from_map, timeout)


def ask_mapper(
    session: zenoh.Session, selector: str, what: str, read: Callable[[Any], T], timeout: float
) -> T:
    """The first reply to ``selector``, decoded and ``read``; ``what`` names it in errors.

    Raises:
        QueryError: no mapper answered, or it refused the query.
        MalformedReplyError: the reply does not decode, or ``read`` refuses it (MessageError).
    """
    for reply in session.get(selector, timeout=timeout):
        if reply.ok is None:
            msg = f"the mapper refused the query: {reply.err.payload.to_string()}"
            raise QueryError(msg)
        try:
            return read(decode(reply.ok.payload.to_bytes()))
        except MessageError as err:
            msg = f"the {what} reply is unreadable: {err}"
            raise MalformedReplyError(msg) from err
    msg = f"no mapper answered on {selector.split('?', maxsplit=1)[0]} within {timeout:.0f} s"
    raise QueryError(msg)


def fetch_rooms(session: zenoh.Session, keys: Keys, *, timeout: float = 5.0) -> dict[str, Any]:
    """Ask ``{prefix}/map/rooms``; the contract's payload, checked for its two lists.

    Raises:
        QueryError: no mapper answered, it refused, or its reply is unreadable.
    """
    return ask_mapper(session, keys.map_rooms, "rooms", _rooms_body, timeout)


def _rooms_body(body: Any) -> dict[str, Any]:
    """The rooms reply, if it holds the contract's two lists; MessageError if not."""
    if not isinstance(body, dict) or not all(
        isinstance(body.get(k), list) for k in ("rooms", "doors")
    ):
        raise MessageError("it has no 'rooms' and 'doors' lists")
    return body


def answer_map_queries(
    channel: zenoh.handlers.Handler[zenoh.Query],
    reply: Callable[[MapQuery, str], bytes],
    count: Callable[[str], None],
) -> None:
    """Answer ``{prefix}/map/walls`` queries from a channel until it is undeclared.

    The selector is checked (a bad one is refused with the reason), ``reply(selection, format)``
    gives the encoded payload, msgpack or JSON; ``count("queries")`` after each. The mapper and a
    fleet's merge service answer alike.
    """
    for query in drain(channel):
        with query:
            params = dict(query.parameters)
            try:
                selection = MapQuery.from_parameters(params)
            except ValueError as err:
                query.reply_err(str(err))
                continue
            fmt = params.get("format") or "msgpack"
            if fmt not in ("msgpack", "json"):
                query.reply_err(f"format must be msgpack or json, got {fmt!r}")
                continue
            if fmt == "json":
                encoding = zenoh.Encoding.APPLICATION_JSON
                query.reply(query.key_expr, reply(selection, fmt), encoding=encoding)
            else:
                query.reply(query.key_expr, reply(selection, fmt))
        count("queries")
