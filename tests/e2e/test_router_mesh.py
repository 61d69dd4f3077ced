"""`wallmap router --connect`: a router joins another, and what is on one is reached from the other.

As a fleet runs it: each robot's router joined to the map's. The mapper is on router A; the
map is asked for through router B, started with ``--connect`` A; without the join B reaches
nothing (a query through it finds no mapper, checked first on a B of its own).
"""

from __future__ import annotations

import json
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
    return run_wallmap("query", "--json", "--connect", f"tcp/127.0.0.1:{port}", "--prefix",
                       prefix, "--timeout", "2", expect=None)  # fmt: skip


def test_a_router_joined_to_another_reaches_its_mapper(tmp_path: Path) -> None:
    a, alone, b = free_port(), free_port(), free_port()
    prefix = "test/mesh"
    procs = {"router-a": _router(tmp_path, "router-a", a)}
    try:
        log = (tmp_path / "mapper.log").open("wb")
        procs["mapper"] = subprocess.Popen(
            [sys.executable, "-m", "wallmap", "mapper", "--connect", f"tcp/127.0.0.1:{a}",
             "--prefix", prefix], stdout=log, stderr=log,
        )  # fmt: skip
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
