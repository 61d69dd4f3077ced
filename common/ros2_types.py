"""The ROS 2 Humble typestore, loaded on first use.

rosbags builds its typestores at import, a tenth of a second and more: every `wallmap` process
would pay it, though only a ROS 2 link (CDR poses in, markers out) or a bag without type
definitions needs one.
"""

from __future__ import annotations

import functools
from typing import Any


@functools.cache
def ros2_typestore() -> Any:
    """The typestore ROS 2 messages are encoded and decoded with (Humble's definitions)."""
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415 - see the module

    return get_typestore(Stores.ROS2_HUMBLE)
