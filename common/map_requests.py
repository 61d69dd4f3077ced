"""Asking a mapper (or a fleet's merge service) for its map over Zenoh, and answering.

The client side (``fetch_map``, ``fetch_rooms``) writes a ``MapQuery`` as selector parameters
and checks what comes back; the server side (``answer_map_queries``) reads them with the same
``MapQuery``, so the two cannot drift apart.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar

import zenoh

from wallmap.common.codec import MessageError, decode
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply
from wallmap.common.runtime import drain
from wallmap.common.transport import Keys

T = TypeVar("T")

ASK_AGAIN = 0.2  # s between two asks while no mapper is up (``ask_mapper``'s ``wait``)


class QueryError(RuntimeError):
    """No usable map came back; the message says why, in one line."""


class MalformedReplyError(QueryError):
    """A mapper answered with a reply that does not decode: refused, and counted by callers."""


def fetch_map(
    session: zenoh.Session,
    keys: Keys,
    query: MapQuery | None = None,
    *,
    timeout: float = 5.0,
    wait: bool = False,
) -> MapReply:
    """Ask ``{prefix}/map/walls`` for the walls ``query`` selects; the reply, checked.

    ``wait``: ask until a mapper answers, for up to ``timeout`` (``ask_mapper``).

    Raises:
        QueryError: no mapper answered, it refused the query, or its reply is unreadable.
    """
    params = (query or MapQuery()).to_parameters()
    selector = keys.map_walls + (
        "?" + ";".join(f"{k}={v}" for k, v in params.items()) if params else ""
    )
    return ask_mapper(session, selector, "map", MapReply.from_map, timeout, wait=wait)


def ask_mapper(
    session: zenoh.Session,
    selector: str,
    what: str,
    read: Callable[[Any], T],
    timeout: float,
    *,
    wait: bool = False,
) -> T:
    """The first reply to ``selector``, decoded and ``read``; ``what`` names it in errors.

    With no mapper up, Zenoh ends a query at once. ``wait``: ask again every ``ASK_AGAIN`` s
    until one answers or ``timeout`` is up (a command run just after ``wallmap mapper &``, a
    mapper restarting); else once (a service's periodic poll, which asks again anyway).

    Raises:
        QueryError: no mapper answered, or it refused the query.
        MalformedReplyError: the reply does not decode, or ``read`` refuses it (MessageError).
    """
    deadline = time.monotonic() + timeout
    while True:
        left = max(deadline - time.monotonic(), 0.01)
        for reply in session.get(selector, timeout=left):
            if reply.ok is None:
                msg = f"the mapper refused the query: {reply.err.payload.to_string()}"
                raise QueryError(msg)
            try:
                return read(decode(reply.ok.payload.to_bytes()))
            except MessageError as err:
                msg = f"the {what} reply is unreadable: {err}"
                raise MalformedReplyError(msg) from err
        if not wait or time.monotonic() + ASK_AGAIN >= deadline:
            break
        time.sleep(ASK_AGAIN)
    msg = f"no mapper answered on {selector.split('?', maxsplit=1)[0]} within {timeout:.0f} s"
    raise QueryError(msg)


def fetch_rooms(
    session: zenoh.Session, keys: Keys, *, timeout: float = 5.0, wait: bool = False
) -> dict[str, Any]:
    """Ask ``{prefix}/map/rooms``; the contract's payload, checked for its two lists.

    ``wait``: ask until a mapper answers, for up to ``timeout`` (``ask_mapper``).

    Raises:
        QueryError: no mapper answered, it refused, or its reply is unreadable.
    """
    return ask_mapper(session, keys.map_rooms, "rooms", _rooms_body, timeout, wait=wait)


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
            if not reply_in_format(query, lambda fmt, selection=selection: reply(selection, fmt)):
                continue
        count("queries")


def reply_in_format(query: zenoh.Query, payload: Callable[[str], bytes]) -> bool:
    """Answer with ``payload(format)`` in the format asked for; whether it was answered.

    ``format=msgpack`` (the default) or ``format=json`` (with Zenoh's JSON encoding); another is
    refused with the reason. Every queryable of the map (walls, rooms, a fleet's robots)
    answers alike.
    """
    fmt = query.parameters.get("format") or "msgpack"
    if fmt not in ("msgpack", "json"):
        query.reply_err(f"format must be msgpack or json, got {fmt!r}")
        return False
    if fmt == "json":
        query.reply(query.key_expr, payload(fmt), encoding=zenoh.Encoding.APPLICATION_JSON)
    else:
        query.reply(query.key_expr, payload(fmt))
    return True
