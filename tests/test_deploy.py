"""`wallmap demo`, `wallmap up`, and docker-compose.yml + Dockerfile run as local processes.

No Docker engine runs here, so the compose file is parsed and each service's command line is run
as a process against a router on a free loopback port: the file cannot rot unnoticed.
"""

from __future__ import annotations

import re
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import free_port, run_wallmap, wait_for_port

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]


def test_demo_maps_the_sample_bag_and_draws_it(tmp_path):
    png = tmp_path / "demo.png"
    out = run_wallmap("demo", "--out", str(png), cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "published 245 frames" in out.stdout
    assert re.search(r"\d+ walls from 245 frames", out.stdout)
    score = re.search(r"precision (\S+) .* recall (\S+) .* duplicates (\d+)", out.stdout)
    assert score, out.stdout
    assert float(score[1]) >= 0.95
    assert float(score[2]) >= 0.9
    assert score[3] == "0"
    picture = png.read_bytes()
    assert picture.startswith(b"\x89PNG\r\n\x1a\n")
    width, height = struct.unpack(">II", picture[16:24])
    assert max(width, height) == 1000


def test_up_writes_the_map_as_json_and_keeps_state(tmp_path):
    port = free_port()
    json_out, state = tmp_path / "map.json", tmp_path / "state.json"
    bag = ROOT / "wallmap" / "data" / "sample.bag"
    args = ["up", str(bag), "--fast", "--exit-when-done", "--json-out", str(json_out)]
    args += ["--state", str(state), "--connect", f"tcp/127.0.0.1:{port}"]
    out = run_wallmap(*args)
    assert out.returncode == 0, out.stderr
    reply = yaml.safe_load(json_out.read_text())  # JSON is YAML
    assert reply["v"] == 1
    assert reply["frames"] == 245
    assert state.exists()  # the mapper saved its map on SIGTERM


def compose_commands() -> dict[str, list[str]]:
    compose = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
    return {name: svc["command"] for name, svc in compose["services"].items()}


def test_compose_and_dockerfile_are_consistent():
    compose = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
    services = compose["services"]
    assert set(services) == {"router", "mapper", "detector", "player"}
    assert services["router"]["build"] == "."
    for name, svc in services.items():
        assert svc["image"] == "wallmap:latest", name
        assert svc["command"][0] == name, "each service runs its own subcommand"
    assert set(services["player"]["depends_on"]) == {"router", "mapper", "detector"}
    assert "wallmap-data:/data" in services["mapper"]["volumes"]

    dockerfile = (ROOT / "Dockerfile").read_text()
    assert re.search(r"^FROM python:3\.1[1-9]", dockerfile, re.MULTILINE)
    assert 'ENTRYPOINT ["wallmap"]' in dockerfile
    for folder in ("wallmap", "common", "services"):
        assert f"COPY {folder} ./{folder}" in dockerfile
        assert (ROOT / folder).is_dir()
    for copied in re.findall(r"^COPY (.+) \./$", dockerfile, re.MULTILINE):
        for name in copied.split():
            assert (ROOT / name).exists(), f"the Dockerfile copies {name}, which is missing"
    # The compose player reads the sample bag where the image has it: /app is the repo.
    player_bag = services["player"]["command"][1]
    assert (ROOT / player_bag.removeprefix("/app/")).is_file()


def localise(command: list[str], endpoint: str, tmp_path: Path) -> list[str]:
    """Compose's container addresses and paths, as they are on this machine."""
    out = []
    for word in command:
        arg = word.replace("tcp/router:7447", endpoint).replace("tcp/0.0.0.0:7447", endpoint)
        if arg.startswith("/data/"):
            arg = str(tmp_path / arg.removeprefix("/data/"))
        elif arg.startswith("/app/"):
            arg = str(ROOT / arg.removeprefix("/app/"))
        out.append(arg)
    return out


def test_compose_services_run_as_processes(tmp_path):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    commands = {k: localise(v, endpoint, tmp_path) for k, v in compose_commands().items()}
    procs: dict[str, subprocess.Popen[bytes]] = {}
    logs = {name: tmp_path / f"{name}.log" for name in commands}

    def start(name: str) -> None:
        procs[name] = subprocess.Popen(
            [sys.executable, "-m", "wallmap", *commands[name]],
            stdout=logs[name].open("wb"),
            stderr=subprocess.STDOUT,
        )

    try:
        start("mapper")  # before the router: services wait for it, as in compose
        start("detector")
        time.sleep(0.5)
        start("router")
        wait_for_port(port)
        start("player")
        assert procs["player"].wait(timeout=120) == 0, logs["player"].read_text()
        assert "published 245 frames" in logs["player"].read_text()
        query = run_wallmap("query", "--min-obs", "3", "--connect", endpoint, timeout=30)
        assert query.returncode == 0, query.stderr
        assert re.search(r"1\d walls from 245 frames", query.stdout), query.stdout
    finally:
        for name in ("player", "detector", "mapper", "router"):
            if name in procs and procs[name].poll() is None:
                procs[name].terminate()
                procs[name].wait(timeout=15)
    assert (tmp_path / "map.json").exists()  # the mapper's state, on its /data volume
