"""``wallmap view``: the live wall map as a page on localhost (see docs/view.md)."""

from wallmap.view.server import add_command

__all__ = ["add_command"]
