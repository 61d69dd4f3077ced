"""`--slam`: drifting wheel odometry corrected by the walls, depth cameras and lidars alike.

The generated scenes record, besides the true poses, an odometry that drifts (scale error, slip
and a heading error per metre, growing slowly) on /odom; the robot drives a loop through the
rooms. Mapped from /odom alone the map is unusable; with --slam it must match the truth and the
corrected trajectory must follow the true one.
"""

from __future__ import annotations

import numpy as np
import pytest

from wallmap.common import ekf
from wallmap.common.messages import WallObservation
from wallmap.config import configured
from wallmap.evaluation import evaluate_map
from wallmap.offline import map_bag, walls
from wallmap.services.mapper.pose_correction import PoseCorrector, SlamConfig

N_FRAMES = 600


def _trajectory_error(poses, trajectory) -> float:
    """RMS position error of ``poses`` against the true trajectory, at their stamps (m)."""
    stamps = [p.stamp for p in poses]
    x = np.interp(stamps, trajectory.stamps, trajectory.x)
    y = np.interp(stamps, trajectory.stamps, trajectory.y)
    dx, dy = np.array([p.x for p in poses]) - x, np.array([p.y for p in poses]) - y
    return float(np.sqrt(np.mean(dx**2 + dy**2)))


@pytest.fixture(scope="module")
def scenes(scene_bags):
    return {
        "depth": scene_bags(
            "slam-depth.bag", seed=500, n_frames=N_FRAMES, fmt="ros1", sensor="depth16"
        ),
        "lidar": scene_bags(
            "slam-lidar.bag", seed=501, n_frames=N_FRAMES, fmt="ros1", sensor="laserscan"
        ),
        "cloud": scene_bags(
            "slam-cloud.bag", seed=502, n_frames=N_FRAMES, fmt="ros1", sensor="pointcloud"
        ),
    }


FLOOR = {"depth": 0.9, "lidar": 0.9, "cloud": 0.9}  # issue 18: precision and recall 0.9


@pytest.mark.parametrize("sensor", ["depth", "lidar", "cloud"])
def test_walls_correct_drifting_odometry(scenes, sensor) -> None:
    scene = scenes[sensor]
    drifting: list = []
    plain = map_bag(
        scene.path,
        configured("player.source.pose_source=odom", "mapper.judge.enabled=false"),
        poses=drifting,
    )
    corrected: list = []
    slam = map_bag(
        scene.path,
        configured("player.source.pose_source=odom", "mapper.slam.enabled=true"),
        poses=corrected,
    )
    before = evaluate_map(walls(plain, 3), scene.plan, scene.seen_counts)
    after = evaluate_map(walls(slam, 3), scene.plan, scene.seen_counts)
    error_before = _trajectory_error(drifting, scene.trajectory)
    error_after = _trajectory_error(corrected, scene.trajectory)
    print(f"\nodom:  {before.summary()}; trajectory {error_before:.3f} m")
    print(f"slam:  {after.summary()}; trajectory {error_after:.3f} m")
    assert before.precision < 0.6, "the odometry drifts enough to matter"
    assert after.precision >= FLOOR[sensor]
    assert after.recall >= FLOOR[sensor]
    assert after.duplicates == 0
    assert after.median_offset_m <= 0.05
    assert error_after < error_before / 3
    assert len(corrected) == N_FRAMES, "every frame integrated"


def test_without_slam_the_poses_are_used_as_they_come(scenes) -> None:
    scene = scenes["depth"]
    used: list = []
    map_bag(scene.path, configured("player.source.pose_source=odom"), poses=used)
    assert all(p.cov is None or p.cov.shape == (3, 3) for p in used)
    assert _trajectory_error(used, scene.trajectory) > 0.3, "raw odometry: the drift stays"


@pytest.mark.parametrize(("start", "end"), [(-1.5, 1.5), (2.0, 5.0), (-6.0, -5.7)])
def test_a_line_is_turned_about_its_foot_by_end_sd_over_its_length(start, end) -> None:
    """The softening is what SlamConfig.end_sd says: in (offset, angle), the angle alone, by
    end_sd / length; at the piece's middle, t from the foot, its offset by t times that."""
    end_sd = 0.02
    obs = WallObservation(
        closest=np.array([0.0, 1.0]),  # a side wall along x, 1 m to the left
        cov=np.diag([1e-4, 4e-4]),
        p0=np.array([start, 1.0]),
        p1=np.array([end, 1.0]),
        n_points=50,
        rms=0.01,
    )
    softened = PoseCorrector(SlamConfig(end_sd=end_sd))._softened(obs)
    to_line = np.linalg.inv(ekf.line_jacobian(obs.closest))
    extra = to_line @ (softened.cov - obs.cov) @ to_line.T  # over (offset, angle)
    turn = end_sd / (end - start)
    np.testing.assert_allclose(extra, np.diag([0.0, turn**2]), atol=1e-12)
    middle = 0.5 * (start + end)  # along the wall from its foot (0, 1)
    across_middle = np.array([1.0, -middle])  # offset there: rho - t theta (direction -x)
    assert across_middle @ extra @ across_middle == pytest.approx((middle * turn) ** 2)


def test_what_a_state_file_keeps_is_a_copy_the_mapping_does_not_change() -> None:
    """The state file is written after the map's lock is let go, while frames go on: the window
    of walls it keeps must be the one its joint state was taken with (a live list once made a
    restarted mapper refuse its state file)."""
    x = np.zeros(5 + 2 * 2)
    corrector = PoseCorrector(
        SlamConfig(enabled=True), x, np.eye(len(x)), np.zeros(3), 0, 0, ids=[3, 7], seen=[0, 0]
    )
    kept = corrector.to_json()
    corrector.ids.append(9)  # the mapping goes on: a wall comes into the window
    restored = PoseCorrector.from_json(kept, SlamConfig(enabled=True))
    assert restored.ids == [3, 7]
