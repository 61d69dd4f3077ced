"""Real RGB-D recordings as people bring them: a TUM folder, a 6-DoF tf bag, a robot's bag.

The kitchen (7-Scenes redkitchen) is a handheld Kinect in a frame that is not level; the cabinet
(TUM fr3) a 0.6 m cabinet in an empty hall, whose honest map has no wall. No wall truth exists,
so the checks are what the data can tell: every frame integrated, the frame levelled with its
floor found, no fan or duplicate, the long wall behind the counter found, few walls, points
at wall height lying on mapped walls. Real services, a real router, `wallmap up` as a user runs it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import free_port, run_wallmap

from wallmap.common.map_consistency import MappedWall, distance_to_walls, duplicates, fans
from wallmap.doctor_inspect import inspect_tum
from wallmap.offline import points_at_heights
from wallmap.recordings import RGBD, DepthCamera, tum_as_bag
from wallmap.services.player.sources import SourceSettings

pytestmark = pytest.mark.e2e


def recording(name: str) -> tuple[Path, DepthCamera]:
    folder, camera = RGBD[name]
    if not folder.is_dir():
        pytest.skip(f"real recording {folder} is absent (shared data not mounted beside the repo)")
    return folder, camera


def camera_flags(camera: DepthCamera) -> list[str]:
    fx, fy, cx, cy = camera.intrinsics
    return ["--intrinsics", f"{fx},{fy},{cx},{cy}", "--depth-scale", f"{camera.depth_scale:g}"]


def up(path: Path, out: Path, *flags: str, fast: bool = True) -> dict:
    """`wallmap up` on a private port, as a user runs it (``fast``: ``--fast``); its final map."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    pace = ["--fast"] if fast else []
    run_wallmap(
        "up",
        str(path),
        *pace,
        "--exit-when-done",
        "--json-out",
        str(out),
        "--connect",
        endpoint,
        *flags,
        timeout=240,
    )
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def kitchen_ways(tmp_path_factory):
    """The kitchen the three ways: (recording, flags, options to read it offline)."""
    folder, camera = recording("redkitchen")
    tmp = tmp_path_factory.mktemp("kitchen")
    options = SourceSettings(intrinsics=camera.intrinsics, depth_scale=camera.depth_scale)
    six_dof = tum_as_bag(folder, tmp / "6dof.bag", camera, way="tf-6dof")
    planar = tum_as_bag(folder, tmp / "planar.bag", camera, way="planar-base")
    return {
        "tum-folder": (folder, camera_flags(camera), options),
        "tf-6dof": (six_dof, [], SourceSettings()),
        "planar-base": (planar, [], SourceSettings()),
    }


@pytest.mark.parametrize("way", ["tum-folder", "tf-6dof", "planar-base"])
def test_the_real_kitchen_maps_the_same_whichever_way_it_comes(kitchen_ways, way, tmp_path):
    path, flags, options = kitchen_ways[way]
    reply = up(path, tmp_path / "map.json", *flags)
    assert reply["frames"] == 50, "every frame integrated"
    walls = [MappedWall.from_reply(w) for w in reply["walls"]]
    assert 1 <= len(walls) <= 12
    assert fans(walls) == []
    assert duplicates(walls) == []
    longest = max(walls, key=lambda w: w.length)
    assert longest.length >= 1.5, "the wall behind the counter, along most of its length"
    seen = points_at_heights(path, source=options)
    on_walls = float((distance_to_walls(seen, walls) < 0.05).mean())
    print(f"\n{way}: {len(walls)} walls, {on_walls:.0%} of the points at 0.9-1.6 m on them")
    assert on_walls >= 0.3


def kitchen_bag() -> Path:
    """The kitchen as a handheld camera's user records it: 6-DoF tf, LZ4 chunks."""
    bag = RGBD["redkitchen"][0].parent / "redkitchen_150_199.bag"
    if not bag.exists():
        pytest.skip(f"real recording {bag} is absent")
    return bag


def test_the_kitchen_bag_played_in_real_time_maps_every_frame(tmp_path) -> None:
    """The default pace, as a live camera delivers its frames: nothing lost, a clean exit."""
    reply = up(kitchen_bag(), tmp_path / "map.json", fast=False)
    assert reply["frames"] == 50, "every frame integrated"
    walls = [MappedWall.from_reply(w) for w in reply["walls"]]
    assert 1 <= len(walls) <= 12
    assert fans(walls) == []
    assert duplicates(walls) == []
    assert max(w.length for w in walls) >= 1.5, "the wall behind the counter"


def test_the_kitchen_bag_with_6dof_tf_needs_no_pose_source_and_the_doctor_says_so() -> None:
    bag = kitchen_bag()
    doctor = run_wallmap("doctor", str(bag))
    assert "tf:map>camera_link" in doctor.stdout
    # The default is judged as the player takes it: it follows the chain to the camera.
    text = " ".join(doctor.stdout.split())  # as one line, wherever the report wrapped it
    assert "the player plays all the same" in text
    assert "choose another --pose-source" not in text
    assert "tilted" in doctor.stdout
    assert "floor at" in doctor.stdout
    assert "ready:" in doctor.stdout


def test_the_cabinet_in_an_empty_hall_is_no_wall(tmp_path) -> None:
    folder, camera = recording("tum_fr3_cabinet")
    reply = up(folder, tmp_path / "map.json", *camera_flags(camera))
    assert reply["frames"] == 58
    assert reply["walls"] == [], "furniture is not a wall"


def test_the_level_and_floor_of_the_kitchen_are_found() -> None:
    folder, camera = recording("redkitchen")
    seen = points_at_heights(
        folder,
        (-0.1, 0.05),
        SourceSettings(intrinsics=camera.intrinsics, depth_scale=camera.depth_scale),
    )
    assert len(seen) > 1000, "the floor lies at z = 0 once levelled"
    assert np.isfinite(seen).all()


def test_the_kitchen_folder_with_default_flags_says_what_to_give(tmp_path) -> None:
    """Its depth.txt says millimetres, which is taken; the camera's intrinsics nothing says, and
    with TUM's the detector sees no line: the run says so in one line, naming the flags."""
    folder, _ = recording("redkitchen")
    out = tmp_path / "map.json"
    done = run_wallmap(
        "up",
        str(folder),
        "--fast",
        "--exit-when-done",
        "--json-out",
        str(out),
        "--connect",
        f"tcp/127.0.0.1:{free_port()}",
        timeout=240,
    )
    reply = json.loads(out.read_text())
    assert reply["config"]["player"]["source"].get("depth_scale") is None  # the folder's own
    assert reply["observations"] == 0
    said = [line for line in done.stderr.splitlines() if "no line was seen" in line]
    assert len(said) == 1, done.stderr
    assert "--intrinsics" in said[0]
    assert "--depth-scale" in said[0]


def test_the_doctor_asks_for_the_kitchen_folder_s_camera() -> None:
    """With TUM's intrinsics no frame of the kitchen sees its floor: the doctor asks for the
    camera instead of saying ready; with the recording's own it is ready."""
    folder, camera = recording("redkitchen")
    guessed = inspect_tum(folder, SourceSettings())
    assert guessed.verdict.status == "check-camera"
    assert "--intrinsics FX,FY,CX,CY" in guessed.verdict.text
    given = inspect_tum(folder, SourceSettings(intrinsics=camera.intrinsics))
    assert given.verdict.status == "ready"
    assert "--depth-scale 1000" in given.verdict.text  # what its depth.txt says


def test_the_doctors_command_for_a_tum_folder_keeps_the_pose_source_it_was_given(
    tmp_path: Path,
) -> None:
    """``--pose-source tum:FILE`` given: the ``wallmap up`` it recommends plays with it too
    (it used to leave it out, and so mapped with the folder's own trajectory)."""
    folder, camera = recording("redkitchen")
    other = tmp_path / "poses.txt"
    other.write_text((folder / "groundtruth.txt").read_text())
    how = SourceSettings(intrinsics=camera.intrinsics, pose_source=f"tum:{other}")
    report = inspect_tum(folder, how)
    assert report.verdict.status == "ready"
    assert report.verdict.command is not None
    assert f"--pose-source tum:{other}" in report.verdict.command
    default = inspect_tum(folder, SourceSettings(intrinsics=camera.intrinsics))
    assert "--pose-source" not in (default.verdict.command or "")
