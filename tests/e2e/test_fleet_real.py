"""A fleet on a real recording: the Jackal arena played as two robots, aligned by the walls.

Robot A: the recording's first 22 s, posed by the motion capture (the arena's frame). Robot B:
from 18 s on, posed by scan matching alone (``wallmap odometry``: its frame is where its first
scan was taken), behind its own router joined to A's. ``wallmap merge`` must find where B's
frame lies in A's from the walls of one L-shaped room: within 10 cm and 2.5° of where A's motion
capture had the robot at B's first scan (the motion capture and the scans disagree by about 1°,
more while the robot turns; found: 2 cm and 1.5-1.6°), and the fused map must be the room's six
walls, each once.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import Stack, ask_zenoh, free_port, real_bag, run_wallmap

from wallmap.common.codec import decode

pytestmark = pytest.mark.e2e

JACKAL = "jackal_arena_2026-02-17-15-54-31"
MOCAP = "pose:/vrpn_client_node/jackal/pose"


def _robots(endpoint: str) -> dict[str, dict]:
    return {r["prefix"]: r for r in decode(ask_zenoh(endpoint, "F/robots"))["robots"]}


def _query(endpoint: str, prefix: str) -> dict:
    out = run_wallmap("query", "--json", "--connect", endpoint, "--prefix", prefix)
    return json.loads(out.stdout)


def test_the_jackal_arena_as_two_robots_is_one_map_of_six_walls(tmp_path: Path) -> None:
    jackal = real_bag(JACKAL)
    at_a, at_b = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    stack = Stack(tmp_path, at_a, "unused")
    try:
        stack.start_linked_routers(at_b)
        for robot, endpoint, services in (
            ("A", at_a, ("mapper", "detector")),
            ("B", at_b, ("mapper", "detector", "odometry")),
        ):
            for service in services:
                stack.start(f"{service}-{robot}", service, "--connect", endpoint, "--prefix", robot)
        stack.start("merge", "merge", "--robots", "A,B", "--prefix", "F", "--connect", at_a)
        a = ("--pose-source", MOCAP, "--duration", "22", "--connect", at_a, "--prefix", "A")
        run_wallmap("player", str(jackal), "--fast", "--wait-for", "detector,mapper", *a)
        b = ("--pose-source", "none", "--start", "18", "--connect", at_b, "--prefix", "B")
        run_wallmap("player", str(jackal), "--fast", "--wait-for", "detector,mapper,odometry", *b)
        frames = _query(at_a, "A")["frames"] + _query(at_b, "B")["frames"]
        deadline = time.monotonic() + 20
        while (fleet := _query(at_a, "F"))["frames"] < frames or not _robots(at_a)["B"]["aligned"]:
            assert time.monotonic() < deadline, (fleet["frames"], frames)
            time.sleep(0.5)
        robots = _robots(at_b)
    finally:
        stack.stop_all()
    stack.assert_all_clean()

    path_a = np.array(robots["A"]["trajectory"])
    start_b = np.array(robots["B"]["trajectory"][0])  # B's first keyframe, placed in A's frame
    truth = [np.interp(start_b[0], path_a[:, 0], v) for v in path_a[:, 1:3].T]
    truth_yaw = np.interp(start_b[0], path_a[:, 0], np.unwrap(path_a[:, 3]))
    off = float(np.hypot(*(start_b[1:3] - truth)))
    turn = abs(math.degrees(math.remainder(start_b[3] - truth_yaw, 2 * math.pi)))
    walls = [w for w in fleet["walls"] if not w.get("tentative")]
    print(
        f"B's frame {off * 100:.1f} cm and {turn:.2f} deg from the motion capture's; "
        f"{len(walls)} fused walls, matched {robots['B']['walls_matched']}"
    )
    assert off < 0.10
    assert turn < 2.5
    assert len(walls) == 6, [w["sources"] for w in walls]
    assert sum(len({s["robot"] for s in w["sources"]}) == 2 for w in walls) >= 4
