"""``wallmap doctor`` on the real recordings, generated scenes and bags written here with a pose
gap, clock jumps, several sensors or damage: the account must match the bag and the player."""

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bag_records import Record, write_records
from conftest import real_bag
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from wallmap.cli import main as wallmap_main
from wallmap.doctor import add_command, report_json
from wallmap.doctor_facts import Report
from wallmap.doctor_inspect import inspect_bag
from wallmap.doctor_text import render_text
from wallmap.options import given
from wallmap.scene import write_scene_bag
from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.errors import PlayerError

T0 = 1_700_000_000  # header stamps, seconds
STORE = get_typestore(Stores.ROS1_NOETIC)
STORE.register(  # tf2's message is not among the noetic typestore's built-in types
    get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
)
TYPES = STORE.types


def fits_one_screen(text: str) -> None:
    lines = text.splitlines()
    assert len(lines) <= 40, text
    assert max(len(line) for line in lines) <= 100, text


def run(path: Path, *options: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    status = wallmap_main(["doctor", str(path), *options])
    return status, capsys.readouterr().out


def unwrapped(text: str) -> str:
    """The report with each wrapped fact back on one line."""
    return text.replace("\n" + " " * 9, " ")


def flat(text: str) -> str:
    """Text without any whitespace, to find a wrapped sentence in the report."""
    return "".join(text.split())


def player_error(path: Path, **options: Any) -> str:
    with pytest.raises(PlayerError) as err:
        BagSource(path, **options)
    return str(err.value)


# --- bags written here --------------------------------------------------------------------------


def header(stamp: float, frame: str) -> Any:
    sec = math.floor(stamp)
    time = TYPES["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9))
    return TYPES["std_msgs/msg/Header"](seq=0, stamp=time, frame_id=frame)


def scan(stamp: float, frame: str = "laser") -> Any:
    ranges = np.full(90, 2.0, dtype=np.float32)
    ranges[::3] = np.inf  # a third without a return
    return TYPES["sensor_msgs/msg/LaserScan"](
        header=header(stamp, frame),
        angle_min=-math.pi / 4,
        angle_max=math.pi / 4,
        angle_increment=math.pi / 2 / 89,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=10.0,
        ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )


def pose(x: float) -> Any:
    return TYPES["geometry_msgs/msg/Pose"](
        position=TYPES["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0),
        orientation=TYPES["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )


def tf(stamp: float, *edges: tuple[str, str]) -> Any:
    transforms = [
        TYPES["geometry_msgs/msg/TransformStamped"](
            header=header(stamp, parent),
            child_frame_id=child,
            transform=TYPES["geometry_msgs/msg/Transform"](
                translation=TYPES["geometry_msgs/msg/Vector3"](x=0.1, y=0.0, z=0.0),
                rotation=TYPES["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )
        for parent, child in edges
    ]
    return TYPES["tf2_msgs/msg/TFMessage"](transforms=transforms)


def odometry(stamp: float, child: str = "base_link") -> Any:
    twist = TYPES["geometry_msgs/msg/TwistWithCovariance"](
        twist=TYPES["geometry_msgs/msg/Twist"](
            linear=TYPES["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            angular=TYPES["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        ),
        covariance=np.zeros(36),
    )
    return TYPES["nav_msgs/msg/Odometry"](
        header=header(stamp, "odom"),
        child_frame_id=child,
        pose=TYPES["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose(stamp - T0), covariance=np.zeros(36)
        ),
        twist=twist,
    )


def write_bag(path: Path, records: list[Record]) -> Path:
    """A ROS 1 bag of the records, in receive-time order."""
    return write_records(path, STORE, sorted(records, key=lambda r: r.receive))


SCAN, TF, ODOM = "sensor_msgs/msg/LaserScan", "tf2_msgs/msg/TFMessage", "nav_msgs/msg/Odometry"


def troubled_bag(path: Path) -> Path:
    """50 scans at 10 Hz whose header stamps step back once (at 2.0 s) and jump 1.6 s (at 3.9 s);
    tf map -> odom -> base_link only over 0-1.5 s and 3-4 s; /odom over the whole bag."""
    return write_bag(path, troubled_bag_records())


def troubled_bag_records() -> list[Record]:
    """``troubled_bag``'s records, in receive-time order."""
    records = [Record("/tf_static", TF, tf(T0, ("base_link", "laser")), T0)]
    for i in range(50):
        stamp = T0 + 0.1 * i if i < 40 else T0 + 5.5 + 0.1 * (i - 40)
        if i == 21:
            stamp = T0 + 1.95  # after 2.0
        records.append(Record("/scan", SCAN, scan(stamp), stamp + 0.02 if i != 21 else T0 + 2.12))
    for i in range(41):
        stamp = T0 + 0.1 * i
        if 1.5 < stamp - T0 < 3.0 - 1e-6:
            continue
        edges = (("map", "odom"), ("odom", "base_link"))
        records.append(Record("/tf", TF, tf(stamp, *edges), stamp))
    for i in range(70):
        stamp = T0 + 0.1 * i
        records.append(Record("/odom", ODOM, odometry(stamp), stamp + 0.01))
    return sorted(records, key=lambda r: r.receive)


# --- the command --------------------------------------------------------------------------------


def test_add_command_adds_doctor_to_wallmap_subcommands() -> None:
    parser = argparse.ArgumentParser(prog="wallmap")
    add_command(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["doctor", "some.bag", "--json", "--sensor-topic", "/scan"])
    assert (args.bag, args.json) == (Path("some.bag"), True)
    assert given(args, args.options) == {"player": {"source": {"sensor_topic": "/scan"}}}
    assert callable(args.func)


def test_missing_bag_is_one_error_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert wallmap_main(["doctor", str(tmp_path / "nowhere.bag")]) == 1
    err = capsys.readouterr().err
    assert err == f"wallmap doctor: error: bag not found: {tmp_path / 'nowhere.bag'}\n"


# --- real recordings ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "frames", "frame_id"),
    [("hallway.bag", 881, "laser_frame"), ("eng403_good.bag", 487, "laser")],
)
def test_real_scan_only_bags_point_to_odometry(
    name: str, frames: int, frame_id: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = real_bag(name)
    status, text = run(path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    assert "sensor   scan (sensor_msgs/msg/LaserScan): the only usable sensor topic" in text
    assert f"{frames} frames at " in text
    assert "360-beam LaserScan" in text
    assert "tf       none (no /tf or /tf_static)" in text
    assert "no odometry or pose topics" in text
    assert flat(player_error(path)) in flat(text)  # the default tf, refused in the player's words
    assert f"(`wallmap up {path} --fast --odometry`)" in unwrapped(text)

    status, out = run(path, "--json", capsys=capsys)
    facts = json.loads(out)
    assert status == facts["exit_status"] == 0
    sensor = facts["sensor"]
    assert (sensor["topic"], sensor["type"], sensor["frames"]) == ("scan", SCAN, frames)
    assert sensor["frame_ids"] == {frame_id: frames}
    assert sensor["geometry"]["beams"] == 360
    assert 0.2 < sensor["invalid"] < 0.4  # low-cost lidars: about 30 % without a return
    assert facts["tf"]["edges"] == []
    assert [c["found"] for c in facts["tf"]["chains"]] == [False, False, False]
    assert [p["source"] for p in facts["poses"]] == ["tf:map>base_link"]
    assert facts["poses"][0]["available"] is False
    assert facts["verdict"]["status"] == "no-poses"
    assert facts["verdict"]["command"] == f"wallmap up {path} --fast --odometry"
    assert "identity sensor mounting" in facts["warnings"][0]
    assert facts["clock"][0]["backward"]["count"] == facts["clock"][0]["jumps"]["count"] == 0


@pytest.mark.parametrize(
    ("name", "magic"),
    [
        ("lsm_demo_2010.bag", "#ROSBAG V2.0"),
        ("sparsifier_demo_rosrecord_v1.2.bag", "#ROSRECORD V1.2"),
    ],
)
def test_real_bags_the_player_refuses(
    name: str, magic: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = real_bag(name)
    reason = player_error(path)
    status, text = run(path, capsys=capsys)
    assert status == 1
    fits_one_screen(text)
    assert f"magic {magic!r}" in text
    assert flat(f"verdict  cannot be played: {reason}") in flat(text)
    facts = json.loads(run(path, "--json", capsys=capsys)[1])
    assert facts["exit_status"] == 1
    assert facts["readable"] is False
    assert facts["verdict"] == {
        "status": "refused",
        "text": f"cannot be played: {reason}",
        "command": None,
    }
    assert facts["file"]["size"] == path.stat().st_size


def test_real_damaged_index_keeps_its_bag_header(capsys: pytest.CaptureFixture[str]) -> None:
    path = real_bag("lsm_demo_2010.bag")
    facts = json.loads(run(path, "--json", capsys=capsys)[1])
    assert facts["file"]["format"] == "ros1"
    assert facts["file"]["ros1_header"] == {
        "chunk_count": 2,
        "conn_count": 1,
        "index_pos": 1_029_025,
    }


@pytest.mark.parametrize(
    ("compression", "said"),
    [(None, "uncompressed"), ("LZ4", "LZ4 chunks"), ("BZ2", "bz2 chunks")],
)
def test_the_bag_line_says_how_its_chunks_are_compressed(
    compression: str | None, said: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """How fast the player reads a ROS 1 bag depends on it; a bz2 bag is told how to speed up."""
    packing = None if compression is None else Writer1.CompressionFormat[compression]
    path = write_records(tmp_path / "scans.bag", STORE, troubled_bag_records(), None, packing)
    text = run(path, capsys=capsys)[1]
    assert f"ROS 1 bag 2.0, {said}, " in text
    assert ("rosbag decompress" in unwrapped(text)) is (compression == "BZ2")
    facts = json.loads(run(path, "--json", capsys=capsys)[1])
    assert facts["chunks"] == (compression or "none").lower()


def test_a_ros2_bag_has_no_chunk_compression(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "scene"
    write_scene_bag(path, seed=3, n_frames=4, fmt="ros2-mcap", sensor="laserscan")
    line = run(path, capsys=capsys)[1].splitlines()[1]
    assert "ROS 2 mcap, " in line
    assert "chunks" not in line
    assert "uncompressed" not in line
    assert json.loads(run(path, "--json", capsys=capsys)[1])["chunks"] is None


@pytest.mark.parametrize("damage", ["cut", "no-equals"])
def test_a_damaged_bag_header_is_left_out(
    damage: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bag header that is itself damaged says nothing: no header line, the player's reason."""
    good = write_bag(tmp_path / "good.bag", [Record("/scan", SCAN, scan(T0), T0)])
    data = good.read_bytes()
    start = data.index(b"\n") + 1 + 4  # the header record's first field
    if damage == "cut":
        data = data[: start + 10]
    else:  # the first field's '=' gone: a field rosbags refuses too
        data = data[:start] + data[start:].replace(b"=", b"_", 1)
    path = tmp_path / "damaged.bag"
    path.write_bytes(data)
    status, text = run(path, capsys=capsys)
    assert status == 1
    assert "bag header" not in text
    assert flat(f"verdict  cannot be played: {player_error(path)}") in flat(text)
    facts = json.loads(run(path, "--json", capsys=capsys)[1])
    assert facts["file"]["format"] == "ros1"
    assert facts["file"]["ros1_header"] is None


def test_real_nav2_bag_has_poses_but_no_sensor(capsys: pytest.CaptureFixture[str]) -> None:
    path = real_bag("nav2_turtlebot.mcap")
    status, text = run(path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    assert "ROS 2 mcap" in text
    assert "sensor   none: no usable sensor topic" in text
    assert "map -> base_link: map -> odom -> base_link (dynamic, dynamic)" in text
    assert "header stamps 20581.4 days behind receive times" in text  # simulation time
    assert "cannot be played: no usable sensor topic; it holds poses only" in text

    facts = json.loads(run(path, "--json", capsys=capsys)[1])
    assert facts["exit_status"] == 0
    assert facts["sensor"]["topic"] is None
    assert [t["count"] for t in facts["topics"]] == [135, 2639, 5422, 1]
    poses = {p["source"]: p for p in facts["poses"]}
    assert set(poses) == {"tf:map>base_link", "tf:odom>base_link", "odom:/odom", "pose:/amcl_pose"}
    for source, samples in [("odom:/odom", 2639), ("pose:/amcl_pose", 135)]:
        assert poses[source]["available"] is True
        assert poses[source]["samples"] == samples
        assert poses[source]["end"] - poses[source]["start"] > 90  # covers the 97 s recording
        assert poses[source]["player"] is None  # no sensor to open the bag with
        assert poses[source]["frames_with_pose"] is None
    tf_pose = poses["tf:map>base_link"]
    assert tf_pose["default"] is True
    assert tf_pose["samples"] == 921  # map -> odom, AMCL's, is the sparser link
    # map -> odom and odom -> base_link stall together around 46 s: one merged gap of ~3.1 s.
    assert tf_pose["gaps"]["largest"]["length"] == pytest.approx(3.076, abs=0.01)
    edges = {(e["parent"], e["child"]): e for e in facts["tf"]["edges"]}
    assert edges[("map", "odom")]["static"] is False
    assert edges[("odom", "base_link")]["samples"] == 2639
    assert edges[("base_link", "shell_link")]["static"] is True
    assert facts["verdict"]["status"] == "no-sensor"


def test_real_tf_example_bag(capsys: pytest.CaptureFixture[str]) -> None:
    path = real_bag("tf_example.bag")
    status, text = run(path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    assert "odom -> base_link: odom -> base_footprint -> base_link (dynamic, static)" in text
    assert "map -> base_link: missing ('map' is not in tf)" in text
    facts = json.loads(run(path, "--json", capsys=capsys)[1])
    assert facts["tf"]["frames"] == ["base_footprint", "base_link", "odom"]
    assert [(e["parent"], e["child"], e["static"]) for e in facts["tf"]["edges"]] == [
        ("odom", "base_footprint", False),
        ("base_footprint", "base_link", True),
    ]
    assert facts["sensor"]["topic"] is None
    assert facts["verdict"]["status"] == "no-sensor"


# --- generated scenes ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fmt", "sensor", "topic"),
    [
        ("ros1", "pointcloud", "/camera/depth/points"),
        ("ros2-mcap", "depth16", "/camera/depth/image_raw"),
    ],
)
def test_generated_scene_is_ready(
    tmp_path: Path, fmt: str, sensor: str, topic: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / ("scene.bag" if fmt == "ros1" else "scene")  # ROS 2: a folder
    info = write_scene_bag(out, seed=11, n_frames=60, fmt=fmt, sensor=sensor)
    status, text = run(info.path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    assert f"verdict  ready: `wallmap up {info.path} --fast`" in unwrapped(text)
    assert (
        "camera_optical_frame -> base_link: camera_optical_frame -> camera_link -> base_link"
        in text
    )
    assert "map -> base_link: map -> odom -> base_link (dynamic, dynamic)" in text

    report = inspect_bag(info.path)
    assert report.sensor is not None
    assert (report.sensor.topic, report.sensor.frames) == (topic, info.n_frames)
    assert report.sensor.geometry["width"] == 160
    assert all(chain.found for chain in report.tf.chains)
    assert [p.source for p in report.poses] == [
        "tf:map>base_link",
        "tf:odom>base_link",
        "odom:/odom",
        "pose:/amcl_pose",
        "pose:/ground_truth",
    ]
    for p in report.poses:
        assert (p.available, p.player, p.frames_with_pose) == (True, "ok", info.n_frames)
        assert p.gaps.count == 0
    assert [c.backward.count + c.jumps.count for c in report.clock] == [0] * 4
    assert report.verdict.command == f"wallmap up {info.path} --fast"
    assert report.warnings == []


# --- troubled bags ------------------------------------------------------------------------------


def test_pose_gap_and_clock_jumps_are_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = troubled_bag(tmp_path / "troubled.bag")
    status, text = run(path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    text = unwrapped(text)
    assert "1 step back in header stamps (largest -0.05 s at 2.0 s)" in text
    assert "1 jump > 1 s in header stamps (largest 1.6 s at 3.9 s)" in text
    assert "1 jump > 1 s in receive times" in text
    assert "frames in gaps (poses interpolated over > 0.5 s): 14 with tf:map>base_link" in text

    report = inspect_bag(path)
    poses = {p.source: p for p in report.poses}
    tf_pose = poses["tf:map>base_link"]
    assert tf_pose.gaps.count == 1
    assert tf_pose.gaps.largest is not None
    assert tf_pose.gaps.largest.start == pytest.approx(1.5)
    assert tf_pose.gaps.largest.length == pytest.approx(1.5)
    assert tf_pose.frames_with_pose == 40  # none after tf ends at 4.0 s (+ 0.05 s tolerance)
    assert tf_pose.frames_in_gaps == 14  # 1.6 .. 2.9 s
    assert poses["odom:/odom"].frames_with_pose == 50
    clock = report.clock[0]
    assert clock.topic == "/scan"
    assert clock.backward.count == 1
    assert clock.jumps.count == 1
    assert clock.jumps.largest is not None
    assert clock.jumps.largest.length == pytest.approx(1.6)
    # Odometry poses every frame, tf only 80 %: the verdict takes the better source.
    assert report.verdict.status == "ready"
    assert report.verdict.command == f"wallmap up {path} --fast --pose-source odom:/odom"


def test_pose_source_the_player_refuses_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Odometry of base_footprint, a frame tf does not know: the player cannot mount the laser."""
    records = [Record("/tf_static", TF, tf(T0, ("base_link", "laser")), T0)]
    for i in range(20):
        stamp = T0 + 0.1 * i
        records.append(Record("/scan", SCAN, scan(stamp), stamp + 0.02))
        records.append(Record("/odom", ODOM, odometry(stamp, "base_footprint"), stamp + 0.01))
    path = write_bag(tmp_path / "footprint.bag", records)
    reason = player_error(path, pose_source="odom")
    status, text = run(path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    assert flat(f"player: {reason}") in flat(text)
    report = inspect_bag(path)
    assert {p.source: p.player for p in report.poses}["odom:/odom"] == reason
    assert report.verdict.status == "no-poses"


def test_several_sensor_topics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    records = []
    for i in range(10):
        stamp = T0 + 0.1 * i
        records.append(Record("/front/scan", SCAN, scan(stamp, "front"), stamp))
        records.append(Record("/rear/scan", SCAN, scan(stamp, "rear"), stamp))
    path = write_bag(tmp_path / "two.bag", records)
    status, text = run(path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    assert flat(player_error(path, pose_source="none")) in flat(text)
    assert "choose a sensor topic" in text

    report = inspect_bag(path, sensor_topic="/rear/scan")
    assert report.sensor is not None
    assert (report.sensor.topic, report.sensor.frame_ids) == ("/rear/scan", {"rear": 10})
    assert report.sensor.invalid == pytest.approx(30 / 90)
    assert report.verdict.command == (
        f"wallmap up {path} --fast --sensor-topic /rear/scan --odometry"
    )


def test_a_busy_bag_still_fits_one_screen(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Nine odometry topics on nine clocks and a dozen unused topics: the report keeps to its
    caps, and lists the sensor and tf topics before the unused ones."""
    records = [Record("/tf_static", TF, tf(T0, ("base_link", "laser")), T0)]
    string = "std_msgs/msg/String"
    for i in range(10):
        stamp = T0 + 0.1 * i
        records.append(Record("/scan", SCAN, scan(stamp), stamp))
        for k in range(9):
            late = stamp + 0.01 * (k + 1)  # a different offset for each: no two read the same
            records.append(Record(f"/odom{k}", ODOM, odometry(stamp), late))
        for k in range(12):
            records.append(Record(f"/chatter{k}", string, TYPES[string](data="hi"), stamp))
    path = write_bag(tmp_path / "busy.bag", records)
    status, text = run(path, capsys=capsys)
    assert status == 0
    fits_one_screen(text)
    assert "/scan " in text
    assert "/tf_static " in text
    assert "... and 15 more topics" in text
    assert "... and 4 more pose sources" in text
    assert "odom:/odom0 " in text
    facts = json.loads(run(path, "--json", capsys=capsys)[1])
    assert len(facts["topics"]) == 23
    assert len(facts["poses"]) == 10


def test_damaged_sensor_data_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    records = [Record("/scan", SCAN, scan(T0 + i), T0 + i) for i in range(50)]
    good = write_bag(tmp_path / "good.bag", records)
    corrupt = bytearray(good.read_bytes())
    corrupt[len(corrupt) // 2 : len(corrupt) // 2 + 1000] = b"\xff" * 1000
    path = tmp_path / "corrupt.bag"
    path.write_bytes(corrupt)
    # The index is intact, so the player opens the bag and fails on a frame.
    with BagSource(path, pose_source="none") as source, pytest.raises(PlayerError) as err:
        list(source.frames())
    status, text = run(path, capsys=capsys)
    assert status == 1
    fits_one_screen(text)
    assert flat(f"cannot be played: {err.value}") in flat(text)


def test_json_and_text_say_the_same(tmp_path: Path) -> None:
    path = troubled_bag(tmp_path / "troubled.bag")
    report = inspect_bag(path)
    facts = json.loads(report_json(report))
    text = render_text(report)
    assert facts["verdict"]["text"] in unwrapped(text)
    assert facts["sensor"]["frames"] == 50
    assert facts["t0"] == pytest.approx(T0)
    assert Report.__dataclass_fields__.keys() <= facts.keys()


def test_the_pose_source_given_is_the_one_judged(tmp_path: Path) -> None:
    """`wallmap doctor BAG --pose-source SPEC`: the verdict is the player's for SPEC."""
    info = write_scene_bag(
        tmp_path / "scene.bag", seed=11, n_frames=30, fmt="ros1", sensor="depth16"
    )
    path = str(info.path)
    verdicts = {}
    for spec in ("pose:/nonexistent", "bogus", "none", "odom", "pose:/amcl_pose"):
        report = inspect_bag(info.path, pose_source=spec)
        verdicts[spec] = (report.exit_status, report.verdict.status, report.verdict.text)
    assert verdicts["pose:/nonexistent"][:2] == (1, "refused")
    assert "the bag has no such poses (it has: tf:map>base_link" in verdicts["pose:/nonexistent"][2]
    assert verdicts["bogus"][:2] == (1, "refused")
    assert "invalid pose source 'bogus'" in verdicts["bogus"][2]
    assert verdicts["none"][:2] == (0, "ready")
    assert f"`wallmap up {path} --fast --pose-source none`" in verdicts["none"][2]
    assert verdicts["odom"] == (0, "ready", f"ready: `wallmap up {path} --fast --pose-source odom`")
    assert verdicts["pose:/amcl_pose"][:2] == (0, "ready")
    assert inspect_bag(info.path).verdict.text == f"ready: `wallmap up {path} --fast`"


def test_the_level_and_floor_given_are_the_ones_the_placement_is_made_with(tmp_path: Path) -> None:
    """`wallmap doctor BAG --level none --floor-z Z`: each source placed as the player would be
    told to (they were read, and the placement made with the defaults)."""
    info = write_scene_bag(
        tmp_path / "scene.bag", seed=11, n_frames=30, fmt="ros1", sensor="depth16"
    )
    found = inspect_bag(info.path).poses[0].placement
    given = inspect_bag(info.path, level="none", floor_z=0.5).poses[0].placement
    assert "floor at" in found
    assert given is not None
    assert "floor at" not in given, "the floor given, not found"
    assert "level" not in given, "taken as it is"
