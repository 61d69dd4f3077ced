"""No frame lost when a detector or the router restarts mid-bag under `--fast`.

The mapper takes each run's frames once and in order and acknowledges by frame number; frames
lost on the way come back from the history (``common.delivery``), and the player only waits.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import zenoh

from wallmap.common.codec import decode
from wallmap.common.link_settings import ZenohSettings
from wallmap.common.messages import Frame, pack
from wallmap.common.transport import Keys, open_session
from wallmap.offline import map_bag, walls
from wallmap.scene import write_scene_bag

N_FRAMES = 300


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return write_scene_bag(
        tmp_path_factory.mktemp("recovery") / "s.bag",
        seed=11,
        n_frames=N_FRAMES,
        fmt="ros1",
        sensor="depth16",
    )


def _control(session, keys: Keys, cmd: str) -> dict | None:
    for reply in session.get(f"{keys.player_control}?cmd={cmd}", timeout=2.0):
        if reply.ok is not None:
            return decode(reply.ok.payload.to_bytes())
    return None


def _until(check, timeout: float = 30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if value := check():
            return value
        time.sleep(0.05)
    raise TimeoutError


def _play_with_a_fault(stack, scene, fault, *, loses_frames: bool) -> tuple[dict, float]:
    """Play with --fast, pause mid-bag, apply ``fault``, resume.

    Returns the final map reply, and how long after the fault the player answered again.
    """
    keys = Keys(stack.prefix)
    player = stack.start(
        "player", "player", str(scene.path), "--fast", "--paused", *stack.zenoh_args
    )
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)
    with open_session(settings) as session:
        _until(lambda: _control(session, keys, "status"))
        _control(session, keys, "resume")
        _until(lambda: (s := _control(session, keys, "status")) and s["published"] >= 100)
        _control(session, keys, "pause")
        fault()
        after_fault = time.monotonic()
        _until(lambda: _control(session, keys, "resume"))
        answered = time.monotonic() - after_fault
    assert player.proc.wait(timeout=120) == 0, player.output()
    assert f"published {N_FRAMES} frames" in player.output()
    assert f"the mapper integrated {N_FRAMES}" in player.output()
    return stack.query("--min-obs", "3"), answered


@pytest.fixture(scope="module")
def reference(scene) -> dict:
    """The uninterrupted map: the services' code in one process, on the same bag."""
    return {
        "frames": N_FRAMES,
        "walls": [w.to_map() for w in walls(map_bag(scene.path), min_obs=3)],
    }


def assert_same_walls(reply: dict, reference: dict) -> None:
    """No wall lost or added, the same ids; the lines agree within RANSAC's sampling.

    Frames detected again come out the same (RANSAC is seeded by the frame number); the
    tolerances cover the map's own order effects.
    """
    assert reply["frames"] == reference["frames"]
    mine = {w["id"]: w for w in reply["walls"]}
    theirs = {w["id"]: w for w in reference["walls"]}
    assert set(mine) == set(theirs), "the same walls, with the same ids"
    for wall_id, wall in mine.items():
        a0, a1, b0, b1 = (np.asarray(w[k]) for w in (wall, theirs[wall_id]) for k in ("p0", "p1"))
        da, db = (a1 - a0) / np.linalg.norm(a1 - a0), (b1 - b0) / np.linalg.norm(b1 - b0)
        assert math.degrees(math.acos(min(abs(float(da @ db)), 1.0))) < 1.0
        normal = np.array([-db[1], db[0]])
        assert abs(float(normal @ ((a0 + a1) / 2 - b0))) < 0.02


@pytest.mark.e2e
def test_detector_killed_mid_bag_loses_no_frame(stack, scene, reference) -> None:
    stack.start("mapper", "mapper", *stack.zenoh_args)
    detector = stack.start("detector", "detector", *stack.zenoh_args)

    def kill_and_restart() -> None:
        detector.kill()
        stack.start("detector-2", "detector", *stack.zenoh_args)

    reply, _ = _play_with_a_fault(stack, scene, kill_and_restart, loses_frames=True)
    assert reply["dropped"] == 0
    assert_same_walls(reply, reference)


@pytest.mark.e2e
def test_router_restarted_mid_bag_loses_no_frame(stack, scene, reference) -> None:
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    router = stack.services[0]
    assert router.name == "router"

    def restart_router() -> None:
        router.stop()
        time.sleep(1.0)
        stack.start("router-2", "router", "--listen", stack.endpoint)

    reply, reconnected = _play_with_a_fault(stack, scene, restart_router, loses_frames=False)
    print(f"\nthe player answered {reconnected:.1f} s after the new router started")
    assert reconnected < 5.0, "services reconnect by themselves within 5 s"
    assert_same_walls(reply, reference)


@pytest.mark.e2e
def test_mapper_killed_mid_bag_resumes_from_its_state_file(stack, scene, tmp_path) -> None:
    """SIGKILL the mapper mid-bag, restart it on its state file: every frame, the same walls."""
    whole = tmp_path / "whole.json"
    stack.start("mapper", "mapper", "--state", str(whole), *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    played = stack.run("player", str(scene.path), "--fast", *stack.zenoh_args)
    assert played.returncode == 0, played.stderr
    uninterrupted = stack.query("--min-obs", "3")
    for service in stack.services[1:]:
        service.stop()
    stack.prefix += "-killed"  # a fresh set of services beside the first
    state = tmp_path / "killed.json"
    mapper = stack.start("mapper-2", "mapper", "--state", str(state), *stack.zenoh_args)
    stack.start("detector-2", "detector", *stack.zenoh_args)

    def kill_and_restart() -> None:
        time.sleep(3.0)  # the mapper saves its state every 2 s
        mapper.kill()
        assert state.exists()
        stack.start("mapper-3", "mapper", "--state", str(state), *stack.zenoh_args)

    reply, _ = _play_with_a_fault(stack, scene, kill_and_restart, loses_frames=True)
    assert reply["dropped"] == 0
    assert_same_walls(reply, uninterrupted)


@pytest.mark.e2e
def test_a_slow_detector_drops_the_oldest_real_time_frames_and_never_fast_ones(stack) -> None:
    # A 2 s window holds 120 frames: a burst of 400 is more than twice that.
    stack.start("detector", "detector", "--history", "2", *stack.zenoh_args)
    keys = Keys(stack.prefix)
    rng = np.random.default_rng(1)
    wall = np.column_stack([np.full(400, 2.0), np.linspace(-2, 2, 400), np.zeros(400)])
    points = (wall + rng.normal(0, 0.003, wall.shape)).astype(np.float32)[None]
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)

    with open_session(settings) as session:
        block = zenoh.CongestionControl.BLOCK
        frames = session.declare_publisher(keys.frames, congestion_control=block)
        _until(lambda: any(True for _ in session.liveliness().get(keys.health("detector"))))
        for run, resends in (("fast", True), ("real-time", False)):
            for seq in range(400):  # far faster than the detector takes them
                frame = Frame(run, seq, 1.0 + seq, "cam", points, np.eye(4), "depth", resends)
                frames.put(pack(frame))
            time.sleep(2.0)
            seen = stack.counters("detector")
            if resends:
                assert seen["received"] == seen["published"] == 400
                assert "dropped" not in seen
    assert seen["received"] == 800
    assert seen["dropped"] > 0, "the real-time backlog was dropped"
    assert seen["published"] + seen["dropped"] == 800
