"""``wallmap view``: the live wall map as a page on localhost (see docs/view.md)."""

import argparse
from typing import Any

from wallmap.config import Config
from wallmap.options import VIEW, ZENOH
from wallmap.options import add_command as add_options_command


def add_command(sub: Any) -> None:
    """Add ``view`` to the ``wallmap`` command's subparsers (``sub`` from add_subparsers)."""
    add_options_command(
        sub, "view", "a live map page on localhost (pan, zoom, hover a wall)", _run, VIEW, ZENOH
    )


def _run(args: argparse.Namespace, config: Config) -> int:
    """The server, imported when the page is asked for: every wallmap command builds this parser."""
    from wallmap.view.server import run  # noqa: PLC0415 - see the docstring

    return run(args, config)


__all__ = ["add_command"]
