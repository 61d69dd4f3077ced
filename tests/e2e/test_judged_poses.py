"""Poses as real systems give them, through ``wallmap up`` as a user runs it: real processes.

The Jackal's motion-capture poses (late, about a degree off while turning, dropping out) and
the project's scan matching on the same run: one wall a surface, the scans on the walls, every
frame taken, in real time as under ``--fast``. And a generated bag posed from a TUM file 80 ms
late, 0.5 degree noisy and 3 s off by 12 degrees: scored against its truth.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import free_port, real_bag, run_wallmap

from wallmap.common.map_consistency import MappedWall, distance_to_walls, fans
from wallmap.common.se2 import transform_points
from wallmap.evaluation import evaluate_map
from wallmap.offline import scan_rows
from wallmap.scene import Glitch, PoseFaults, load_truth, write_scene_bag
from wallmap.scene.bags import tum_path_for

pytestmark = pytest.mark.e2e

JACKAL = "jackal_arena_2026-02-17-15-54-31"
MOCAP = "pose:/vrpn_client_node/jackal/pose"


def _up(bag: Path, out: Path, *flags: str, timeout: float = 180.0) -> dict:
    """``wallmap up`` to the end of the bag: its map reply, the run checked clean."""
    port = free_port()
    done = run_wallmap(
        "up",
        str(bag),
        "--exit-when-done",
        "--json-out",
        str(out),
        "--connect",
        f"tcp/127.0.0.1:{port}",
        *flags,
        timeout=timeout,
    )
    assert "error" not in done.stderr.lower(), done.stderr
    return json.loads(out.read_text())


def _explained(reply: dict, bag: Path) -> float:
    """The share of the scans' points within 5 cm of a served wall, placed with the poses the
    mapper used (its trajectory, interpolated at each scan)."""
    walls = [MappedWall.from_reply(w) for w in reply["walls"]]
    stamps, x, y, yaw = np.array(reply["trajectory"]).T
    yaw = np.unwrap(yaw)
    distances = []
    for stamp, xy in scan_rows(bag):
        pose = [np.interp(stamp, stamps, value) for value in (x, y, yaw)]
        distances.append(distance_to_walls(transform_points(xy, pose), walls))
    return float(np.mean(np.concatenate(distances) <= 0.05))


# The defaults take the motion capture (the bag's only pose topic): the same run as naming it,
# which the real-time run does.
JACKAL_RUNS = [
    ("defaults", ("--fast",)),
    ("motion capture, real time", ("--pose-source", MOCAP)),
    ("scan matching", ("--fast", "--odometry")),
]


@pytest.mark.parametrize(("label", "flags"), JACKAL_RUNS, ids=[r[0] for r in JACKAL_RUNS])
def test_the_jackal_arena_maps_as_six_walls(tmp_path: Path, label: str, flags) -> None:
    bag = real_bag(JACKAL)
    reply = _up(bag, tmp_path / "map.json", *flags)
    walls = [MappedWall.from_reply(w) for w in reply["walls"]]
    explained = _explained(reply, bag)
    scans = sum(1 for _ in scan_rows(bag))
    print(
        f"\n{label}: {len(walls)} walls, {len(fans(walls))} fans, {explained:.1%} of the scan "
        f"points within 5 cm; {reply.get('pose_source')}"
    )
    assert reply["frames"] == scans, "every frame integrated"
    assert reply["dropped"] == 0
    assert len(walls) <= 8
    assert fans(walls) == []
    assert explained >= 0.8
    found = reply["pose_source"]
    assert found["frames_corrected"] >= 0.7 * scans
    if "--odometry" in flags:
        assert found["latency_fixed"]  # scan matching poses its own frames: latency 0
    # The arena is one L-shaped room: one closed room, no door, of the walls' area.
    rooms = reply["rooms"]
    assert len(rooms["rooms"]) == 1
    assert rooms["doors"] == []
    (room,) = rooms["rooms"]
    assert room["closed"]
    assert room["area"] == pytest.approx(_area_walled(reply["walls"]), rel=0.05)


def _area_walled(walls: list[dict]) -> float:
    """The area of the polygon the walls' ends chain into (each end meets the next wall's)."""
    left = [np.array([w["p0"], w["p1"]]) for w in walls if not w.get("tentative")]
    chain = [left[0][0], left[0][1]]
    left = left[1:]
    while left:
        k, end = min(
            ((k, e) for k, w in enumerate(left) for e in (0, 1)),
            key=lambda ke: np.hypot(*(left[ke[0]][ke[1]] - chain[-1])),
        )
        chain.append(left.pop(k)[1 - end])
    x, y = np.array(chain).T
    return abs(0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def test_a_late_noisy_glitching_tum_file_still_maps_the_scene(tmp_path: Path) -> None:
    """The held-back case's kind: 80 ms late, 0.5 deg noise, 3 s 12 deg and 10 cm off."""
    faults = PoseFaults(
        latency=0.08, heading_sd_deg=0.5, glitches=(Glitch(15, 3, 12, 0.1),), seed=3
    )
    info = write_scene_bag(
        tmp_path / "late.bag", seed=3, n_frames=600, fmt="ros1", sensor="depth16", faults=faults
    )
    reply = _up(
        info.path,
        tmp_path / "map.json",
        "--fast",
        "--pose-source",
        f"tum:{tum_path_for(info.path)}",
        "--truth",
        str(info.truth_path),
    )
    plan, _, seen = load_truth(info.truth_path)
    score = evaluate_map(
        [MappedWall.from_reply(w) for w in reply["walls"]] and reply["walls"], plan, seen
    )
    found = reply["pose_source"]
    print(f"\n{score.summary()}; {found}")
    assert reply["frames"] == info.n_frames
    assert score.precision >= 0.98
    assert score.recall >= 0.95
    assert score.duplicates == 0
    assert score.median_offset_m <= 0.015
    assert found["latency_s"] == pytest.approx(0.08, abs=0.01)
    assert found["frames_recovered"] + found["frames_refused"] > 0


def test_trust_poses_and_a_given_latency_do_what_they_say(tmp_path: Path) -> None:
    bag = real_bag(JACKAL)
    trusted = _up(bag, tmp_path / "trusted.json", "--fast", "--pose-source", MOCAP, "--trust-poses")
    assert "pose_source" not in trusted, "nothing judged"
    given = _up(
        bag, tmp_path / "given.json", "--fast", "--pose-source", MOCAP, "--pose-latency", "-0.03"
    )
    assert given["pose_source"]["latency_fixed"]
    assert given["pose_source"]["latency_s"] == -0.03
