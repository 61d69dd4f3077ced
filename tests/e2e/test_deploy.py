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
from conftest import ROOT, Stack, ask_zenoh, free_port, run_wallmap, wait_for_port
from live_robot import mapped, play_to_the_source

from wallmap.common.codec import decode
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


def test_demo_is_tuned_by_its_configuration_flags(tmp_path):
    """`wallmap demo --set ...` runs with the key set (it was accepted and ignored)."""
    out = run_wallmap("demo", "--out", str(tmp_path / "d.png"), "--set", "up.min_obs=40")
    assert out.returncode == 0, out.stderr
    rows = [line.split() for line in out.stdout.splitlines() if re.match(r"\s+\d+\s+-?\d", line)]
    assert rows, out.stdout
    assert all(int(row[-1]) >= 40 for row in rows), "only walls seen 40 times are printed"


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


# The fleet profile's services: each robot's (-a, -b) and the merge.
FLEET = {"merge"} | {
    f"{service}-{robot}"
    for service in ("scene", "router", "detector", "mapper", "player")
    for robot in "ab"
}


def test_compose_and_dockerfile_are_consistent():
    text = (ROOT / "docker-compose.yml").read_text()
    compose = yaml.safe_load(text)
    services = compose["services"]
    assert set(services) == {"router", "mapper", "detector", "odometry", "ros2", "player", *FLEET}
    assert services["odometry"]["profiles"] == ["odometry"], "only for bags without poses"
    assert services["ros2"]["profiles"] == ["live"], "only for a live robot"
    for name in FLEET:
        assert services[name]["profiles"] == ["fleet"], f"{name}: only for the fleet"
    assert services["router"]["build"] == "."
    for name, svc in services.items():
        assert svc["image"] == "wallmap:latest", name
        command = svc["command"][0]
        assert name in (command, f"{command}-a", f"{command}-b"), "its own subcommand"
    assert set(services["player"]["depends_on"]) == {"router", "mapper", "detector"}
    assert "wallmap-data:/data" in services["mapper"]["volumes"]
    # Every profile is documented at the top of the file, with how to run it.
    header = text.split("\nservices:", 1)[0]
    profiles = {p for svc in services.values() for p in svc.get("profiles", [])}
    assert profiles == {"odometry", "live", "fleet"}
    for profile in profiles:
        assert f"docker-compose --profile {profile} up" in header, profile
    # The fleet: each robot's services on its own router under its own prefix, the routers
    # linked, each player after its bag is written, the merge on robot A's router.
    for robot in "ab":
        router = f"tcp/router-{robot}:7447"
        for name in (f"detector-{robot}", f"mapper-{robot}", f"player-{robot}"):
            command = services[name]["command"]
            assert command[command.index("--prefix") + 1] == f"robot_{robot}", name
            assert command[command.index("--connect") + 1] == router, name
        after = services[f"player-{robot}"]["depends_on"]
        assert after[f"scene-{robot}"] == {"condition": "service_completed_successfully"}
        assert {f"router-{robot}", f"detector-{robot}", f"mapper-{robot}"} <= set(after)
        bag = services[f"player-{robot}"]["command"][1]
        assert bag == services[f"scene-{robot}"]["command"][1], "it plays the bag written"
        assert "fleet-bags:/data:ro" in services[f"player-{robot}"]["volumes"]
        assert "fleet-bags:/data" in services[f"scene-{robot}"]["volumes"]
    scenes = [services[f"scene-{robot}"]["command"] for robot in "ab"]
    assert len({c[c.index("--seed") + 1] for c in scenes}) == 1, "one building"
    assert {"--reverse", "--own-frame"} <= set(scenes[1])
    assert services["router-b"]["command"][-2:] == ["--connect", "tcp/router-a:7447"]
    merge = services["merge"]["command"]
    assert merge[merge.index("--robots") + 1] == "robot_a,robot_b"
    assert merge[merge.index("--connect") + 1] == "tcp/router-a:7447"

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
    command: list[str],
    endpoint: str,
    tmp_path: Path,
    env: dict[str, str] | None = None,
    routers: dict[str, str] | None = None,
) -> list[str]:
    """Compose's container addresses and paths, as they are on this machine.

    ``endpoint`` stands for the router ``router`` and for what a router listens on; ``routers``
    maps other routers' service names (the fleet's ``router-a``, ``router-b``) to theirs.
    """
    hosts = {"router": endpoint, **(routers or {})}
    out = []
    for word in command:
        arg = interpolate(word, env or {})
        for host, local in hosts.items():
            arg = arg.replace(f"tcp/{host}:7447", local)
        arg = arg.replace("tcp/0.0.0.0:7447", endpoint)
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


def fleet_robots(endpoint: str) -> dict[str, dict]:
    """``fleet/robots`` (where each robot's map frame lies), asked through a session of our own."""
    return {r["prefix"]: r for r in decode(ask_zenoh(endpoint, "fleet/robots"))["robots"]}


def test_compose_fleet_profile_merges_two_robots(tmp_path: Path) -> None:
    """`docker-compose --profile fleet up`: the two bags written, each robot's player, detector
    and mapper on its own router (router-b joined to router-a), and the merge's one map."""
    at_a, at_b = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    routers = {"router-a": at_a, "router-b": at_b}
    commands = {
        name: localise(command, at_b if name == "router-b" else at_a, tmp_path, routers=routers)
        for name, command in compose_commands().items()
        if name in FLEET
    }
    stack = Stack(tmp_path, at_a, "fleet")  # stack.query(): the fleet's map, on router-a
    robots = {"robot_a": "a", "robot_b": "b"}  # each robot's prefix, its services' suffix
    try:
        scenes = [stack.start(name, *commands[name]) for name in ("scene-a", "scene-b")]
        for name in ("router-a", "router-b"):
            stack.start(name, *commands[name])
            wait_for_port(int(routers[name].rsplit(":", 1)[1]))
        for name in ("detector-a", "mapper-a", "detector-b", "mapper-b", "merge"):
            stack.start(name, *commands[name])
        for scene in scenes:  # the players wait for their bags: service_completed_successfully
            assert scene.proc.wait(timeout=60) == 0, scene.output()
        players = {
            robot: stack.start(f"player-{x}", *commands[f"player-{x}"])
            for robot, x in robots.items()
        }
        published = {}
        for robot, player in players.items():
            assert player.proc.wait(timeout=120) == 0, player.output()
            found = re.search(r"published (\d+) frames", player.output())
            assert found, player.output()
            published[robot] = int(found[1])
        mapped = {
            robot: stack.run(
                "query", "--json", "--prefix", robot, "--connect", routers[f"router-{x}"]
            )
            for robot, x in robots.items()
        }
        frames = {robot: json.loads(out.stdout)["frames"] for robot, out in mapped.items()}
        assert frames == published, "every frame of both bags in its robot's map"
        deadline = time.monotonic() + 20  # the merge reads each robot's map at least every 5 s
        while (fleet := stack.query())["frames"] < sum(frames.values()):
            assert time.monotonic() < deadline, (fleet["frames"], frames)
            time.sleep(0.5)
        placed = fleet_robots(at_b)  # asked through router-b: the routers are one mesh
    finally:
        stack.stop_all()
    stack.assert_all_clean()
    assert placed["robot_a"]["aligned"], placed
    assert placed["robot_b"]["aligned"], placed  # B's map frame found in A's, by the walls
    sources = [{s["robot"] for s in wall["sources"]} for wall in fleet["walls"]]
    assert all(sources), "every fused wall says which robots saw it"
    assert set().union(*sources) == {"robot_a", "robot_b"}
    assert sum(seen == {"robot_a", "robot_b"} for seen in sources) >= 6, "walls both saw, once"
