"""Every pose source on one bag, through real processes: the map must not depend on the source.

Accurate sources (tf, a pose topic, a TUM file, an outside publisher at 4x, CDR Odometry or tf
over Zenoh) must give the same precision and recall within 0.02; drifting odometry must still
integrate every frame.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from wallmap.common.link_settings import ZenohSettings
from wallmap.common.transport import open_session
from wallmap.evaluation import MapScore, evaluate_map
from wallmap.scene import write_scene_bag, write_tum

pytestmark = pytest.mark.e2e

N_FRAMES = 450
STORE = get_typestore(Stores.ROS2_HUMBLE)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pose-sources")
    info = write_scene_bag(
        folder / "bag", seed=303, n_frames=N_FRAMES, fmt="ros2-mcap", sensor="depth16"
    )
    tum = folder / "truth.tum"
    write_tum(info.trajectory, tum)
    return info, tum


@pytest.fixture(scope="module")
def reference(scene):
    """The tf run's score, filled in by the first test."""
    return {}


def map_with(stack, bag: Path, *player_args: str, mapper_args: tuple[str, ...] = ()) -> dict:
    stack.start("mapper", "mapper", *mapper_args, *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    played = stack.run("player", str(bag), *player_args, *stack.zenoh_args)
    assert played.returncode == 0, played.stderr
    return stack.query("--min-obs", "3")


def score_of(reply: dict, scene, skipped: int = 0) -> MapScore:
    """The map's score; every frame integrated but the ``skipped`` ones the detector counted."""
    info, _ = scene
    assert reply["frames"] + skipped == info.n_frames
    assert reply["dropped"] == 0
    score = evaluate_map(reply["walls"], info.plan, info.seen_counts)
    print(score.summary())
    return score


def assert_same_map(score: MapScore, reference: dict) -> None:
    ref = reference.get("tf")
    assert ref is not None, "the tf run sets the reference and runs first"
    assert abs(score.precision - ref.precision) <= 0.02
    assert abs(score.recall - ref.recall) <= 0.02
    assert score.duplicates == 0


def test_tf_is_the_reference(stack, scene, reference):
    score = score_of(map_with(stack, scene[0].path, "--fast"), scene)
    assert score.precision >= 0.95
    assert score.recall >= 0.9
    reference["tf"] = score


@pytest.mark.parametrize(
    "spec", ["tf:map>base_link", "pose:/ground_truth", "pose:/amcl_pose", "tum"]
)
def test_bag_and_file_pose_sources(stack, scene, reference, spec):
    info, tum = scene
    source = f"tum:{tum}" if spec == "tum" else spec
    reply = map_with(stack, info.path, "--fast", "--pose-source", source)
    assert_same_map(score_of(reply, scene), reference)


def test_drifting_odometry_integrates_every_frame(stack, scene):
    reply = map_with(stack, scene[0].path, "--fast", "--pose-source", "odom")
    assert reply["frames"] == N_FRAMES
    assert reply["dropped"] == 0
    assert reply["walls"]


def test_outside_publisher_over_zenoh_at_4x(stack, scene, reference):
    info, tum = scene
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    prefix = ["--connect", stack.endpoint, "--prefix", stack.prefix]
    publisher = subprocess.Popen(
        [
            sys.executable,
            str(ROOT / "examples" / "tum_publisher.py"),
            str(tum),
            "--rate",
            "4",
            *prefix,
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    played = stack.run(
        "player",
        str(info.path),
        "--pose-source",
        "none",
        "--rate",
        "4",
        "--wait-for",
        "detector,mapper",
        *stack.zenoh_args,
    )
    assert played.returncode == 0, played.stderr
    assert publisher.wait(timeout=60) == 0
    assert f"published {len(info.trajectory)} poses" in publisher.stdout.read()
    reply, skipped = stack.settled_frames(info.n_frames, "--min-obs", "3")
    assert skipped <= 0.25 * info.n_frames  # real time at 4x: a busy machine skips some
    assert_same_map(score_of(reply, scene, skipped), reference)


def publish_cdr(stack, key: str, payloads: list[bytes]) -> None:
    import zenoh

    with open_session(ZenohSettings(connect=(stack.endpoint,))) as session:
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + 15
        while not pub.matching_status.matching:
            assert time.monotonic() < deadline, "the mapper never subscribed"
            time.sleep(0.05)
        for payload in payloads:
            pub.put(payload)
        time.sleep(0.5)  # let the router forward the tail before the session closes


def odometry_cdr(info) -> list[bytes]:
    t = STORE.types
    out = []
    traj = info.trajectory
    for stamp, x, y, yaw in zip(traj.stamps, traj.x, traj.y, traj.yaw, strict=True):
        sec = math.floor(stamp)
        msg = t["nav_msgs/msg/Odometry"](
            header=t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9)),
                frame_id="map",
            ),
            child_frame_id="base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](
                    position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
                    orientation=t["geometry_msgs/msg/Quaternion"](
                        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
                    ),
                ),
                covariance=np.zeros(36),
            ),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](
                    linear=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                ),
                covariance=np.zeros(36),
            ),
        )
        out.append(bytes(STORE.serialize_cdr(msg, "nav_msgs/msg/Odometry")))
    return out


def test_cdr_odometry_over_zenoh(stack, scene, reference):
    info, _ = scene
    stack.start(
        "mapper",
        "mapper",
        "--pose-key",
        "rt/odom",
        "--pose-format",
        "ros2:nav_msgs/msg/Odometry",
        *stack.zenoh_args,
    )
    stack.start("detector", "detector", *stack.zenoh_args)
    publish_cdr(stack, "rt/odom", odometry_cdr(info))
    played = stack.run(
        "player", str(info.path), "--pose-source", "none", "--fast", *stack.zenoh_args
    )
    assert played.returncode == 0, played.stderr
    assert_same_map(score_of(stack.query("--min-obs", "3"), scene), reference)


def test_cdr_tf_from_the_bag_over_zenoh(stack, scene, reference):
    info, _ = scene
    with AnyReader([info.path]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]
        raw = [(c.topic, bytes(data)) for c, _, data in reader.messages(connections=conns)]
    stack.start(
        "mapper",
        "mapper",
        "--pose-key",
        "rt/tf$*",
        "--pose-format",
        "ros2:tf2_msgs/msg/TFMessage",
        *stack.zenoh_args,
    )
    stack.start("detector", "detector", *stack.zenoh_args)
    publish_cdr(stack, "rt/tf", [data for topic, data in raw if topic == "/tf"])
    played = stack.run(
        "player", str(info.path), "--pose-source", "none", "--fast", *stack.zenoh_args
    )
    assert played.returncode == 0, played.stderr
    assert_same_map(score_of(stack.query("--min-obs", "3"), scene), reference)


def test_laserscan_bag_maps_accurately(stack, tmp_path):
    bag = tmp_path / "scan.bag"
    info = write_scene_bag(bag, seed=404, n_frames=600, fmt="ros1", sensor="laserscan")
    reply = map_with(stack, bag, "--fast")
    assert reply["frames"] == info.n_frames
    score = evaluate_map(reply["walls"], info.plan, info.seen_counts)
    print(score.summary())
    assert score.precision >= 0.95
    assert score.recall >= 0.9
    assert score.duplicates == 0


def test_frames_without_a_pose_are_dropped_counted_and_visible(stack, scene):
    info, _ = scene
    reply = map_with(
        stack, info.path, "--fast", "--pose-source", "none", mapper_args=("--pose-wait", "0.2")
    )
    assert reply["frames"] == 0
    assert reply["dropped"] == N_FRAMES
    assert reply["dropped_reasons"] == {"pose_timeout": N_FRAMES, "no_pose": 0, "backlog": 0}
