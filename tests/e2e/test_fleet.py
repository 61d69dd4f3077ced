"""A fleet: two robots of one building on two routers, one map from `wallmap merge`.

As the issue's acceptance runs it, smaller: robot A a depth camera (a ROS 2 mcap bag, its map
frame the world's), robot B a 2-D lidar driving the route the other way with its poses in a
frame at its own start; A's detector and mapper on router A, B's on router B, router B started
with ``--connect`` to A; both bags played at 4x at the same time; ``wallmap merge --robots A,B``
on router A. The fused map is scored against the building's truth and B's frame against where
the scene put it; every process exits 0 with no traceback.
"""

from __future__ import annotations

import json
import math
import re
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from conftest import Stack, ask_zenoh, free_port, run_wallmap, wait_for_port

from wallmap.common.codec import decode
from wallmap.evaluation import evaluate_map
from wallmap.scene import Camera, load_truth, write_scene_bag
from wallmap.scene.bags import load_map_in_world
from wallmap.services.mapper import ros2_out

pytestmark = pytest.mark.e2e
FRAMES = 700


def _query(endpoint: str, *args: str) -> dict:
    out = run_wallmap("query", "--json", "--connect", endpoint, *args, "--timeout", "3")
    return json.loads(out.stdout)


def _settled(endpoint: str, frames: int) -> dict | None:
    """The fleet's map once it holds every frame of both robots (None: not yet, or no answer)."""
    out = run_wallmap("query", "--json", "--connect", endpoint, "--prefix", "F", expect=None)
    if out.returncode:
        return None
    reply = json.loads(out.stdout)
    return reply if reply["frames"] >= frames and reply["walls"] else None


def _sources(reply: dict) -> list[list[tuple[str, int]]]:
    """Each fused wall as the sorted robots' walls it holds."""
    return sorted(sorted((s["robot"], s["id"]) for s in w["sources"]) for w in reply["walls"])


def _page(port: int) -> dict:
    """What the live page shows: ``/api/map`` of ``wallmap view``."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/map?since=0", timeout=5) as answer:
        return json.loads(answer.read())


def _ids(body: dict) -> set[int]:
    return {w["id"] for w in body.get("walls", ())}


def test_two_robots_on_two_routers_make_one_map(tmp_path: Path) -> None:
    bag_a, bag_b = tmp_path / "a", tmp_path / "b.bag"
    camera = Camera(width=160, height=120)
    scene = {"seed": 4, "n_frames": FRAMES}
    written = {
        "A": write_scene_bag(bag_a, **scene, fmt="ros2-mcap", sensor="depth16", camera=camera),
        "B": write_scene_bag(
            bag_b, **scene, fmt="ros1", sensor="laserscan", reverse=True, own_frame=True
        ),
    }
    at_a, at_b = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    stack = Stack(tmp_path, at_a, "unused")
    try:
        stack.start_linked_routers(at_b)
        for robot, endpoint in (("A", at_a), ("B", at_b)):
            for service in ("mapper", "detector"):
                stack.start(f"{service}-{robot}", service, "--connect", endpoint, "--prefix", robot)
        merge = stack.start("merge", "merge", "--robots", "A,B", "--prefix", "F", "--connect", at_a)
        page = free_port()
        stack.start("view", "view", "--port", str(page), "--prefix", "F", "--connect", at_a)
        wait_for_port(page)
        played = {}

        def play(robot: str, bag: Path, endpoint: str) -> None:
            where = ("--connect", endpoint, "--prefix", robot)
            played[robot] = run_wallmap("player", str(bag), "--rate", "4", *where, timeout=300)

        players = [
            threading.Thread(target=play, args=("A", bag_a, at_a)),
            threading.Thread(target=play, args=("B", bag_b, at_b)),
        ]
        for thread in players:
            thread.start()
        for thread in players:
            thread.join()
        frames = {r: _query(e, "--prefix", r)["frames"] for r, e in (("A", at_a), ("B", at_b))}
        deadline = time.monotonic() + 20
        while (fleet := _query(at_a, "--prefix", "F"))["frames"] < sum(frames.values()):
            assert time.monotonic() < deadline, (fleet["frames"], frames, merge.output())
            time.sleep(0.5)
        robots = {
            r["prefix"]: r for r in decode(ask_zenoh(at_b, "F/robots"))["robots"]
        }  # through B
        markers = ros2_out.decode(
            ask_zenoh(at_a, "F/markers"), "visualization_msgs/msg/MarkerArray"
        )
        rooms = _query(at_a, "--prefix", "F", "--rooms")
        deadline = time.monotonic() + 15  # the live page follows the fleet's updates
        served = {w["id"] for w in fleet["walls"]}
        while _ids(shown := _page(page)) != served:
            assert time.monotonic() < deadline, (shown, fleet)
            time.sleep(0.5)
        picture, export = tmp_path / "fleet.svg", tmp_path / "fleet.geojson"
        run_wallmap("plot", str(picture), "--prefix", "F", "--connect", at_a, "--timeout", "3")
        run_wallmap("export", str(export), "--prefix", "F", "--connect", at_a, "--timeout", "3")
        merge.stop()  # a merge service restarted rebuilds the fleet's map from the robots' maps
        stack.start("merge-again", "merge", "--robots", "A,B", "--prefix", "F", "--connect", at_a)
        deadline = time.monotonic() + 30
        while (rebuilt := _settled(at_a, sum(frames.values()))) is None:
            assert time.monotonic() < deadline, "the restarted merge service rebuilt no map"
            time.sleep(0.5)
    finally:
        stack.stop_all()
    stack.assert_all_clean()

    plan, _, seen_a = load_truth(Path(f"{bag_a}.truth.json"))
    _, _, seen_b = load_truth(Path(f"{bag_b}.truth.json"))
    assert all(played[r].returncode == 0 for r in "AB")
    assert frames == {r: info.n_frames for r, info in written.items()}, "every frame integrated"
    assert robots["A"]["aligned"]
    assert robots["B"]["aligned"], robots
    truth_b = np.array(load_map_in_world(Path(f"{bag_b}.truth.json")))
    found_b = np.array([robots["B"][k] for k in ("x", "y", "yaw")])
    assert np.hypot(*(found_b[:2] - truth_b[:2])) < 0.05
    assert abs(math.degrees(math.remainder(found_b[2] - truth_b[2], 2 * math.pi))) < 0.5
    assert robots["B"]["trajectory"], "B's path, in the fleet's frame"
    seen = {k: seen_a.get(k, 0) + seen_b.get(k, 0) for k in set(seen_a) | set(seen_b)}
    score = evaluate_map(fleet["walls"], plan, seen)
    print(f"fleet: {score.summary()}; B at {found_b.round(4)} (truth {truth_b.round(4)})")
    assert score.precision >= 0.95
    assert score.recall >= 0.95
    assert score.duplicates == 0
    assert all(w["sources"] for w in fleet["walls"])
    assert _sources(rebuilt) == _sources(fleet), "the same walls from the same robots' walls"
    both = [w for w in fleet["walls"] if {s["robot"] for s in w["sources"]} == {"A", "B"}]
    assert len(both) >= 6, "walls both robots saw are one wall each"
    assert {m.id for m in markers.markers} == {w["id"] for w in fleet["walls"]}, "RViz's walls"
    assert len(rooms["rooms"]) >= 2, rooms
    assert len(shown["rooms"]["rooms"]) == len(rooms["rooms"]), "the page's rooms are the fleet's"
    ids = {r["id"] for r in rooms["rooms"]}
    assert all(set(d["rooms"]) <= ids for d in rooms["doors"])
    assert all(set(r["walls"]) <= {w["id"] for w in fleet["walls"]} for r in rooms["rooms"])
    kinds = [f["geometry"]["type"] for f in json.loads(export.read_text())["features"]]
    assert kinds.count("Polygon") == len(rooms["rooms"]), "GeoJSON: a Polygon per room"
    svg = picture.read_text()
    paths = re.findall(r'<polyline class="trajectory"[^>]*stroke="(#[0-9a-f]{6})"', svg)
    assert len(set(paths)) == 2, "each robot's path, in its own colour"
