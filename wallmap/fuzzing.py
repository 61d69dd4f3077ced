"""Mutation fuzzing of every decoder a service runs on received bytes.

Used by the tests and ``benchmarks/fuzz.py``; it lives beside the commands, not in ``common/``,
because it reaches into the services for their decoders.
Each decoder gets valid messages broken in the ways networks and people break them: random bytes,
truncation, flipped bytes, fields of the wrong type, NaN and infinities, empty and absurdly large
arrays. A decoder may accept a message or refuse it with the error its service catches (and
counts); anything else is a crash, which would take a service's worker thread down.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import msgpack
import numpy as np
from rosbags.typesys import Stores, get_typestore

from wallmap.common.codec import MessageError, decode
from wallmap.common.map_records import MapReply, MapUpdate, WallRecord
from wallmap.common.messages import (
    Frame,
    Observations,
    Pose,
    Progress,
    WallObservation,
    pack,
    unpack_frame,
    unpack_observations,
    unpack_pose,
    unpack_progress,
)
from wallmap.common.scan_row import RowSelection
from wallmap.services.mapper.pose_input import make_pose_input
from wallmap.services.odometry.tracker import PoseTracker

Decoder = Callable[[bytes], object]
_ODD_VALUES: list[Any] = [
    None,
    True,
    -1,
    2**64 - 1,
    -(2**63),
    math.nan,
    math.inf,
    -math.inf,
    1e308,
    "",
    "x" * 300,
    b"\x00\xff",
    [],
    {},
    [1.0] * 1000,
    {"__nd__": ["<f4", [2**40, 2**40], b""]},
    {"__nd__": ["<f4", [0, 3], b""]},
    {"__nd__": ["|O", [1], b"\x00" * 8]},
    {"__nd__": ["<f8", [3, 3], np.full(9, np.nan).tobytes()]},
]


@dataclass
class Outcome:
    """What one decoder did with the fuzzed messages."""

    messages: int = 0
    accepted: int = 0
    refused: int = 0
    crashes: Counter[str] = field(default_factory=Counter)


def _cdr_samples() -> dict[str, tuple[bytes, Decoder]]:
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](sec=5, nanosec=0)
    header = types["std_msgs/msg/Header"](stamp=stamp, frame_id="map")
    point = types["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0)
    rotation = types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    pose = types["geometry_msgs/msg/Pose"](position=point, orientation=rotation)
    with_cov = types["geometry_msgs/msg/PoseWithCovariance"](
        pose=pose, covariance=np.eye(6).ravel() * 0.01
    )
    twist = types["geometry_msgs/msg/TwistWithCovariance"](
        twist=types["geometry_msgs/msg/Twist"](
            linear=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            angular=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        ),
        covariance=np.zeros(36),
    )
    transform = types["geometry_msgs/msg/TransformStamped"](
        header=header,
        child_frame_id="base_link",
        transform=types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](x=1.0, y=0.0, z=0.0),
            rotation=rotation,
        ),
    )
    messages = {
        "nav_msgs/msg/Odometry": types["nav_msgs/msg/Odometry"](
            header=header, child_frame_id="base_link", pose=with_cov, twist=twist
        ),
        "geometry_msgs/msg/PoseStamped": types["geometry_msgs/msg/PoseStamped"](
            header=header, pose=pose
        ),
        "geometry_msgs/msg/PoseWithCovarianceStamped": types[
            "geometry_msgs/msg/PoseWithCovarianceStamped"
        ](header=header, pose=with_cov),
        "tf2_msgs/msg/TFMessage": types["tf2_msgs/msg/TFMessage"](transforms=[transform]),
    }
    out = {}
    for msgtype, message in messages.items():
        decoder = make_pose_input(f"ros2:{msgtype}")
        out[f"ros2 {msgtype}"] = (
            bytes(store.serialize_cdr(message, msgtype)),
            lambda b, d=decoder: d.decode(b, "tf"),
        )
    return out


def samples() -> dict[str, tuple[bytes, Decoder]]:
    """Per decoder: a valid message and the decoder."""
    tracker = PoseTracker()
    cov = np.eye(2) * 1e-4
    ends = np.array([2.0, -1.0]), np.array([2.0, 1.0])
    wall = WallObservation(np.array([2.0, 0.1]), cov, *ends, 40, 0.01)
    points = np.random.default_rng(0).normal(size=(2, 8, 3)).astype(np.float32)
    record = WallRecord(
        1,
        0.0,
        2.0,
        ((1e-4, 0.0), (0.0, 1e-4)),
        (0.0, 2.0),
        (4.0, 2.0),
        (((0.0, 2.0), (4.0, 2.0)),),
        9,
        3,
        False,
        0.5,
        1.0,
    )
    update = {"v": 1, **MapUpdate(3, 1.0, (record,), (4,)).to_map()}
    reply = {
        "v": 1,
        **MapReply(frames=3, walls=(record,), trajectory=((1.0, 0.0, 0.0, 0.1),)).to_map(),
    }
    out = {
        "pose": (pack(Pose(1.0, 1.0, 2.0, 0.3, np.eye(3) * 0.01)), unpack_pose),
        "frame": (pack(Frame("r", 3, 1.0, "cam", points, np.eye(4))), unpack_frame),
        "observations": (
            pack(Observations("r", 3, 1.0, "base_link", [wall, wall])),
            unpack_observations,
        ),
        "progress": (pack(Progress("r", 3, 2, 1, "e")), unpack_progress),
        "row selection": (
            msgpack.packb({"v": 1, **RowSelection().to_map()}),
            lambda b: RowSelection.from_map(decode(b)),
        ),
        "map update (odometry)": (msgpack.packb(update), tracker.take_update),
        "map reply": (msgpack.packb(reply), lambda b: MapReply.from_map(decode(b))),
    }
    out.update(_cdr_samples())
    return out


def mutate(valid: bytes, rng: np.random.Generator) -> bytes:
    """One broken variant of a valid message."""
    kind = rng.integers(0, 5)
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 512)))
    if kind == 1:
        return valid[: int(rng.integers(0, len(valid)))]
    if kind == 2:
        data = bytearray(valid)
        for _ in range(int(rng.integers(1, 9))):
            data[int(rng.integers(0, len(data)))] = int(rng.integers(0, 256))
        return bytes(data)
    try:  # structural: a field of the wrong type, or a nested field
        message = msgpack.unpackb(valid, raw=False, strict_map_key=False)
    except Exception:  # CDR bytes are not msgpack: flip them instead
        return mutate(valid, rng) if kind != 4 else rng.bytes(64)
    if not isinstance(message, dict) or not message:
        return rng.bytes(32)
    keys = list(message)
    target = keys[int(rng.integers(0, len(keys)))]
    value = _ODD_VALUES[int(rng.integers(0, len(_ODD_VALUES)))]
    if kind == 4 and isinstance(message[target], list) and message[target]:
        inner = message[target][0]
        if isinstance(inner, dict) and inner:
            inner_keys = list(inner)
            inner[inner_keys[int(rng.integers(0, len(inner_keys)))]] = value
    else:
        message[target] = value
    return msgpack.packb(message, use_bin_type=True)


def fuzz(messages: int, seed: int = 0) -> dict[str, Outcome]:
    """Fuzz every decoder with ``messages`` broken messages in all, shared out evenly."""
    rng = np.random.default_rng(seed)
    targets = samples()
    outcomes = {name: Outcome() for name in targets}
    per = max(1, messages // len(targets))
    for name, (valid, decoder) in targets.items():
        outcome = outcomes[name]
        for _ in range(per):
            payload = mutate(valid, rng)
            outcome.messages += 1
            try:
                decoder(payload)
            except MessageError:  # the refusal the services catch, count and log
                outcome.refused += 1
            except Exception as err:  # what the fuzzer is there to find
                outcome.crashes[f"{type(err).__name__}: {str(err)[:80]}"] += 1
            else:
                outcome.accepted += 1
    return outcomes
