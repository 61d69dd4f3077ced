"""Service behaviour over a real router: state across restarts, real-time playback, updates,
queries and pictures of the live map."""

from __future__ import annotations

import json
import time

import pytest
import zenoh
from conftest import Stack, free_port

from wallmap.common.codec import decode
from wallmap.common.link_settings import ZenohSettings
from wallmap.common.transport import Keys, open_session
from wallmap.scene import write_scene_bag


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    bag = tmp_path_factory.mktemp("bags") / "small.bag"
    write_scene_bag(bag, seed=8, n_frames=60, fmt="ros1", sensor="depth16")
    return bag


@pytest.mark.e2e
def test_mapper_restart_on_its_state_file_keeps_walls_and_ids(stack, small_bag, tmp_path):
    state = tmp_path / "map.json"
    mapper = stack.start("mapper", "mapper", "--state", str(state), *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    assert stack.run("player", str(small_bag), "--fast", *stack.zenoh_args).returncode == 0
    before = stack.query()
    assert mapper.stop() == 0
    assert state.exists()
    stack.start("mapper-again", "mapper", "--state", str(state), *stack.zenoh_args)
    after = stack.query()  # asked again until the restarted mapper is up
    assert after["walls"] == before["walls"]
    assert after["frames"] == 60
    # New frames extend the same map; the ids stay.
    assert stack.run("player", str(small_bag), "--fast", *stack.zenoh_args).returncode == 0
    again = stack.query()
    assert again["frames"] == 120
    # Every id stays, or was merged into a wall that is there (pieces found to be one wall).
    survivors = {merged: kept for merged, kept, _ in again["merges"]}
    ids = {w["id"] for w in again["walls"]}
    assert all(i in ids or survivors.get(i) in ids for i in (w["id"] for w in before["walls"]))


@pytest.mark.e2e
def test_query_waits_its_timeout_for_a_mapper_to_come_up(stack):
    """`wallmap query --timeout S`: with no mapper up, Zenoh ends a query at once; the command
    asks again until one answers, and gives up only after S seconds."""
    started = time.monotonic()
    alone = stack.run("query", "--timeout", "2", *stack.zenoh_args, expect=1)
    assert time.monotonic() - started >= 2.0
    assert "no mapper answered" in alone.stderr
    query = stack.start("query", "query", "--json", "--timeout", "30", *stack.zenoh_args)
    time.sleep(1.5)
    assert query.proc.poll() is None, "still waiting for a mapper"
    stack.start("mapper", "mapper", *stack.zenoh_args)
    assert query.proc.wait(timeout=40) == 0, query.output()
    assert json.loads(query.output())["frames"] == 0


@pytest.mark.e2e
def test_query_waits_its_timeout_for_the_router_too(tmp_path) -> None:
    """`wallmap up &` then `wallmap query`: the query may start before the router listens."""
    stack = Stack(tmp_path, f"tcp/127.0.0.1:{free_port()}", prefix="test/router-later")
    try:
        query = stack.start("query", "query", "--json", "--timeout", "30", *stack.zenoh_args)
        time.sleep(1.5)
        assert query.proc.poll() is None, "still waiting for a router"
        stack.start("router", "router", "--listen", stack.endpoint)
        stack.start("mapper", "mapper", *stack.zenoh_args)
        assert query.proc.wait(timeout=40) == 0, query.output()
        assert json.loads(query.output())["frames"] == 0
    finally:
        stack.stop_all()
    stack.assert_all_clean()


@pytest.mark.e2e
def test_real_time_playback_keeps_the_bag_timing_and_loses_nothing_uncounted(stack, small_bag):
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    started = time.monotonic()
    played = stack.run(
        "player", str(small_bag), "--rate", "2", "--wait-for", "detector,mapper", *stack.zenoh_args
    )
    elapsed = time.monotonic() - started
    assert played.returncode == 0, played.stderr
    assert elapsed >= 59 / 15 / 2  # 60 frames at 15 Hz, played twice as fast
    reply, skipped = stack.settled_frames(60)
    assert reply["frames"] + skipped == 60  # integrated, or skipped and counted
    assert skipped <= 6


@pytest.mark.e2e
def test_map_updates_stream_the_walls_as_they_change(stack, small_bag):
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    with open_session(ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)) as session:
        sub = session.declare_subscriber(
            Keys(stack.prefix).map_updates, zenoh.handlers.FifoChannel(1000)
        )
        assert stack.run("player", str(small_bag), "--fast", *stack.zenoh_args).returncode == 0
        time.sleep(1.0)
        updates = []
        while (sample := sub.try_recv()) is not None:
            updates.append(decode(sample.payload.to_bytes()))
    assert 1 <= len(updates) < 30  # rate-limited: far fewer updates than the 60 frames
    latest: dict[int, dict] = {}
    for update in updates:
        for wall in update["walls"]:
            latest[wall["id"]] = wall
        for gone in update["removed"]:
            latest.pop(gone, None)
    final = stack.query("--tentative")
    assert {w["id"]: w for w in final["walls"]} == latest


@pytest.mark.e2e
def test_map_updates_nobody_heard_go_to_the_first_subscriber(stack, small_bag):
    """Played with nothing subscribed, the changes are held, then sent whole to who comes."""
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    assert stack.run("player", str(small_bag), "--fast", *stack.zenoh_args).returncode == 0
    with open_session(ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)) as session:
        sub = session.declare_subscriber(
            Keys(stack.prefix).map_updates, zenoh.handlers.FifoChannel(1000)
        )
        deadline = time.monotonic() + 5.0
        while (sample := sub.try_recv()) is None:
            assert time.monotonic() < deadline, "no update came to a late subscriber"
            time.sleep(0.05)
        update = decode(sample.payload.to_bytes())
    walls = {w["id"]: w for w in stack.query("--tentative")["walls"]}
    assert walls, "the bag maps walls"
    assert {w["id"]: w for w in update["walls"]} == walls
    assert update["frames"] == stack.query()["frames"]


@pytest.mark.e2e
def test_query_filters_from_the_command_line(stack, small_bag):
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    assert stack.run("player", str(small_bag), "--fast", *stack.zenoh_args).returncode == 0
    everything = stack.query("--tentative")
    served = stack.query()
    assert len(served["walls"]) <= len(everything["walls"])
    assert all(not w["tentative"] for w in served["walls"])
    assert stack.query("--bbox", "1000,1000,1001,1001")["walls"] == []
    assert stack.query("--since", "1e12")["walls"] == []
    bad = stack.run("query", "--bbox", "1,2", *stack.zenoh_args, expect=1)
    assert "bbox must be xmin,ymin,xmax,ymax" in bad.stderr


@pytest.mark.e2e
def test_plot_and_export_the_live_map(stack, small_bag, tmp_path):
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    assert stack.run("player", str(small_bag), "--fast", *stack.zenoh_args).returncode == 0
    served = stack.query()["walls"]
    for name in ("map.png", "map.svg"):
        out = stack.run("plot", str(tmp_path / name), *stack.zenoh_args)
        assert out.returncode == 0, out.stderr
    assert (tmp_path / "map.png").read_bytes().startswith(b"\x89PNG")
    assert (tmp_path / "map.svg").read_text().count('class="wall"') >= len(served)
    out = stack.run("export", str(tmp_path / "map.geojson"), *stack.zenoh_args)
    assert out.returncode == 0, out.stderr
    collection = json.loads((tmp_path / "map.geojson").read_text())
    ids = [
        f["properties"]["id"] for f in collection["features"] if f["properties"]["kind"] == "wall"
    ]
    assert sorted(ids) == sorted(w["id"] for w in served)
