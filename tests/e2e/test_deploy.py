"""`wallmap demo`, `wallmap up`, and docker-compose.yml + Dockerfile run as local processes.

No Docker engine runs here, so the compose file is parsed and each service's command line is run
as a process against a router on a free loopback port: the file cannot rot unnoticed.
"""

from __future__ import annotations

import json
import math
import re
import struct
import subprocess
import sys
import time
from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import ROOT, free_port, run_wallmap, wait_for_port
from live_robot import mapped, play_to_the_source

from wallmap.evaluation import evaluate_map
from wallmap.scene import load_truth, write_scene_bag

pytestmark = pytest.mark.e2e


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
    assert set(services) == {"router", "mapper", "detector", "odometry", "ros2", "player"}
    assert services["odometry"]["profiles"] == ["odometry"], "only for bags without poses"
    assert services["ros2"]["profiles"] == ["live"], "only for a live robot"
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
    ignored = [
        line.strip()
        for line in (ROOT / ".dockerignore").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]
    lines = re.findall(r"^COPY (.+) \./$", dockerfile, re.MULTILINE)
    copied = [name for line in lines for name in line.split()]
    for name in [*copied, "wallmap", "common", "services"]:
        assert (ROOT / name).exists(), f"the Dockerfile copies {name}, which is missing"
        assert not any(fnmatch(name, pattern) for pattern in ignored), f"{name} is docker-ignored"
    assert {".git", ".venv"} <= set(ignored), "the build context leaves the repo's bulk out"
    # The detector's loops are compiled at build, where the containers' numba cache is.
    cache = re.search(r"NUMBA_CACHE_DIR=(\S+)", dockerfile)
    assert cache, "the image keeps numba's cache in a known place"
    assert f"chown -R wallmap {cache[1]}" in dockerfile, "...which the services' user may read"
    warm = re.search(r"python -c '([^']+)'", dockerfile)
    assert warm, "the image compiles the detector's loops at build"
    subprocess.run([sys.executable, "-c", warm[1]], check=True, timeout=120)
    # The compose player reads the sample bag where the image has it: /app is the repo.
    player_bag = interpolate(services["player"]["command"][1], {})
    assert (ROOT / player_bag.removeprefix("/app/")).is_file()
    assert "./bags:/bags:ro" in services["player"]["volumes"]


def interpolate(word: str, env: dict[str, str]) -> str:
    """Compose's ``${NAME:-default}``, as docker-compose expands it from the environment."""
    return re.sub(r"\$\{(\w+):-([^}]*)\}", lambda m: env.get(m[1]) or m[2], word)


def localise(
    command: list[str], endpoint: str, tmp_path: Path, env: dict[str, str] | None = None
) -> list[str]:
    """Compose's container addresses and paths, as they are on this machine."""
    out = []
    for word in command:
        arg = interpolate(word, env or {})
        arg = arg.replace("tcp/router:7447", endpoint).replace("tcp/0.0.0.0:7447", endpoint)
        if arg.startswith("/data/"):
            arg = str(tmp_path / arg.removeprefix("/data/"))
        elif arg.startswith("/app/"):
            arg = str(ROOT / arg.removeprefix("/app/"))
        elif arg.startswith("/bags/"):
            arg = str(tmp_path / "bags" / arg.removeprefix("/bags/"))
        out.append(arg)
    return out


def test_compose_services_run_as_processes(tmp_path):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    commands = {k: localise(v, endpoint, tmp_path) for k, v in compose_commands().items()}
    del commands["odometry"], commands["ros2"]  # their profiles are off by default
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


def moved(wall: dict, pose: tuple[float, float, float]) -> dict:
    """A wall record of the map reply, moved by a planar pose (its u, v recomputed)."""
    x, y, yaw = pose
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    p0, p1 = (rot @ np.asarray(wall[k]) + (x, y) for k in ("p0", "p1"))
    segments = np.asarray(wall["segments"]) @ rot.T + (x, y)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    u, v = p0 - (p0 @ d) * d  # the line's closest point to the origin
    return {
        **wall,
        "p0": p0.tolist(),
        "p1": p1.tolist(),
        "segments": segments.tolist(),
        "u": float(u),
        "v": float(v),
    }


def test_compose_odometry_profile_maps_a_bag_without_poses(tmp_path):
    """`docker-compose --profile odometry up` with the documented variables, on a lidar bag."""
    (tmp_path / "bags").mkdir()
    info = write_scene_bag(
        tmp_path / "bags" / "lidar.bag", seed=707, n_frames=200, fmt="ros1", sensor="laserscan"
    )
    env = {
        "WALLMAP_BAG": "/bags/lidar.bag",
        "WALLMAP_POSE_SOURCE": "none",
        "WALLMAP_WAIT_FOR": "detector,mapper,odometry",
    }
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    commands = {k: localise(v, endpoint, tmp_path, env) for k, v in compose_commands().items()}
    procs = {}
    try:
        for name in ("router", "mapper", "detector", "odometry", "player"):
            log = (tmp_path / f"{name}.log").open("wb")
            procs[name] = subprocess.Popen(
                [sys.executable, "-m", "wallmap", *commands[name]], stdout=log, stderr=log
            )
            if name == "router":
                wait_for_port(port)
        player_log = tmp_path / "player.log"
        assert procs["player"].wait(timeout=120) == 0, player_log.read_text()
        assert "published 200 frames and 0 poses" in player_log.read_text()
        query = run_wallmap("query", "--json", "--min-obs", "3", "--connect", endpoint, timeout=30)
        assert query.returncode == 0, query.stderr
        reply = json.loads(query.stdout)
        assert reply["frames"] == 200
        plan, trajectory, seen = load_truth(info.truth_path)
        # The odometry frame starts at the first scan: place the map where that scan was taken.
        score = evaluate_map([moved(w, trajectory.pose_at(0)) for w in reply["walls"]], plan, seen)
        # Every wall found; on this short drive two corner slivers come out too, as they do
        # with the same poses in one process (tests/test_odometry.py measures the accuracy).
        assert score.recall >= 0.9, score.summary()
        assert score.precision >= 0.8, score.summary()
        assert score.median_offset_m < 0.02, score.summary()
    finally:
        for name in ("player", "odometry", "detector", "mapper", "router"):
            if name in procs and procs[name].poll() is None:
                procs[name].terminate()
                procs[name].wait(timeout=15)


def test_compose_live_profile_maps_a_live_robot(tmp_path):
    """`docker-compose --profile live up router mapper detector ros2`, as documented, on a robot
    that sends a laser scan under the namespace robot1 (tests/live_robot.py), its sensor topic
    found from what its bridge announces."""
    info = write_scene_bag(
        tmp_path / "live", seed=21, n_frames=120, fmt="ros2-mcap", sensor="laserscan"
    )
    env = {"WALLMAP_NAMESPACE": "robot1"}  # the sensor: the one topic the bridge announces
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    commands = {k: localise(v, endpoint, tmp_path, env) for k, v in compose_commands().items()}
    procs = {}
    try:
        for name in ("router", "mapper", "detector", "ros2"):
            log = (tmp_path / f"{name}.log").open("wb")
            procs[name] = subprocess.Popen(
                [sys.executable, "-m", "wallmap", *commands[name]], stdout=log, stderr=log
            )
            if name == "router":
                wait_for_port(port)
        robot = play_to_the_source(endpoint, (), info.path, "robot1", tmp_path / "ros2.log")
        query = ("query", "--json", "--min-obs", "3", "--connect", endpoint)
        reply = mapped(lambda: json.loads(run_wallmap(*query).stdout), robot.sent["/scan"])
        score = evaluate_map(reply["walls"], info.plan, info.seen_counts)
        assert score.precision >= 0.98, score.summary()
        assert score.recall >= 0.95, score.summary()
    finally:
        for name in ("ros2", "detector", "mapper", "router"):
            if name in procs and procs[name].poll() is None:
                procs[name].terminate()
                assert procs[name].wait(timeout=15) == 0, (tmp_path / f"{name}.log").read_text()
