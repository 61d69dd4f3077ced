"""Shared fixtures: a real Zenoh router on a free loopback port, services as real processes."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for_port(port: int, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on port {port}")


def run_wallmap(*args: str, timeout: float = 120.0, **kwargs) -> subprocess.CompletedProcess[str]:
    """Run one wallmap command to its end, capturing its output as text."""
    return subprocess.run(
        [sys.executable, "-m", "wallmap", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        **kwargs,
    )


@dataclass
class Service:
    """A running wallmap process and its log file."""

    name: str
    proc: subprocess.Popen[bytes]
    log: Path

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def stop(self, timeout: float = 15.0) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode


class Stack:
    """Starts wallmap processes against one router and stops them all at the end."""

    def __init__(self, tmp_path: Path, endpoint: str, prefix: str) -> None:
        self.tmp_path = tmp_path
        self.endpoint = endpoint
        self.prefix = prefix
        self.services: list[Service] = []

    @property
    def zenoh_args(self) -> list[str]:
        return ["--connect", self.endpoint, "--prefix", self.prefix]

    def start(self, name: str, *args: str, env: dict[str, str] | None = None) -> Service:
        log = self.tmp_path / f"{name}.log"
        proc = subprocess.Popen(
            [sys.executable, "-m", "wallmap", *args],
            stdout=log.open("wb"),
            stderr=subprocess.STDOUT,
            env={**os.environ, **(env or {})},
        )
        service = Service(name, proc, log)
        self.services.append(service)
        return service

    def run(self, *args: str, timeout: float = 300.0) -> subprocess.CompletedProcess[str]:
        return run_wallmap(*args, timeout=timeout)

    def query(self, *extra: str) -> dict:
        out = self.run("query", "--json", *extra, *self.zenoh_args, timeout=30)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)

    def counters(self, service: str) -> dict:
        """A running service's counters, as `wallmap status --json` reads them."""
        out = self.run("status", "--json", *self.zenoh_args, timeout=30)
        assert out.returncode == 0, out.stderr
        return next(s["counters"] for s in json.loads(out.stdout) if s["service"] == service)

    def settled_frames(self, n_frames: int, *query: str) -> tuple[dict, int]:
        """The map once every frame is integrated or counted as skipped by the detector.

        In real-time playback a detector that falls behind (a busy machine) skips to the newest
        frame and counts what it skipped; --fast loses none. Returns the reply and the skips.
        """
        deadline = time.monotonic() + 10
        while True:
            skipped = self.counters("detector").get("dropped", 0)
            reply = self.query(*query)
            if reply["frames"] + skipped >= n_frames or time.monotonic() > deadline:
                return reply, skipped

    def stop_all(self) -> None:
        for service in reversed(self.services):
            service.stop()


@pytest.fixture
def stack(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Stack]:
    """A router on a free loopback port (multicast off); more services via ``stack.start``."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    s = Stack(tmp_path, endpoint, prefix=f"test/{request.node.name[:40]}")
    s.start("router", "router", "--listen", endpoint)
    wait_for_port(port)
    try:
        yield s
    finally:
        s.stop_all()
        for service in s.services:
            if service.proc.returncode not in (0, -15):
                print(
                    f"--- {service.name} (exit {service.proc.returncode}) ---\n{service.output()}"
                )
