"""`wallmap mapper --slam` as a process: the corrected pose out, a restart on the state file."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
import zenoh

from wallmap.common.link_settings import ZenohSettings
from wallmap.common.messages import unpack_pose
from wallmap.common.transport import Keys, open_session
from wallmap.evaluation import evaluate_map

N_FRAMES = 600


@pytest.mark.e2e
def test_mapper_slam_publishes_the_corrected_pose_and_survives_a_restart(
    stack, scene_bags, tmp_path
) -> None:
    """Real processes: mapper --slam on its state file, killed mid-bag and restarted."""
    scene = scene_bags(
        "slam-depth.bag", seed=500, n_frames=N_FRAMES, fmt="ros1", sensor="depth16"
    )  # the unit tests' depth scene
    state = tmp_path / "map.json"
    mapper = stack.start("mapper", "mapper", "--slam", "--state", str(state), *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    keys = Keys(stack.prefix)
    received: list = []
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)
    with open_session(settings) as session:
        sub = session.declare_subscriber(
            keys.pose_corrected, lambda s: received.append(unpack_pose(s.payload.to_bytes()))
        )
        corrections = session.declare_subscriber(
            keys.pose_correction, zenoh.handlers.FifoChannel(4096)
        )
        player = stack.start(
            "player",
            "player",
            str(scene.path),
            "--pose-source",
            "odom",
            "--rate",
            "4",
            "--wait-for",
            "detector,mapper",
            *stack.zenoh_args,
        )
        time.sleep(1.0 + 0.4 * N_FRAMES / 15.0 / 4)
        deadline = time.monotonic() + 30  # a busy machine: the first save may come later
        while not state.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        mapper.kill()
        saved = json.loads(state.read_text())
        assert saved["slam"]["x"] is not None, "the state file carries the pose correction"
        time.sleep(2.0)
        stack.start("mapper-2", "mapper", "--slam", "--state", str(state), *stack.zenoh_args)
        assert player.proc.wait(timeout=120) == 0, player.output()
        deadline = time.monotonic() + 60  # the restarted mapper catches up from the history
        while (reply := stack.query("--min-obs", "3"))["frames"] < N_FRAMES:
            assert time.monotonic() < deadline, reply
            time.sleep(0.5)
        sub.undeclare()
        correction = corrections.handler.try_recv()
        corrections.undeclare()
    assert correction is not None
    assert unpack_pose(correction.payload.to_bytes()).child == "odom"
    assert reply["slam"]["fixes"] > N_FRAMES, "the walls fixed the pose"
    assert len(received) >= N_FRAMES // 2
    last = received[-1]
    assert last.cov is not None
    score = evaluate_map(reply["walls"], scene.plan, scene.seen_counts)
    print(score.summary())
    assert score.precision >= 0.9
    assert score.recall >= 0.9
    assert score.duplicates == 0
    truth = scene.trajectory
    error = math.hypot(
        last.x - float(np.interp(last.stamp, truth.stamps, truth.x)),
        last.y - float(np.interp(last.stamp, truth.stamps, truth.y)),
    )
    assert error < 0.3, "the corrected pose follows the true one"
