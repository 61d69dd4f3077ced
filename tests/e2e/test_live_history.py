"""Real-time playback loses nothing when a service, the router or a link goes away for a while.

A live sensor does not replay, so frames, poses and observations are published with a window
of history (``common.delivery``): a detector or mapper that restarts, or a router that comes
back, catches up on what it missed, and the mapper takes every run's frames in order. Each test
plays a 600-frame bag at 4x real time, SIGKILLs one process 40 % in, restarts it 2 s later, and
asserts every frame integrated and the same walls, with the same ids, as an uninterrupted run.
"""

from __future__ import annotations

import time

import pytest
from test_recovery import assert_same_walls

from wallmap.evaluation import evaluate_map
from wallmap.offline import map_bag, walls
from wallmap.scene import Camera, write_scene_bag

pytestmark = pytest.mark.e2e

N_FRAMES = 600
RATE_HZ = 15.0
SPEED = 4.0
PLAYED_S = N_FRAMES / RATE_HZ / SPEED


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return write_scene_bag(
        tmp_path_factory.mktemp("live") / "s.bag",
        seed=11,
        n_frames=N_FRAMES,
        fmt="ros1",
        sensor="depth16",
        camera=Camera(width=120, height=90),
        rate_hz=RATE_HZ,
    )


@pytest.fixture(scope="module")
def reference(scene) -> dict:
    """The uninterrupted map: the services' code in one process, on the same bag."""
    return {
        "frames": N_FRAMES,
        "walls": [w.to_map() for w in walls(map_bag(scene.path), min_obs=3)],
    }


def _play_with_a_fault(stack, scene, fault) -> dict:
    """Play at 4x; 40 % in, ``fault()``; the map once the player is done."""
    player = stack.start(
        "player",
        "player",
        str(scene.path),
        "--rate",
        str(SPEED),
        "--wait-for",
        "detector,mapper",
        *stack.zenoh_args,
    )
    time.sleep(1.0 + 0.4 * PLAYED_S)  # the player waits about a second for its services
    before = stack.query()["frames"]
    assert 0 < before < N_FRAMES, "the fault comes mid-run"
    fault()
    assert player.proc.wait(timeout=120) == 0, player.output()
    assert f"published {N_FRAMES} frames" in player.output()
    deadline = time.monotonic() + 30
    while (reply := stack.query("--min-obs", "3"))["frames"] < N_FRAMES:
        assert time.monotonic() < deadline, reply
        time.sleep(0.5)
    print(f"\n{before} frames before the fault, {reply['frames']} in all")
    assert (reply["lost"], reply["dropped"], reply["skipped"]) == (0, 0, 0), reply
    assert f"the mapper integrated {N_FRAMES}" in player.output()
    score = evaluate_map(reply["walls"], scene.plan, scene.seen_counts)
    print(score.summary())
    assert score.duplicates == 0
    assert score.precision >= 0.95
    assert score.recall >= 0.9
    return reply


def test_the_mapper_killed_and_restarted_on_its_state_catches_up(
    stack, scene, reference, tmp_path
) -> None:
    state = tmp_path / "map.json"
    mapper = stack.start("mapper", "mapper", "--state", str(state), *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)

    def kill_and_restart() -> None:
        # Saved every 2 s once the map has changed: on a busy machine the first save can come
        # after the fault's moment, and a mapper killed before it restarts on no state at all.
        deadline = time.monotonic() + 10.0
        while not state.exists():
            assert time.monotonic() < deadline, "the mapper saved no state within 10 s"
            time.sleep(0.1)
        mapper.kill()
        time.sleep(2.0)
        stack.start("mapper-2", "mapper", "--state", str(state), *stack.zenoh_args)

    assert_same_walls(_play_with_a_fault(stack, scene, kill_and_restart), reference)


def test_the_detector_killed_and_restarted_catches_up(stack, scene, reference) -> None:
    stack.start("mapper", "mapper", *stack.zenoh_args)
    detector = stack.start("detector", "detector", *stack.zenoh_args)

    def kill_and_restart() -> None:
        detector.kill()
        time.sleep(2.0)
        stack.start("detector-2", "detector", *stack.zenoh_args)

    assert_same_walls(_play_with_a_fault(stack, scene, kill_and_restart), reference)


def test_the_router_killed_and_restarted_loses_nothing(stack, scene, reference) -> None:
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    router = stack.services[0]

    def kill_and_restart() -> None:
        router.kill()
        time.sleep(2.0)
        stack.start("router-2", "router", "--listen", stack.endpoint)

    assert_same_walls(_play_with_a_fault(stack, scene, kill_and_restart), reference)
    assert stack.counters("mapper")["router_lost"] == 1


def test_a_window_too_short_for_the_outage_counts_what_it_lost(stack, scene) -> None:
    """A window of 1 s, a detector down 3 s: frames are lost, and the map reply says how many."""
    stack.start("mapper", "mapper", "--history", "1", "--gap-wait", "2", *stack.zenoh_args)
    detector = stack.start("detector", "detector", "--history", "1", *stack.zenoh_args)
    player = stack.start(
        "player",
        "player",
        str(scene.path),
        "--rate",
        str(SPEED),
        "--history",
        "1",
        "--wait-for",
        "detector,mapper",
        *stack.zenoh_args,
    )
    time.sleep(1.0 + 0.4 * PLAYED_S)
    detector.kill()
    time.sleep(3.0)
    stack.start("detector-2", "detector", "--history", "1", *stack.zenoh_args)
    assert player.proc.wait(timeout=120) == 0, player.output()
    deadline = time.monotonic() + 30
    while (reply := stack.query())["frames"] + reply["lost"] + reply["skipped"] < N_FRAMES:
        assert time.monotonic() < deadline, reply
        time.sleep(0.5)
    print(f"\n{reply['frames']} integrated, {reply['lost']} lost")
    assert reply["lost"] >= 60, "3 s at 60 frames/s, less the 1 s window"
    assert reply["frames"] + reply["lost"] == N_FRAMES, "every frame integrated or counted"
    assert reply["skipped"] == 0, "catching up on the window is not falling behind"
    status = stack.run("status", *stack.zenoh_args, timeout=30)
    assert "lost" in status.stdout
