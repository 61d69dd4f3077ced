"""The ROS 2 Humble typestore, loaded on first use.

rosbags builds its typestores at import, a tenth of a second and more: every `wallmap` process
would pay it, though only a ROS 2 link (CDR poses in, markers out) or a bag without type
definitions needs one.
"""

from __future__ import annotations

import functools
from typing import Any

from wallmap.common.codec import MessageError


@functools.cache
def ros2_typestore() -> Any:
    """The typestore ROS 2 messages are encoded and decoded with (Humble's definitions)."""
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415 - see the module

    return get_typestore(Stores.ROS2_HUMBLE)


def deserialize_cdr(payload: bytes, msgtype: str) -> Any:
    """A ROS 2 message from its CDR bytes; MessageError says why bytes are not one."""
    try:
        return ros2_typestore().deserialize_cdr(payload, msgtype)
    except Exception as err:  # the CDR decoder raises many types for bad bytes
        msg = f"not a CDR {msgtype} ({type(err).__name__}: {err})"
        raise MessageError(msg) from err
