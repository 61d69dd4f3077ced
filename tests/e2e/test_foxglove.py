"""`wallmap record` and `wallmap foxglove` as processes; without the extra, one line."""

from __future__ import annotations

import base64
import json
import os
import re
import socket
import struct
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from conftest import Service, Stack, free_port, wait_for_port
from foxglove_wire import decode, descriptor_types, one, stamp_ns

from wallmap.scene import write_scene_bag

RECORD = [sys.executable, "-m", "wallmap"]
SCHEMAS = {
    "/wallmap/walls": "foxglove.SceneUpdate",
    "/wallmap/pose": "foxglove.PoseInFrame",
    "/tf": "foxglove.FrameTransforms",
    "/wallmap/observations": "foxglove.SceneUpdate",
    "/wallmap/trajectory": "foxglove.PosesInFrame",
    "/wallmap/rooms": "foxglove.SceneUpdate",
}


def _without_foxglove(*argv: str) -> subprocess.CompletedProcess[str]:
    code = (
        "import sys; sys.modules['foxglove'] = None\n"  # as if foxglove-sdk were not installed
        "from wallmap.cli import main\n"
        "sys.exit(main(sys.argv[1:]))"
    )
    return subprocess.run(
        [sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=60, check=False
    )


def test_without_the_extra_the_commands_fail_in_one_line(tmp_path: Path) -> None:
    for command in (["record", str(tmp_path / "out.mcap")], ["foxglove"]):
        out = _without_foxglove(*command)
        assert out.returncode == 1
        assert out.stderr == (
            f"wallmap {command[0]}: error: the foxglove extra is not installed: "
            "pip install 'wallmap[foxglove]'\n"
        )
    assert not (tmp_path / "out.mcap").exists()
    out = _without_foxglove("record", "--help")
    assert out.returncode == 0
    assert "--until-idle" in out.stdout


def _ws_connect(port: int) -> socket.socket:
    """A WebSocket client handshake with the SDK's subprotocol, by hand."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
        "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n".encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)
    assert head.startswith(b"HTTP/1.1 101"), head
    return sock


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        assert chunk, "the server closed the connection"
        data += chunk
    return data


def _ws_recv(sock: socket.socket) -> tuple[int, bytes]:
    """One unfragmented frame from the server: (opcode, payload)."""
    first, second = _recv_exact(sock, 2)
    n = second & 0x7F
    if n == 126:
        n = struct.unpack(">H", _recv_exact(sock, 2))[0]
    elif n == 127:
        n = struct.unpack(">Q", _recv_exact(sock, 8))[0]
    return first & 0x0F, _recv_exact(sock, n)


def _ws_send_text(sock: socket.socket, text: str) -> None:
    data = text.encode()
    mask = os.urandom(4)
    assert len(data) < 126
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
    sock.sendall(bytes([0x81, 0x80 | len(data)]) + mask + masked)


def _ws_json(sock: socket.socket, op: str) -> dict[str, Any]:
    while True:
        kind, payload = _ws_recv(sock)
        if kind == 1 and (message := json.loads(payload))["op"] == op:
            return message


@pytest.mark.e2e
def test_record_a_playback_then_serve_the_map_live(stack: Stack, tmp_path: Path) -> None:
    pytest.importorskip("foxglove")
    reader = pytest.importorskip("mcap.reader")
    bag = tmp_path / "s.bag"
    write_scene_bag(bag, seed=11, n_frames=120, fmt="ros1", sensor="depth16")
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    out = tmp_path / "run.mcap"
    log = tmp_path / "record.log"
    record = subprocess.Popen(
        [*RECORD, "record", str(out), "--until-idle", "3", *stack.zenoh_args],
        stdout=subprocess.PIPE,
        stderr=log.open("wb"),
        text=True,
    )
    stack.services.append(Service("record", record, log))
    # The recorder's liveliness token lets the player wait for it too.
    played = stack.run(
        "player", str(bag), "--fast", "--wait-for", "detector,mapper,record", *stack.zenoh_args
    )
    assert played.returncode == 0, played.stderr
    stdout, _ = record.communicate(timeout=30)
    assert record.returncode == 0, log.read_text()
    served = stack.query()["walls"]
    walls = stack.query("--tentative")["walls"]  # the map updates carry the tentative walls too

    poses = int(re.search(r"and (\d+) poses", played.stdout)[1])
    assert poses >= 120, "each frame's pose, and the stream ahead of the frames"
    assert stdout.startswith(f"wrote {out}: ")
    assert f"/wallmap/pose {poses}" in stdout

    with out.open("rb") as f:
        mcap = reader.make_reader(f)
        summary = mcap.get_summary()
        topics = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        assert set(topics) == set(SCHEMAS) - {"/wallmap/trajectory"}  # no path before the run
        for topic, schema in topics.items():
            assert (schema.name, schema.encoding) == (SCHEMAS[topic], "protobuf")
        types = {name: descriptor_types(schema.data) for name, schema in topics.items()}
        messages: dict[str, list[tuple[int, dict[str, list[Any]]]]] = defaultdict(list)
        for schema, channel, message in mcap.iter_messages(log_time_order=False):
            decoded = decode(message.data, schema.name, types[channel.topic])
            messages[channel.topic].append((message.log_time, decoded))

    assert len(messages["/wallmap/pose"]) == poses  # each one the player sent
    assert len(messages["/tf"]) == poses
    assert len(messages["/wallmap/observations"]) == 120  # one per frame
    for topic, logged in messages.items():
        times = [t for t, _ in logged]
        if topic not in ("/wallmap/pose", "/tf"):
            # Written as they come, in the order of their stamps; a player sends each frame's own
            # pose after the poses ahead of it (MCAP's index orders them by log time).
            assert times == sorted(times), topic
        if topic not in ("/wallmap/walls", "/wallmap/rooms"):
            assert len(set(times)) == len(times), topic  # ...one per stamp
    pose_time, pose = messages["/wallmap/pose"][-1]
    assert stamp_ns(pose) == pose_time  # log time = the message's stamp
    _, last = messages["/wallmap/walls"][-1]
    ids = {one(e, "id") for e in last["entities"]}
    assert ids == {f"wall/{w['id']}" for w in walls}
    confirmed = {
        one(e, "id")
        for e in last["entities"]
        if {"key": ["tentative"], "value": ["false"]} in e["metadata"]
    }
    assert confirmed == {f"wall/{w['id']}" for w in served}
    rooms = stack.query("--rooms")  # the rooms the mapper serves, as the last update drew them
    _, last_rooms = messages["/wallmap/rooms"][-1]
    assert rooms["rooms"], "a room in 120 frames of a three-room scene"
    assert {one(e, "id") for e in last_rooms["entities"]} == {
        *(f"room/{r['id']}" for r in rooms["rooms"]),
        *(f"door/{d['id']}" for d in rooms["doors"]),
    }

    # The same map, live. The first viewer gets it from the server's first query (or from the
    # resend, if it subscribes after that); the second, long after, only from the resend.
    port = free_port()
    log = tmp_path / "foxglove.log"
    live = subprocess.Popen(
        [*RECORD, "foxglove", "--port", str(port), *stack.zenoh_args],
        stdout=subprocess.DEVNULL,
        stderr=log.open("wb"),
    )
    stack.services.append(Service("foxglove", live, log))
    wait_for_port(port)
    for _viewer in range(2):
        with _ws_connect(port) as sock:
            assert _ws_json(sock, "serverInfo")["name"] == "wallmap"
            advertised: dict[str, dict[str, Any]] = {}
            while set(advertised) != set(SCHEMAS):
                advertised |= {c["topic"]: c for c in _ws_json(sock, "advertise")["channels"]}
            assert {t: c["schemaName"] for t, c in advertised.items()} == SCHEMAS
            subscribe = {"id": 7, "channelId": advertised["/wallmap/walls"]["id"]}
            _ws_send_text(sock, json.dumps({"op": "subscribe", "subscriptions": [subscribe]}))
            while (frame := _ws_recv(sock))[0] != 2:  # binary: message data
                pass
            opcode, subscription, log_time = struct.unpack_from("<BIQ", frame[1])
            assert (opcode, subscription) == (1, 7)
            scene = decode(frame[1][13:], "foxglove.SceneUpdate", types["/wallmap/walls"])
            assert {one(e, "id") for e in scene["entities"]} == ids
            assert log_time == messages["/wallmap/walls"][-1][0]
    live.terminate()
    assert live.wait(timeout=15) == 0
    assert "Callback failed" not in log.read_text()  # the listener answers every callback
