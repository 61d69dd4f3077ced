"""`wallmap ros2` maps a live ROS 2 robot from its topics on Zenoh (zenoh-bridge-ros2dds naming).

The robot is a generated ROS 2 bag replayed in real time (here twice as fast) onto the bridge's
keys: each message's own CDR bytes on the key of its topic (``/T`` -> ``NAMESPACE/T``), in the
bag's order and at its pace; ``tf_static`` once at the start and answered to queries, as the
bridge answers from its cache for a transient-local topic. A detector and a mapper take what
`wallmap ros2` publishes; the walls are scored against the scene's truth.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import Service, Stack, assert_clean_exit, free_port
from live_robot import DOMAIN, SENSORS, Robot, client, mapped, play_to_the_source

from wallmap.common.messages import unpack_frame
from wallmap.common.transport import Keys
from wallmap.evaluation import evaluate_map


def _wait_for(
    stack: Stack, service: str, timeout: float = 30.0, not_run: str | None = None
) -> None:
    """Until ``service`` answers `wallmap status` (one of another run than ``not_run``)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        out = stack.run("status", "--json", *stack.zenoh_args, timeout=30)
        runs = [s.get("run") for s in json.loads(out.stdout or "[]") if s["service"] == service]
        if any(not_run is None or run != not_run for run in runs):
            return
        time.sleep(0.2)
    pytest.fail(f"no {service} came up")


@pytest.mark.parametrize(
    ("sensor", "namespace", "naming", "discovered"),
    [
        ("depth16", "robot1", "bridge", False),
        ("pointcloud", "", "bridge-advanced", True),
        ("laserscan", "robot1", "rmw_zenoh", True),
    ],
)
def test_a_live_robot_is_mapped_from_its_topics(
    stack: Stack, scene_bags, sensor: str, namespace: str, naming: str, discovered: bool
) -> None:
    """Each sensor type, each naming; the sensor topic given, or found from what is announced.

    The static transforms are sent before the source starts, as a robot sends them long before
    anyone listens: from the bridge's cache by a query, or from an advanced publisher's cache.
    """
    info = scene_bags(f"live-{sensor}", seed=21, n_frames=120, fmt="ros2-mcap", sensor=sensor)
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    _wait_for(stack, "detector")
    args = ["--namespace", namespace]
    args += ["--rmw-zenoh", str(DOMAIN)] if naming == "rmw_zenoh" else []
    args += [] if discovered else ["--sensor", SENSORS[sensor]]
    with client(stack.endpoint) as session:
        robot = Robot(session, info.path, namespace, naming)
        try:
            robot.send_static_first()
            source = stack.start("ros2", "ros2", *args, *stack.zenoh_args)
            _wait_for(stack, "ros2")
            robot.play(skip=("/tf_static",))
        finally:
            robot.close()
    sensor_topic = SENSORS[sensor].split(":")[0]
    if discovered:
        assert f"the sensor topic, as announced: {SENSORS[sensor]}" in source.output()
    heard = _status_of(stack, "ros2")
    sensor_key = next(key for key in heard["topics"] if sensor_topic in key)
    assert heard["topics"][sensor_key]["messages"] >= 0.95 * 120, heard  # big clouds may drop
    assert not [m for m in heard["missing"] if "nothing heard" in m], heard
    sent = robot.sent[f"/{sensor_topic}"]
    reply = mapped(lambda: stack.query("--min-obs", "3"), sent)
    score = evaluate_map(reply["walls"], info.plan, info.seen_counts)
    print(score.summary())
    assert score.precision >= 0.98
    assert score.recall >= 0.95
    assert score.duplicates == 0
    assert source.stop(sig=2) == 0  # Ctrl-C


def _status_of(stack: Stack, service: str) -> dict:
    out = stack.run("status", "--json", *stack.zenoh_args, timeout=30)
    return next(s for s in json.loads(out.stdout) if s["service"] == service)


def _published(source: Service) -> int:
    """The frames a stopped `wallmap ros2` published, as its last log line counts them."""
    found = re.search(r"stopping: .*'frames': (\d+)", source.output())
    assert found, source.output()
    return int(found[1])


# The restart just after the stall (the 36th image sent is the bag's 59th). While no source runs
# the robot goes on for 15 images (1 s of the bag), then waits for the new source: how long a
# process takes to start on a loaded machine does not decide what is lost. Anywhere near here a
# loss of up to 45 frames leaves every wall seen again; later in the bag, a loss of 20-30 frames
# leaves the far side of a doorway seen too few times to be merged with its near side, and the
# map rightly has that wall in two pieces.
RESTART_AT, GONE_ON = 36, 15
TF_LESS = 2  # the new source's first frames, older than any tf it holds, are dropped


def test_a_sensor_that_stalls_and_a_source_restarted_mid_run(stack: Stack, scene_bags) -> None:
    """The camera silent for 1.5 s; then `wallmap ros2` stopped and started while the robot goes on.

    What the robot sends while no source runs is lost (a bridge keeps no frames), and no more;
    the rest is mapped as one run would map it.
    """
    info = scene_bags("live-depth16", seed=21, n_frames=120, fmt="ros2-mcap", sensor="depth16")
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    _wait_for(stack, "detector")
    args = ("ros2", "--sensor", SENSORS["depth16"], *stack.zenoh_args)
    first = stack.start("ros2", *args)
    _wait_for(stack, "ros2")
    first_run = _status_of(stack, "ros2")["run"]  # now: asked at the restart, it would delay it
    image = "/camera/depth/image_raw"
    with client(stack.endpoint) as session:
        robot = Robot(session, info.path, "")
        playing = threading.Thread(target=robot.play, kwargs={"quiet": (2.0, 3.5)})
        playing.start()
        while robot.sent.get(image, 0) < RESTART_AT and playing.is_alive():
            time.sleep(0.05)
        robot.hold_after(image, GONE_ON)
        assert first.stop(sig=2) == 0
        second = stack.start("ros2-again", *args)
        _wait_for(stack, "ros2", not_run=first_run)  # the first's presence may linger
        robot.go_on()
        playing.join()
        robot.close()
    assert second.stop() == 0
    sent = _published(first) + _published(second)
    lost = robot.sent[image] - sent
    assert lost <= GONE_ON + TF_LESS, f"{lost} frames lost, {GONE_ON} sent while no source ran"
    reply = mapped(lambda: stack.query("--min-obs", "3"), sent)
    score = evaluate_map(reply["walls"], info.plan, info.seen_counts)
    print(score.summary(), f"({lost} frames lost in the restart)")
    assert score.precision >= 0.98
    assert score.recall >= 0.9  # what the restart missed may be all a wall was seen in
    assert score.duplicates == 0


def test_frames_whose_tf_never_comes_are_dropped_and_counted(stack: Stack, scene_bags) -> None:
    info = scene_bags("live-depth16", seed=21, n_frames=120, fmt="ros2-mcap", sensor="depth16")
    source = stack.start(
        "ros2", "ros2", "--sensor", SENSORS["depth16"], "--tf-wait", "0.5", *stack.zenoh_args
    )
    _wait_for(stack, "ros2")
    with client(stack.endpoint) as session:
        robot = Robot(session, info.path, "")
        try:
            robot.play(skip=("/tf", "/tf_static"))  # no transform at all
        finally:
            robot.close()
    time.sleep(1.0)
    heard = _status_of(stack, "ros2")
    assert "tf: nothing heard" in heard["missing"], heard
    counters = heard["counters"]
    assert counters.get("frames", 0) == 0
    assert counters["no_tf"] >= 100, counters  # of 120 frames, all but the last tf_wait's
    assert "without its tf" in source.output()


def test_up_maps_a_live_robot_until_stopped(tmp_path: Path, scene_bags) -> None:
    """`wallmap up --ros2`: router, detector, mapper and the live source in one command."""
    info = scene_bags("live-laserscan", seed=21, n_frames=120, fmt="ros2-mcap", sensor="laserscan")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    zenoh_args = ("--connect", endpoint, "--prefix", "test/up-ros2")
    out = tmp_path / "map.json"
    log = tmp_path / "up.log"
    up = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "wallmap",
            "up",
            "--ros2",
            "--namespace",
            "robot1",
            "--sensor",
            SENSORS["laserscan"],
            "--json-out",
            str(out),
            *zenoh_args,
        ],
        stdout=log.open("wb"),
        stderr=subprocess.STDOUT,
    )
    try:
        robot = play_to_the_source(endpoint, zenoh_args[2:], info.path, "robot1", log)
        time.sleep(2.0)  # the last frames through the detector and the mapper
        up.send_signal(signal.SIGINT)
        code = up.wait(timeout=60)
    finally:
        if up.poll() is None:
            up.kill()
    assert_clean_exit("wallmap up --ros2", code, log.read_text())
    reply = json.loads(out.read_text())
    assert reply["frames"] >= 0.95 * robot.sent["/scan"], reply["frames"]
    score = evaluate_map(reply["walls"], info.plan, info.seen_counts)
    print(score.summary())
    assert score.precision >= 0.98
    assert score.recall >= 0.95
    assert score.duplicates == 0


def test_without_sensor_and_nothing_announced_the_source_says_so_and_exits(stack: Stack) -> None:
    out = stack.run(
        "ros2", "--namespace", "robot9", "--discover-wait", "1", *stack.zenoh_args, expect=None
    )
    assert out.returncode == 1, out.stderr
    assert "Traceback" not in out.stderr
    assert out.stderr.strip().splitlines()[-1] == (
        "wallmap ros2: error: no sensor topic announced by the bridge under 'robot9' within 1 s "
        "(seen: no topic at all); give --sensor TOPIC:TYPE"
    )


def test_camera_info_elsewhere_and_whole_clouds(stack: Stack, scene_bags) -> None:
    """``--camera-info`` finds a CameraInfo not beside its image; ``--whole-clouds`` sends every
    row of each image, not the band's rows the detector asks for."""
    info = scene_bags("live-depth16", seed=21, n_frames=120, fmt="ros2-mcap", sensor="depth16")
    camera = json.loads(info.truth_path.read_text())["camera"]
    stack.start("detector", "detector", *stack.zenoh_args)
    _wait_for(stack, "detector")
    shapes: list[tuple[int, ...]] = []
    renamed = {"/camera/depth/camera_info": "/calibration/depth"}
    with client(stack.endpoint) as session:
        frames = session.declare_subscriber(
            Keys(stack.prefix).frames,
            lambda s: shapes.append(unpack_frame(s.payload.to_bytes()).points.shape),
        )
        robot = Robot(session, info.path, "", renamed=renamed)
        try:
            stack.start(
                "ros2",
                "ros2",
                "--sensor",
                SENSORS["depth16"],
                "--camera-info",
                "/calibration/depth",
                "--whole-clouds",
                *stack.zenoh_args,
            )
            _wait_for(stack, "ros2")
            robot.play()
        finally:
            robot.close()
        time.sleep(1.0)
        frames.undeclare()
    counters = _status_of(stack, "ros2")["counters"]
    assert counters.get("no_camera_info", 0) <= 1, counters  # an image before the first info
    assert counters["frames"] >= 0.95 * robot.sent["/camera/depth/image_raw"], counters
    assert len(shapes) == counters["frames"]
    assert set(shapes) == {(camera["height"], camera["width"], 3)}, set(shapes)
