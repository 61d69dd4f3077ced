"""Several hosts: the router and each service in its own network namespace, a link cut mid-run.

Namespaces joined by veth pairs stand in for machines on a network: the router in one, the
mapper and the detector in one each, the player (this test) in the host's. The detector's link
is cut while frames flow and restored two seconds later; in real-time playback as under
`--fast`, no frame may be lost: what the link lost comes back from the history.
Needs root and `ip netns`; skipped with the reason elsewhere.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest
from conftest import free_port
from test_recovery import N_FRAMES, _control, _until

from wallmap.common.link_settings import ZenohSettings
from wallmap.common.transport import Keys, open_session
from wallmap.scene import write_scene_bag

pytestmark = pytest.mark.e2e

TAG = f"wm{os.getpid() % 10000}"


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture
def network() -> Iterator[dict[str, str]]:
    """Namespaces router/mapper/detector; returns each one's address of the router."""
    if os.geteuid() != 0:
        pytest.skip("network namespaces need root")
    try:
        _ip("netns", "add", f"{TAG}-router")
    except (OSError, subprocess.CalledProcessError) as err:
        pytest.skip(f"cannot create network namespaces here ({err})")
    links = {"mapper": 1, "detector": 2, "player": 3}
    try:
        try:
            _build(links)
        except subprocess.CalledProcessError as err:
            pytest.skip(f"cannot wire network namespaces here ({err.stderr.strip()})")
        yield {name: f"10.77.{subnet}.1" for name, subnet in links.items()}
    finally:
        for name in ("router", "mapper", "detector"):
            subprocess.run(
                ["ip", "netns", "del", f"{TAG}-{name}"], check=False, capture_output=True
            )
        subprocess.run(["ip", "link", "del", f"{TAG}p"], check=False, capture_output=True)


def _build(links: dict[str, int]) -> None:
    """Namespaces for the mapper and the detector, and a veth pair from each (and from the
    host, for the player) to the router's namespace, on subnet 10.77.N.0/24."""
    _ip("-n", f"{TAG}-router", "link", "set", "lo", "up")
    for name, subnet in links.items():
        inside, router_side = f"{TAG}{name[0]}", f"{TAG}{name[0]}r"
        if name != "player":
            _ip("netns", "add", f"{TAG}-{name}")
            _ip("-n", f"{TAG}-{name}", "link", "set", "lo", "up")
        _ip("link", "add", inside, "type", "veth", "peer", "name", router_side)
        _ip("link", "set", router_side, "netns", f"{TAG}-router")
        if name != "player":
            _ip("link", "set", inside, "netns", f"{TAG}-{name}")
        where = [] if name == "player" else ["-n", f"{TAG}-{name}"]
        _ip(*where, "addr", "add", f"10.77.{subnet}.2/24", "dev", inside)
        _ip(*where, "link", "set", inside, "up")
        _ip("-n", f"{TAG}-router", "addr", "add", f"10.77.{subnet}.1/24", "dev", router_side)
        _ip("-n", f"{TAG}-router", "link", "set", router_side, "up")


@pytest.mark.parametrize("speed", [["--fast"], ["--rate", "4"]], ids=["fast", "rate4"])
def test_a_link_cut_mid_run_loses_no_frame(network, tmp_path, speed) -> None:
    bag = write_scene_bag(
        tmp_path / "s.bag", seed=11, n_frames=N_FRAMES, fmt="ros1", sensor="depth16"
    ).path
    port = free_port()
    wallmap = [sys.executable, "-m", "wallmap"]
    procs = []

    def start(namespace: str, *args: str) -> subprocess.Popen[bytes]:
        log = (tmp_path / f"{args[0]}.log").open("wb")
        command = ["ip", "netns", "exec", f"{TAG}-{namespace}", *wallmap, *args]
        procs.append(subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT))
        return procs[-1]

    try:
        start("router", "router", "--listen", f"tcp/0.0.0.0:{port}")
        for name in ("mapper", "detector"):
            start(name, name, "--connect", f"tcp/{network[name]}:{port}")
        endpoint = f"tcp/{network['player']}:{port}"
        settings = ZenohSettings(connect=(endpoint,), wait_for_router=20.0)
        keys = Keys()
        player = subprocess.Popen(
            [
                *wallmap,
                "player",
                str(bag),
                *speed,
                "--paused",
                "--wait-for",
                "detector,mapper",
                "--connect",
                endpoint,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        with open_session(settings) as session:
            _until(lambda: _control(session, keys, "status"))
            _control(session, keys, "resume")
            _until(lambda: (s := _control(session, keys, "status")) and s["published"] >= 100)
            _control(session, keys, "pause")
            _ip("-n", f"{TAG}-router", "link", "set", f"{TAG}dr", "down")  # the cut
            _control(session, keys, "resume")
            time.sleep(2.0)
            _ip("-n", f"{TAG}-router", "link", "set", f"{TAG}dr", "up")
        output, _ = player.communicate(timeout=120)
        assert player.returncode == 0, output
        assert f"the mapper integrated {N_FRAMES}" in output
        reply = json.loads(
            subprocess.run(
                [*wallmap, "query", "--json", "--connect", endpoint],
                capture_output=True,
                text=True,
                check=True,
                timeout=30,
            ).stdout
        )
        assert (reply["frames"], reply["lost"], reply["dropped"]) == (N_FRAMES, 0, 0)
        for name in ("detector", "mapper", "router"):
            assert "Traceback" not in (tmp_path / f"{name}.log").read_text()
        assert "Traceback" not in output
    finally:
        for proc in procs:
            proc.terminate()
            proc.wait(timeout=15)
