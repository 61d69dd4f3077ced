"""Bad input: refused with a reason and counted, services stay up; the CLI fails in one line."""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import msgpack
import pytest
from conftest import ROOT, free_port, run_wallmap
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from wallmap.common.codec import encode
from wallmap.common.link_settings import ZenohSettings
from wallmap.common.transport import Keys, open_session
from wallmap.scene import write_scene_bag

pytestmark = pytest.mark.e2e


def assert_one_line_error(out: subprocess.CompletedProcess[str], command: str, *words: str) -> None:
    assert out.returncode != 0
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith(f"wallmap {command}: error: ")
    assert "Traceback" not in out.stderr
    for word in words:
        assert word in lines[0]


def put_when_matched(session, key: str, payloads: list[bytes]) -> None:
    publisher = session.declare_publisher(key)
    deadline = time.monotonic() + 10
    while not publisher.matching_status.matching:
        assert time.monotonic() < deadline, f"nobody subscribes to {key}"
        time.sleep(0.05)
    for payload in payloads:
        publisher.put(payload)
    publisher.undeclare()


def test_malformed_messages_are_refused_counted_and_the_services_keep_working(stack, tmp_path):
    detector = stack.start("detector", "detector", *stack.zenoh_args)
    stack.start("mapper", "mapper", *stack.zenoh_args)
    keys = Keys(stack.prefix)
    nan_pose = encode({"stamp": 1.0, "x": math.nan, "y": 0.0, "yaw": 0.0})
    wrong_version = msgpack.packb({"v": 7, "stamp": 1.0, "x": 0.0, "y": 0.0, "yaw": 0.0})
    with open_session(ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)) as session:
        put_when_matched(session, keys.frames, [b"\x00garbage", wrong_version])
        put_when_matched(session, keys.pose, [nan_pose, wrong_version, b"{}"])
        put_when_matched(session, keys.observations, [b"not msgpack at all \xc1"])
        # The mapper declares its queryable after its subscribers: on a busy machine a query
        # can come between the two and find nothing to answer it. Asked again until answered.
        deadline = time.monotonic() + 20
        while not (bad := list(session.get(f"{keys.map_walls}?min_obs=many", timeout=5))):
            assert time.monotonic() < deadline, "the mapper answers no query"
            time.sleep(0.2)
        assert bad[0].err is not None
        assert "min_obs must be an integer" in bad[0].err.payload.to_string()

    bag = tmp_path / "small.bag"
    write_scene_bag(bag, seed=5, n_frames=30, fmt="ros1", sensor="depth16")
    played = stack.run("player", str(bag), "--fast", *stack.zenoh_args)
    assert played.returncode == 0, played.stderr
    reply = stack.query()
    assert reply["frames"] == 30
    assert reply["refused"] == 4  # three poses and one observation message
    assert "refused frame: not a msgpack payload" in detector.output()
    assert "unsupported schema version 7" in detector.output()
    assert detector.proc.poll() is None


def test_missing_bag_is_one_line(tmp_path):
    out = run_wallmap(
        "player", str(tmp_path / "nope.bag"), "--connect", "tcp/127.0.0.1:1", expect=1
    )
    assert_one_line_error(out, "player", "nope.bag")


def test_bag_without_a_usable_sensor_topic_is_one_line(tmp_path):
    store = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "chatter.bag"
    with Writer(bag) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hello")
        writer.write(conn, 1_000_000_000, store.serialize_ros1(msg, "std_msgs/msg/String"))
    out = run_wallmap(
        "player", str(bag), "--pose-source", "none", "--connect", "tcp/127.0.0.1:1", expect=1
    )
    assert_one_line_error(out, "player", "/chatter")


def test_corrupt_bag_is_one_line(tmp_path):
    bag = tmp_path / "cut.bag"
    write_scene_bag(bag, seed=5, n_frames=5, fmt="ros1", sensor="depth16")
    bag.write_bytes(bag.read_bytes()[:5000])
    out = run_wallmap("player", str(bag), "--connect", "tcp/127.0.0.1:1", expect=1)
    assert_one_line_error(out, "player", "cut.bag")
    assert "('" not in out.stderr, "the library's reason as words, not as a Python tuple"


SAMPLE = str(ROOT / "wallmap" / "data" / "sample.bag")


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["player", "x.bag", "--rate", "-2"], ["--rate", "positive"]),
        (["player", "x.bag", "--rate", "2", "--fast"], ["not allowed"]),
        (["detector", "--band", "2,1"], ["LOW must be below HIGH"]),
        (["query", "--prefix", "a/*"], ["invalid prefix", "--prefix"]),
        (["config", "--set", "detector.seed=x"], ["detector.seed", "integer"]),
        (["up", "x.bag", "--config", "/nonexistent/run.toml"], ["cannot read the configuration"]),
        (["mapper", "--pose-key", "rt/tf*"], ["invalid --pose-key", "may only be preceded"]),
        (["mapper", "--pose-format", "ros2:std_msgs/msg/String"], ["--pose-format"]),
        (["player", "x.bag", "--start", "-1"], ["--start", ">= 0"]),
        (["odometry", "--initial-pose", "1,nan,0"], ["--initial-pose", "finite"]),
        (["scene", "/tmp/wallmap-scene-without-suffix"], ["ends in .bag"]),
        (["scene", "/tmp/x.mcap", "--format", "ros2-mcap"], ["ROS 2 bag is a folder", "/tmp/x "]),
        (["query", "--connect", "garbage"], ["invalid --connect 'garbage'", "<protocol>"]),
        (["router", "--listen", "tcp:7447"], ["invalid --listen 'tcp:7447'"]),
        (["up", "x.bag", "--connect", "garbage"], ["invalid --connect 'garbage'"]),
        (["up", "x.bag", "--bogus"], ["unrecognized arguments: --bogus", "wallmap up --help"]),
        # --set and a file are held to the flags' rules: a dataclass checks its own values
        (["up", "x.bag", "--set", "player.rate=-1"], ["player: rate must be a positive"]),
        (["config", "--set", "history.seconds=0"], ["history: seconds must be a positive"]),
        (["config", "--set", "mapper.pose_wait=-1"], ["mapper: pose_wait must be >= 0"]),
        (["detector", "--noise-k", "-1"], ["detector.ransac: noise_k must be >= 0"]),
        (["mapper", "--pose-frames", "nope"], ["pose_frames must be PARENT>CHILD"]),
        (["query", "--min-obs", "-1"], ["--min-obs", "whole number > 0"]),
        (["plot", "map.jpg"], ["OUT", "a picture is drawn as .png or .svg, not .jpg"]),
        (["merge", "--robots", "A"], ["--robots", "two or more distinct robot prefixes"]),
        (["merge", "--robots", "A,B,A"], ["--robots", "two or more distinct"]),
        (["merge", "--robots", "A,,B"], ["--robots", "two or more distinct"]),
        (["merge", "--robots", "A,B", "--prefix", "A"], ["--prefix 'A' is one of the robots"]),
        (["merge", "--robots", "a/*,B", "--prefix", "F"], ["invalid robot prefix 'a/*'"]),
        (["scene", "/tmp/x.bag", "--keep", "--format", "ros2-mcap"], ["ROS 2 bag is a folder"]),
        (["plot", "map.png", "--size", "0"], ["--size", "whole number > 0"]),
        (["query", "--rooms", "--bbox", "0,0,1,1"], ["--rooms answers every room", "--bbox"]),
        (["scene", "/tmp/x.bag", "--set", "a.b=1"], ["unrecognized arguments: --set"]),
        (["router", "--prefix", "x"], ["unrecognized arguments: --prefix x"]),
        (["up", "--ros2", "--fast", "--level", "none"], ["--fast, --level: a BAG's, not --ros2's"]),
        (["up", SAMPLE, "--namespace", "r1"], ["--namespace: --ros2's, not a BAG's"]),
        (["scene", "/tmp/x.bag", "--width", "0"], ["--width", "whole number > 0"]),
        (["scene", "/tmp/x.bag", "--frames", "-3"], ["--frames", "whole number > 0"]),
        (["doctor", SAMPLE, "--latency-frames", "0"], ["--latency-frames", "whole number > 0"]),
        (["up", "x.bag", "--picture", "map.bmp"], ["--picture", ".png or .svg, not .bmp"]),
        (["up", "x.bag", "--set", "up.picture=map.jpg"], ["up: picture must be .png or .svg"]),
        (["up", "/nonexistent.bag"], ["/nonexistent.bag does not exist"]),
        (
            ["player", SAMPLE, "--zenoh-config", "/nonexistent.json5"],
            ["zenoh config /nonexistent.json5 does not exist"],
        ),
        (
            ["player", SAMPLE, "--start", "1000", "--connect", "tcp/127.0.0.1:1"],
            ["--start 1000 s is past the end", "48.8 s long"],
        ),
        # checked before the services start, not after the recording has played
        (["up", SAMPLE, "--truth", "/nonexistent.json"], ["cannot read the ground truth"]),
        (["up", SAMPLE, "--json-out", "/nonexistent/map.json"], ["/nonexistent is not a folder"]),
    ],
)
def test_bad_flags_are_one_line(args, words):
    out = run_wallmap(*args, expect=None)  # 2 from argparse, 1 from a later check
    assert_one_line_error(out, args[0], *words)


def test_up_with_a_bad_bag_is_the_players_one_line(tmp_path):
    """The services ``up`` started, stopped while they still wait for the router (the player
    failed at once), stop cleanly and say nothing more; the player's line is the one."""
    bag = tmp_path / "notabag.bag"
    bag.write_text("not a bag\n")
    out = run_wallmap("up", str(bag), "--connect", f"tcp/127.0.0.1:{free_port()}", expect=1)
    assert_one_line_error(out, "player", "not a ROS bag")


def test_up_on_an_endpoint_taken_is_one_line(stack):
    """``up`` runs its own router: another one already there is said before anything starts."""
    out = run_wallmap("up", "x.bag", "--connect", stack.endpoint, expect=1)
    assert_one_line_error(out, "up", "cannot start a router", stack.endpoint)


def test_up_on_a_port_out_of_range_is_one_line():
    out = run_wallmap("up", "x.bag", "--connect", "tcp/127.0.0.1:99999", expect=1)
    assert_one_line_error(out, "up", "cannot start a router", "a port is 1-65535")


def test_no_router_is_one_line():
    port = free_port()
    out = run_wallmap("query", "--connect", f"tcp/127.0.0.1:{port}", expect=1)
    assert_one_line_error(out, "query", f"tcp/127.0.0.1:{port}")


def test_bad_zenoh_config_is_one_line(tmp_path):
    config = tmp_path / "z.json5"
    config.write_text("{ mode: 'client', connect: { endpoints: [ } ")
    out = run_wallmap("query", "--zenoh-config", str(config), expect=1)
    assert_one_line_error(out, "query", "z.json5")
    out = run_wallmap("query", "--zenoh-config", str(Path(tmp_path / "absent.json5")), expect=1)
    assert_one_line_error(out, "query", "does not exist")


def test_a_closed_pipe_is_no_error() -> None:
    """`wallmap config | head -1`: the reader went away before the output; exit 0, silently."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "wallmap", "config"], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    assert proc.stdout is not None
    proc.stdout.close()  # before it writes: its first write meets a closed pipe
    _, err = proc.communicate(timeout=60)
    assert (proc.returncode, err.decode()) == (0, "")
