"""Which way is up and where the floor is, from the planes of a few frames; the band seen."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallmap.common.level import estimate_up, find_planes, level_from_frames, rotation_onto_z
from wallmap.common.pose3d import rpy_matrix
from wallmap.common.scan_row import DEFAULT_BAND, auto_band


def room_points(rng: np.random.Generator, n: int = 3000) -> np.ndarray:
    """A corner of a room, z up, floor at z = 0: floor, two walls, a table top at 0.75 m."""
    floor = np.column_stack([rng.uniform(0, 3, n), rng.uniform(0, 3, n), np.zeros(n)])
    wall_a = np.column_stack([np.zeros(n), rng.uniform(0, 3, n), rng.uniform(0, 2.5, n)])
    wall_b = np.column_stack([rng.uniform(0, 3, n), np.full(n, 3.0), rng.uniform(0, 2.5, n)])
    table = np.column_stack(
        [rng.uniform(1, 2, n // 3), rng.uniform(1, 2, n // 3), np.full(n // 3, 0.75)]
    )
    points = np.vstack([floor, wall_a, wall_b, table])
    return points + rng.normal(0, 0.005, points.shape)


def frames_in(rotation: np.ndarray, offset: np.ndarray, seed: int = 0):
    """Eight frames of the room seen from a camera 1.4 m up, in a fixed frame p' = R p + t."""
    rng = np.random.default_rng(seed)
    clouds, ups, positions = [], [], []
    for _ in range(8):
        clouds.append(room_points(rng, 600) @ rotation.T + offset)
        ups.append(rotation @ (rpy_matrix(*rng.uniform(-0.2, 0.2, 2), 0.0) @ [0, 0, 1]))
        positions.append(rotation @ np.array([2.0, 1.0, 1.4]) + offset)
    return clouds, np.array(ups), np.array(positions)


def angle(a: np.ndarray, b: np.ndarray) -> float:
    cosine = abs(float(a @ b)) / np.linalg.norm(a) / np.linalg.norm(b)
    return math.degrees(math.acos(min(1.0, cosine)))


def test_a_level_frame_is_left_as_it_is_and_its_floor_found() -> None:
    clouds, ups, positions = frames_in(np.eye(3), np.zeros(3))
    level = level_from_frames(clouds, ups, positions, np.random.default_rng(0))
    assert level.is_level
    np.testing.assert_array_equal(level.up, [0.0, 0.0, 1.0])
    assert level.floor == pytest.approx(0.0, abs=0.01)
    assert level.floor_frames == 8
    np.testing.assert_allclose(level.matrix()[:3, :3], np.eye(3))


@pytest.mark.parametrize("tilt", [(25.0, 0.0), (10.0, -20.0), (-60.0, 30.0), (100.0, 10.0)])
def test_a_tilted_frame_is_levelled_and_its_floor_found(tilt) -> None:
    rotation = rpy_matrix(math.radians(tilt[0]), math.radians(tilt[1]), 0.4)
    offset = np.array([0.3, -1.2, 0.8])
    clouds, ups, positions = frames_in(rotation, offset)
    level = level_from_frames(clouds, ups, positions, np.random.default_rng(0))
    assert angle(level.up, rotation @ [0, 0, 1]) < 0.5
    assert not level.is_level
    floor = float(offset @ (rotation @ [0, 0, 1]))  # the floor's height along up
    assert level.floor == pytest.approx(floor, abs=0.02)
    levelled = level.matrix()
    back = clouds[0] @ levelled[:3, :3].T + levelled[:3, 3]
    assert np.percentile(back[:, 2], 5) == pytest.approx(0.0, abs=0.02)  # the floor at z = 0


def test_the_sensors_up_decides_between_planes_that_explain_the_scene_equally() -> None:
    """Two upright walls and no floor: up is either their common line or one of them."""
    rng = np.random.default_rng(3)
    n = 2000
    wall_a = np.column_stack([np.zeros(n), rng.uniform(0, 3, n), rng.uniform(0, 2.5, n)])
    wall_b = np.column_stack([rng.uniform(0, 3, n), np.full(n, 3.0), rng.uniform(0, 2.5, n)])
    rotation = rpy_matrix(1.0, 0.3, 0.0)
    cloud = np.vstack([wall_a, wall_b]) @ rotation.T
    planes = find_planes(cloud, rng)
    up, explained = estimate_up(planes, sensor_ups=np.array([rotation @ [0.2, 0.0, 1.0]]))
    assert angle(up, rotation @ [0, 0, 1]) < 0.5
    assert explained > 0.9


def test_too_little_to_tell_leaves_the_frame_as_it_is() -> None:
    cloud = np.random.default_rng(0).normal(size=(12, 3))
    level = level_from_frames(
        [cloud], np.array([[0, 0, 1.0]]), np.zeros((1, 3)), np.random.default_rng(0)
    )
    assert level.is_level
    assert level.floor is None
    assert "no floor seen" in level.describe()


def test_the_smallest_turn_takes_up_onto_z() -> None:
    for up in (np.array([0.0, 0.6, 0.8]), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0, 0])):
        rotation = rotation_onto_z(up)
        np.testing.assert_allclose(rotation @ up, [0, 0, 1], atol=1e-12)
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)


def test_the_band_adapts_to_what_the_sensor_sees() -> None:
    rng = np.random.default_rng(0)
    assert auto_band(rng.uniform(0, 3.0, 5000)) == DEFAULT_BAND  # a robot's level camera
    handheld = auto_band(rng.uniform(0, 1.55, 5000))  # 1.4 m up, looking down
    assert handheld[0] == 0.9
    assert handheld[1] == pytest.approx(1.45, abs=0.02)
    low = auto_band(rng.uniform(0, 0.7, 5000))  # sees nothing above furniture
    assert low == (0.9, 1.2), "never down into the furniture"
    assert auto_band(np.array([1.0, 2.0])) == DEFAULT_BAND  # too little to tell
