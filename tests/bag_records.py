"""Writing test bags from plain records: one topic, type, message and receive time each."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys.store import Typestore


@dataclass
class Record:
    topic: str
    msgtype: str
    msg: Any
    receive: float  # seconds


def write_records(
    path: Path,
    store: Typestore,
    records: list[Record],
    plugin: StoragePlugin | None = None,
    compression: Writer1.CompressionFormat | None = None,
) -> Path:
    """Write records (in the given order) to a ROS 1 bag, or a ROS 2 bag with ``plugin``.

    ``compression``: a ROS 1 bag's chunks compressed so (uncompressed by default).
    """
    if plugin is None:
        writer: Writer1 | Writer2 = Writer1(path)
        if compression is not None:
            writer.set_compression(compression)
        serialize = store.serialize_ros1
    else:
        writer = Writer2(path, version=9, storage_plugin=plugin)
        serialize = store.serialize_cdr
    connections: dict[str, Any] = {}
    with writer:
        for record in records:
            if record.topic not in connections:
                connections[record.topic] = writer.add_connection(
                    record.topic, record.msgtype, typestore=store
                )
            data = serialize(record.msg, record.msgtype)
            writer.write(connections[record.topic], int(record.receive * 1e9), data)
    return path
