"""The rows a detector searches, asked of it, so a source sends only those (player, ros2)."""

from __future__ import annotations

import zenoh

from wallmap.common.codec import MessageError, decode
from wallmap.common.scan_row import RowSelection
from wallmap.common.transport import Keys


def ask_rows(session: zenoh.Session, keys: Keys) -> RowSelection | None:
    """The detector's row selection, or None (send whole clouds) when no detector answers."""
    for reply in session.get(keys.detector_rows, timeout=2.0):
        if reply.ok is not None:
            try:
                return RowSelection.from_map(decode(reply.ok.payload.to_bytes()))
            except MessageError:
                return None
    return None
