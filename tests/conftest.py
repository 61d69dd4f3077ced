"""Shared fixtures: a real Zenoh router on a free loopback port, services as real processes.

Every process a test runs through these helpers is checked the same way: its exit status (0
unless the test says otherwise, or killed it on purpose) and that nothing it printed is a Python
traceback or a Rust panic. A good run that ends in a traceback is a failure.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

ROOT = Path(__file__).resolve().parents[1]  # the checkout
REAL_DATA = ROOT.parent / "shared" / "data" / "real"


def real_bag(name: str) -> Path:
    """A recording in ``../shared/data/real/``; the test is skipped, saying so, without it."""
    path = REAL_DATA / name
    if not path.exists():
        pytest.skip(f"real recording {path} is absent (shared data not mounted beside the repo)")
    return path


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


CRASH_MARKS = ("Traceback (most recent call last)", "panicked at", "FATAL: exception not rethrown")
ZENOH_ERROR = re.compile(r"ERROR.*zenoh")  # Zenoh's own log: e.g. a channel closed under it
# ... except the shared-memory watchdog's "timer overrun": a machine too busy to wake it on time.
ZENOH_LOAD = "timer overrun"


def crash_in(output: str, *, zenoh_errors: bool = False) -> str | None:
    """The first line that says a process crashed (a traceback, a panic, a Zenoh error)."""
    for line in output.splitlines():
        if any(mark in line for mark in CRASH_MARKS):
            return line
        if not zenoh_errors and ZENOH_ERROR.search(line) and ZENOH_LOAD not in line:
            return line
    return None


def assert_clean_exit(
    name: str, code: int | None, output: str, expect: int | None = 0, *, zenoh_errors: bool = False
) -> None:
    """``name`` ended with status ``expect`` (None: any) and printed no traceback or panic.

    ``zenoh_errors``: Zenoh's own error lines are expected (a router that refuses on purpose).
    """
    crash = crash_in(output, zenoh_errors=zenoh_errors)
    assert crash is None, f"{name} crashed ({crash}):\n{output[-4000:]}"
    if expect is not None:
        assert code == expect, f"{name} exited {code}, not {expect}:\n{output[-4000:]}"


def ask_zenoh(endpoint: str, key: str, timeout: float = 5.0) -> bytes:
    """The first answer to ``key``, asked through a client session of the test's own."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session:
        for reply in session.get(key, timeout=timeout):
            return reply.ok.payload.to_bytes()
    raise AssertionError(f"nothing answered {key} at {endpoint}")


def run_wallmap(
    *args: str, timeout: float = 120.0, expect: int | None = 0, **kwargs
) -> subprocess.CompletedProcess[str]:
    """Run one wallmap command to its end, capturing its output as text.

    Asserts it exited with ``expect`` (None: any status) and printed no traceback.
    """
    done = subprocess.run(
        [sys.executable, "-m", "wallmap", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        **kwargs,
    )
    assert_clean_exit(f"wallmap {args[0]}", done.returncode, done.stdout + done.stderr, expect)
    return done


@dataclass
class Service:
    """A running wallmap process and its log file."""

    name: str
    proc: subprocess.Popen[bytes]
    log: Path
    killed: bool = False  # SIGKILLed by the test: its exit status is not its own
    zenoh_errors: bool = False  # Zenoh logs errors on purpose (an access-control router)

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def stop(self, timeout: float = 15.0, sig: int = signal.SIGTERM) -> int:
        """Ask it to stop (SIGTERM, or ``sig``) and wait; a service that hangs is killed."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode

    def kill(self) -> None:
        """SIGKILL, as a crash or a power cut would."""
        self.killed = True
        self.proc.kill()
        self.proc.wait()

    def assert_clean(self) -> None:
        """It ended with status 0 (unless killed on purpose) and printed no traceback."""
        expect = None if self.killed else 0
        assert_clean_exit(
            self.name, self.proc.returncode, self.output(), expect, zenoh_errors=self.zenoh_errors
        )


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

    def start_linked_routers(self, other: str) -> None:
        """Router A on the stack's endpoint, router B on ``other`` joined to A (a fleet's
        mesh, on loopback); both ready."""
        self.start("router-a", "router", "--listen", self.endpoint)
        wait_for_port(int(self.endpoint.rsplit(":", 1)[1]))
        self.start("router-b", "router", "--listen", other, "--connect", self.endpoint)
        wait_for_port(int(other.rsplit(":", 1)[1]))

    def run(
        self, *args: str, timeout: float = 300.0, expect: int | None = 0
    ) -> subprocess.CompletedProcess[str]:
        return run_wallmap(*args, timeout=timeout, expect=expect)

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

    def assert_all_clean(self) -> None:
        """Every process of the stack exited 0 (or was killed by the test), with no traceback."""
        for service in self.services:
            service.assert_clean()


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
    s.assert_all_clean()


@pytest.fixture(scope="session")
def scene_bags(tmp_path_factory):
    """Generated scene bags, each written once per test session: ``scene_bags(name, **how)``.

    Unit and end-to-end tests that map the same scene share it (``write_scene_bag``'s arguments).
    """
    from wallmap.scene import write_scene_bag

    made = {}
    folder = tmp_path_factory.mktemp("scenes")

    def scene(name: str, **how):
        key = (name, tuple(sorted(how.items())))
        if key not in made:
            made[key] = write_scene_bag(folder / name, **how)
        return made[key]

    return scene


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Every test under tests/e2e/ runs real processes: marked ``e2e`` (``-m "not e2e"``)."""
    e2e = Path(__file__).parent / "e2e"
    for item in items:
        if e2e in Path(item.fspath).parents:
            item.add_marker(pytest.mark.e2e)


@pytest.fixture(scope="session")
def handheld_recordings(tmp_path_factory):
    """The handheld kitchen, three ways (``handheld_scenes``), written once per session."""
    from handheld_scenes import write_all

    return write_all(tmp_path_factory.mktemp("handheld"))


@pytest.fixture(scope="session")
def odometry_scene(scene_bags):
    """A lidar scene with drifting wheel odometry: (bag, plan, trajectory, seen counts)."""
    info = scene_bags("odometry-lidar.bag", seed=606, n_frames=300, fmt="ros1", sensor="laserscan")
    return info.path, info.plan, info.trajectory, info.seen_counts
