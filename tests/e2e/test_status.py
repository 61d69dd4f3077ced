"""`wallmap status`: the live services under a prefix and their counters, as a table or JSON."""

from __future__ import annotations

import json
import time

import pytest

from wallmap.scene import write_scene_bag

pytestmark = pytest.mark.e2e


def test_status_lists_live_services_and_their_counters(stack, tmp_path) -> None:
    empty = stack.run("status", *stack.zenoh_args, timeout=30)
    assert empty.returncode == 0, empty.stderr
    assert "no wallmap service is live under prefix" in empty.stdout
    bag = tmp_path / "s.bag"
    write_scene_bag(bag, seed=11, n_frames=40, fmt="ros1", sensor="depth16")
    for service in ("mapper", "detector"):
        stack.start(service, service, *stack.zenoh_args)
    played = stack.run("player", str(bag), "--fast", *stack.zenoh_args)
    assert played.returncode == 0, played.stderr
    deadline = time.monotonic() + 20
    while True:
        out = stack.run("status", "--json", *stack.zenoh_args, timeout=30)
        assert out.returncode == 0, out.stderr
        services = {s["service"]: s for s in json.loads(out.stdout)}
        if {"mapper", "detector"} <= set(services) or time.monotonic() > deadline:
            break
    assert services["detector"]["counters"]["received"] == 40
    assert services["detector"]["counters"]["published"] == 40
    assert services["mapper"]["counters"]["integrated"] == 40
    assert services["mapper"]["uptime"] > 0
    table = stack.run("status", *stack.zenoh_args, timeout=30).stdout
    assert table.splitlines()[0].split() == ["service", "uptime", "counters"]
    assert any(line.startswith("detector") and "received 40" in line for line in table.splitlines())
