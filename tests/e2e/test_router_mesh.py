"""`wallmap router --connect`: a router joins another, and what is on one is reached from the other.

As a fleet runs it: each robot's router joined to the map's. The mapper is on router A; the
map is asked for through router B, started with ``--connect`` A; without the join B reaches
nothing (a query through it finds no mapper, checked first on a B of its own).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import assert_clean_exit, free_port, run_wallmap, wait_for_port

pytestmark = pytest.mark.e2e


def _router(tmp_path: Path, name: str, port: int, *join: str) -> subprocess.Popen:
    log = (tmp_path / f"{name}.log").open("wb")
    connect = [arg for endpoint in join for arg in ("--connect", endpoint)]
    command = ["router", "--listen", f"tcp/127.0.0.1:{port}", *connect]
    proc = subprocess.Popen([sys.executable, "-m", "wallmap", *command], stdout=log, stderr=log)
    wait_for_port(port)
    return proc


def _map_through(port: int, prefix: str) -> subprocess.CompletedProcess[str]:
    return run_wallmap(
        "query",
        "--json",
        "--connect",
        f"tcp/127.0.0.1:{port}",
        "--prefix",
        prefix,
        "--timeout",
        "2",
        expect=None,
    )


def test_a_router_joined_to_another_reaches_its_mapper(tmp_path: Path) -> None:
    a, alone, b = free_port(), free_port(), free_port()
    prefix = "test/mesh"
    procs = {"router-a": _router(tmp_path, "router-a", a)}
    try:
        log = (tmp_path / "mapper.log").open("wb")
        procs["mapper"] = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "wallmap",
                "mapper",
                "--connect",
                f"tcp/127.0.0.1:{a}",
                "--prefix",
                prefix,
            ],
            stdout=log,
            stderr=log,
        )
        deadline = time.monotonic() + 30
        while _map_through(a, prefix).returncode != 0:
            assert time.monotonic() < deadline, (tmp_path / "mapper.log").read_text()
            time.sleep(0.3)
        procs["router-alone"] = _router(tmp_path, "router-alone", alone)
        assert _map_through(alone, prefix).returncode != 0  # a router of its own: no mapper
        procs["router-b"] = _router(tmp_path, "router-b", b, f"tcp/127.0.0.1:{a}")
        deadline = time.monotonic() + 20
        while (through := _map_through(b, prefix)).returncode != 0:
            assert time.monotonic() < deadline, through.stderr
            time.sleep(0.3)
        assert json.loads(through.stdout)["frames"] == 0
        # The router says so once its session is open, which a query through it can beat.
        said = f"joining the routers at tcp/127.0.0.1:{a}"
        deadline = time.monotonic() + 10
        while said not in (tmp_path / "router-b.log").read_text():
            assert time.monotonic() < deadline, (tmp_path / "router-b.log").read_text()
            time.sleep(0.1)
    finally:
        for name, proc in reversed(procs.items()):
            proc.terminate()
            code = proc.wait(timeout=15)
            assert_clean_exit(name, code, (tmp_path / f"{name}.log").read_text())


def test_a_router_told_to_join_itself_says_so_in_one_line() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    out = run_wallmap("router", "--listen", endpoint, "--connect", endpoint, expect=1)
    assert out.stderr.strip() == (
        f"wallmap router: error: a router cannot join itself: --connect {endpoint} is one of its "
        "--listen"
    )


def test_the_link_survives_either_router_restarting(tmp_path: Path) -> None:
    """Router A (the mapper's) restarted: B joins it again; B restarted: it joins A again. The
    map is reached through B each time, within a few seconds (Zenoh retries the link)."""
    a, b = free_port(), free_port()
    prefix = "test/mesh-restart"
    procs = {"router-a": _router(tmp_path, "router-a", a)}
    procs["router-b"] = _router(tmp_path, "router-b", b, f"tcp/127.0.0.1:{a}")
    log = (tmp_path / "mapper.log").open("wb")
    mapper = ["mapper", "--connect", f"tcp/127.0.0.1:{a}", "--prefix", prefix]
    procs["mapper"] = subprocess.Popen(
        [sys.executable, "-m", "wallmap", *mapper], stdout=log, stderr=log
    )

    def reached_through_b(within: float) -> bool:
        deadline = time.monotonic() + within
        while _map_through(b, prefix).returncode != 0:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.3)
        return True

    try:
        assert reached_through_b(30), (tmp_path / "mapper.log").read_text()
        for name, port, join in (("router-a", a, ()), ("router-b", b, (f"tcp/127.0.0.1:{a}",))):
            procs[name].terminate()
            assert_clean_exit(
                name, procs[name].wait(timeout=15), (tmp_path / f"{name}.log").read_text()
            )
            procs[name] = _router(tmp_path, f"{name}-again", port, *join)
            assert reached_through_b(15), f"not reached through router B after {name} restarted"
    finally:
        for name, proc in reversed(procs.items()):
            proc.terminate()
            code = proc.wait(timeout=15)
            logs = sorted(tmp_path.glob(f"{name}*.log"))
            assert_clean_exit(name, code, logs[-1].read_text())


def _namespaces() -> tuple[str, str, str] | None:
    """Two network namespaces joined by a veth pair, as two machines on a link; None if this
    machine does not allow it (not root, no iproute2)."""
    tag = f"wm{os.getpid() % 100000}"
    a, b = f"{tag}a", f"{tag}b"
    steps = [
        ["ip", "netns", "add", a],
        ["ip", "netns", "add", b],
        ["ip", "link", "add", f"{tag}va", "type", "veth", "peer", "name", f"{tag}vb"],
        ["ip", "link", "set", f"{tag}va", "netns", a],
        ["ip", "link", "set", f"{tag}vb", "netns", b],
        ["ip", "-n", a, "addr", "add", "10.77.0.1/24", "dev", f"{tag}va"],
        ["ip", "-n", b, "addr", "add", "10.77.0.2/24", "dev", f"{tag}vb"],
    ]
    devices = ((a, "lo"), (b, "lo"), (a, f"{tag}va"), (b, f"{tag}vb"))
    steps += [["ip", "-n", ns, "link", "set", dev, "up"] for ns, dev in devices]
    for step in steps:
        failed = subprocess.run(step, capture_output=True, check=False).returncode
        if shutil.which(step[0]) is None or failed:
            _drop_namespaces(a, b)
            return None
    return a, b, tag


def _drop_namespaces(*names: str) -> None:
    for name in names:
        subprocess.run(["ip", "netns", "del", name], capture_output=True, check=False)


def test_routers_in_two_network_namespaces_link_as_two_machines(tmp_path: Path) -> None:
    """The mapper and router A in one network namespace (10.77.0.1), router B in another
    (10.77.0.2) joined to A over a veth link; the map asked for inside B's namespace through B."""
    made = _namespaces()
    if made is None:
        pytest.skip("network namespaces need root and iproute2 (ip netns): not available here")
    ns_a, ns_b, _ = made
    prefix = "test/netns"

    def start(name: str, ns: str, *args: str) -> subprocess.Popen:
        log = (tmp_path / f"{name}.log").open("wb")
        command = ["ip", "netns", "exec", ns, sys.executable, "-m", "wallmap", *args]
        return subprocess.Popen(command, stdout=log, stderr=log)

    at_a, at_b = "tcp/10.77.0.1:7447", "tcp/127.0.0.1:7447"
    procs = {
        "router-a": start("router-a", ns_a, "router", "--listen", at_a),
        "router-b": start("router-b", ns_b, "router", "--listen", at_b, "--connect", at_a),
        "mapper": start("mapper", ns_a, "mapper", "--connect", at_a, "--prefix", prefix),
    }
    query = ["ip", "netns", "exec", ns_b, sys.executable, "-m", "wallmap", "query", "--json"]
    query += ["--connect", at_b, "--prefix", prefix, "--timeout", "2"]
    try:
        deadline = time.monotonic() + 40
        while (
            done := subprocess.run(query, capture_output=True, text=True, check=False)
        ).returncode:
            assert time.monotonic() < deadline, done.stderr + (tmp_path / "mapper.log").read_text()
            time.sleep(0.5)
        assert json.loads(done.stdout)["frames"] == 0
    finally:
        for name, proc in reversed(procs.items()):
            proc.terminate()
            code = proc.wait(timeout=15)
            assert_clean_exit(name, code, (tmp_path / f"{name}.log").read_text())
        _drop_namespaces(ns_a, ns_b)
