"""The whole pipeline as separate processes over a real router, scored against the scene's truth.

The scenes are generated with seeds that were never used to tune the detector or mapper
(tuning used seeds 1-9, see docs/accuracy.md).
"""

from __future__ import annotations

import pytest

from wallmap.common.evaluation import evaluate_map
from wallmap.common.scene import write_scene_bag

pytestmark = pytest.mark.e2e

CASES = [
    pytest.param(101, "ros1", "pointcloud", id="ros1-pointcloud2"),
    pytest.param(202, "ros2-mcap", "depth16", id="ros2-mcap-depth16"),
]


@pytest.mark.parametrize(("seed", "fmt", "sensor"), CASES)
def test_generated_scene_is_mapped_accurately(stack, tmp_path, seed, fmt, sensor):
    bag = tmp_path / ("scene.bag" if fmt == "ros1" else "scene")
    scene = write_scene_bag(bag, seed=seed, n_frames=520, fmt=fmt, sensor=sensor)
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    played = stack.run("player", str(bag), "--fast", *stack.zenoh_args)
    assert played.returncode == 0, played.stderr
    assert f"published {scene.n_frames} frames" in played.stdout

    reply = stack.query("--min-obs", "3")
    assert reply["frames"] == scene.n_frames  # --fast: not one frame lost
    score = evaluate_map(reply["walls"], scene.plan, scene.seen_counts)
    print(score.summary())
    assert score.precision >= 0.95
    assert score.recall >= 0.9
    assert score.duplicates == 0
    assert score.median_angle_deg <= 1.0
    assert score.median_offset_m <= 0.03
