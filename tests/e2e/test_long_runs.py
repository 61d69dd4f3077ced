"""Long bags in every playback mode, as separate processes over a real router.

Each run checks every process's exit status and that none printed a traceback (the ``stack``
fixture does, for every service it started). The bags are long enough that a run outlasts any
small buffer: a channel of acknowledgements that nobody drained filled after 256 frames, blocked
the player's session, and made real-time playback end in a close timeout (exit 1) and a router
restart silently freeze the map. Short runs and ``--fast`` never showed it.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest
from conftest import Stack, assert_clean_exit, free_port

from wallmap.evaluation import evaluate_map
from wallmap.scene import Camera, write_scene_bag

pytestmark = pytest.mark.e2e

RATE_HZ = 15.0
SMALL = Camera(width=96, height=72)  # light frames: the bag's length is what matters here


@pytest.fixture(scope="module")
def long_bags(tmp_path_factory):
    """A ROS 2 mcap depth bag of 720 frames (48 s) and a ROS 1 PointCloud2 bag of 360 (24 s)."""
    folder = tmp_path_factory.mktemp("long")
    depth = write_scene_bag(
        folder / "depth", seed=31, n_frames=720, fmt="ros2-mcap", sensor="depth16", camera=SMALL
    )
    cloud = write_scene_bag(
        folder / "cloud.bag",
        seed=32,
        n_frames=360,
        fmt="ros1",
        sensor="pointcloud",
        camera=SMALL,
        compress=True,
    )
    return {"mcap-depth": depth, "ros1-pointcloud": cloud}


def _services(stack) -> None:
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)


def _published(output: str) -> int:
    found = re.search(r"published (\d+) frames", output)
    assert found, output
    return int(found[1])


@pytest.mark.parametrize(
    ("bag", "speed"),
    [
        pytest.param("mcap-depth", ["--rate", "4"], id="mcap-rate4"),
        pytest.param("ros1-pointcloud", ["--rate", "8"], id="ros1-rate8"),
        pytest.param("mcap-depth", ["--fast"], id="mcap-fast"),
        pytest.param("ros1-pointcloud", ["--fast"], id="ros1-fast"),
    ],
)
def test_a_long_bag_plays_to_the_end_and_every_process_exits_cleanly(
    stack, long_bags, bag, speed
) -> None:
    scene = long_bags[bag]
    _services(stack)
    played = stack.run(
        "player", str(scene.path), *speed, "--wait-for", "detector,mapper", *stack.zenoh_args
    )
    assert _published(played.stdout) == scene.n_frames
    reply, skipped = stack.settled_frames(scene.n_frames, "--min-obs", "3")
    assert reply["frames"] + skipped == scene.n_frames, "every frame integrated or counted"
    assert skipped <= scene.n_frames // 20
    if "--fast" in speed:
        assert skipped == 0
    score = evaluate_map(reply["walls"], scene.plan, scene.seen_counts)
    print(score.summary())
    assert score.precision >= 0.9
    assert score.recall >= 0.8


def test_rate_1_on_a_short_bag(stack, long_bags) -> None:
    scene = long_bags["mcap-depth"]
    _services(stack)
    started = time.monotonic()
    played = stack.run(
        "player",
        str(scene.path),
        "--duration",
        "5",
        "--wait-for",
        "detector,mapper",
        *stack.zenoh_args,
    )
    assert time.monotonic() - started >= 5.0, "real time"
    n = _published(played.stdout)
    assert n == 5 * RATE_HZ
    reply, skipped = stack.settled_frames(n)
    assert reply["frames"] + skipped == n


def test_without_poses_the_frames_are_counted_as_dropped_and_all_exit_cleanly(
    stack, long_bags
) -> None:
    scene = long_bags["mcap-depth"]
    _services(stack)
    played = stack.run(
        "player", str(scene.path), "--rate", "8", "--pose-source", "none", *stack.zenoh_args
    )
    assert _published(played.stdout) == scene.n_frames
    assert "0 poses" in played.stdout
    deadline = time.monotonic() + 20  # frames wait 5 s for a pose that never comes
    while (reply := stack.query())["dropped"] + stack.counters("detector").get("dropped", 0) < (
        scene.n_frames
    ):
        assert time.monotonic() < deadline, reply
        time.sleep(0.5)
    assert reply["frames"] == 0
    assert reply["walls"] == []


@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
def test_a_looping_player_stopped_by_a_signal_exits_0(stack, long_bags, how) -> None:
    scene = long_bags["mcap-depth"]
    _services(stack)
    player = stack.start(
        "player",
        "player",
        str(scene.path),
        "--rate",
        "8",
        "--loop",
        "--duration",
        "4",
        *stack.zenoh_args,
    )
    deadline = time.monotonic() + 60
    while " frames on " not in player.output():  # it has read the bag and starts playing
        assert time.monotonic() < deadline, player.output()
        assert player.proc.poll() is None, player.output()
        time.sleep(0.1)
    time.sleep(2.0)  # four passes of 0.5 s (the bag's first 4 s at 8x)
    assert player.proc.poll() is None, player.output()
    assert player.stop(sig=how) == 0
    assert _published(player.output()) > 4 * RATE_HZ + 1, "it went round more than once"


@pytest.mark.parametrize(
    ("service", "how"),
    [("mapper", signal.SIGTERM), ("detector", signal.SIGINT), ("player", signal.SIGTERM)],
)
def test_a_service_waiting_for_its_router_stops_on_a_signal(
    long_bags, tmp_path, service: str, how: int
) -> None:
    """Started before any router (docker-compose, a robot's boot), a service waits for one; a
    stop must still be heard then, not only once a router came (the wait is in Zenoh's code)."""
    nowhere = Stack(tmp_path, f"tcp/127.0.0.1:{free_port()}", "norouter")
    bag = [str(long_bags["ros1-pointcloud"].path)] if service == "player" else []
    waiting = nowhere.start(
        service, service, *bag, *nowhere.zenoh_args, env={"WALLMAP_LOG": "INFO"}
    )
    deadline = time.monotonic() + 30.0
    while "connecting to" not in waiting.output() and " frames on " not in waiting.output():
        assert waiting.proc.poll() is None, waiting.output()
        assert time.monotonic() < deadline, waiting.output()
        time.sleep(0.1)
    time.sleep(0.5)  # listening for signals since before that line; now waiting in zenoh.open
    assert waiting.proc.poll() is None, waiting.output()
    start = time.monotonic()
    assert waiting.stop(timeout=10.0, sig=how) == 0, waiting.output()
    assert time.monotonic() - start < 5.0, "the stop is heard at once"
    waiting.assert_clean()
    assert "stopped while waiting for a Zenoh router" in waiting.output()


def test_up_stopped_by_ctrl_c_stops_its_services_cleanly(long_bags, tmp_path) -> None:
    """Ctrl-C as a terminal sends it, to the whole process group, mid-run: the services stop
    cleanly, and the map so far is printed, written (--json-out, marked partial) and drawn."""
    scene = long_bags["mcap-depth"]
    log = tmp_path / "up.log"
    out, picture = tmp_path / "map.json", tmp_path / "map.png"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with log.open("wb") as output:
        up = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "wallmap",
                "up",
                str(scene.path),
                "--rate",
                "4",
                "--connect",
                endpoint,
                "--json-out",
                str(out),
                "--picture",
                str(picture),
            ],
            stdout=output,
            stderr=subprocess.STDOUT,
            env={**os.environ, "WALLMAP_LOG": "INFO"},
            start_new_session=True,  # a terminal's group of its own: the signal goes to all in it
        )
        time.sleep(8.0)
        os.killpg(up.pid, signal.SIGINT)
        code = up.wait(timeout=60)
    output = log.read_text()
    assert_clean_exit("wallmap up", code, output, 0)
    for service in ("mapper", "detector"):
        assert f"{service}: stopping" in output, output
    assert "published" in output, "the player said what it played"
    assert "stopped before the end of the recording" in output
    document = json.loads(out.read_text())
    assert document["partial"] is True
    assert 0 < document["frames"] < scene.n_frames
    assert picture.read_bytes().startswith(b"\x89PNG")


def test_router_killed_and_restarted_in_real_time_the_map_goes_on(stack, long_bags) -> None:
    """SIGKILL the router 40 % into a 4x playback, a new one 2 s later on the same endpoint."""
    scene = long_bags["mcap-depth"]
    _services(stack)
    router = stack.services[0]
    player = stack.start(
        "player",
        "player",
        str(scene.path),
        "--rate",
        "4",
        "--wait-for",
        "detector,mapper",
        *stack.zenoh_args,
    )
    played_s = scene.n_frames / RATE_HZ / 4
    time.sleep(1.0 + 0.4 * played_s)  # the player waits about 1 s for its services
    before = stack.query()["frames"]
    router.kill()
    time.sleep(2.0)
    stack.start("router-2", "router", "--listen", stack.endpoint)
    assert player.proc.wait(timeout=120) == 0, player.output()
    assert _published(player.output()) == scene.n_frames
    reply, skipped = stack.settled_frames(scene.n_frames)
    after = reply["frames"]
    lost = scene.n_frames - after - skipped
    print(f"\nframes integrated: {before} before the kill, {after} in all; {lost} lost")
    # What was published while no router ran comes back from the history (common.delivery).
    assert lost == 0
    assert reply["lost"] == 0
    for name in ("mapper", "detector", "player"):
        output = next(s for s in stack.services if s.name == name).output()
        assert output.count("lost the Zenoh router") == 1, output
        assert len(re.findall(r"reconnected to the Zenoh router after \d+\.\d s", output)) == 1
    assert stack.counters("mapper")["router_lost"] == 1


def test_a_player_waiting_for_its_services_stops_at_once_on_sigterm(stack, long_bags) -> None:
    player = stack.start(
        "player",
        "player",
        str(long_bags["mcap-depth"].path),
        "--wait-for",
        "detector,mapper",
        *stack.zenoh_args,
    )
    deadline = time.monotonic() + 60
    while " frames on " not in player.output():  # the bag read: now it waits for its services
        assert time.monotonic() < deadline, player.output()
        time.sleep(0.1)
    time.sleep(0.5)
    asked = time.monotonic()
    assert player.stop(timeout=10) == 0
    assert time.monotonic() - asked < 3.0
    assert "published 0 frames" in player.output()
