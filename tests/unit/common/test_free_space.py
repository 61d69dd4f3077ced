"""The floor seen free: rays counted up to short of their ends, a grid that grows, a state."""

from __future__ import annotations

import numpy as np

from wallmap.common.free_space import CELL, MIN_FREE, RAY_SHORT, FreeSpace


def _free_at(space: FreeSpace, x: float, y: float) -> int:
    i, j = np.floor(np.array([x, y]) / space.cell).astype(int) - space.origin
    inside = 0 <= i < space.counts.shape[0] and 0 <= j < space.counts.shape[1]
    return int(space.counts[i, j]) if inside else 0


def test_a_ray_frees_the_floor_up_to_short_of_its_end() -> None:
    space = FreeSpace()
    pose = np.array([1.0, 2.0, np.pi / 2])  # facing +y
    space.add_rays(pose, np.zeros(2), np.array([[3.0, 0.0]]))  # 3 m ahead: to y = 5
    assert _free_at(space, 1.05, 3.55) >= MIN_FREE, "a cell a ray crossed is free"
    assert _free_at(space, 1.05, 5.0 - RAY_SHORT + 0.5 * CELL) == 0, "not the last stretch"
    assert _free_at(space, 3.0, 3.5) == 0, "nor beside the ray"
    assert space.free().sum() > 25


def test_a_sample_alone_is_not_free_floor() -> None:
    space = FreeSpace()
    space.add_points(np.array([[7.05, 7.05]]))
    assert 0 < _free_at(space, 7.05, 7.05) < MIN_FREE


def test_the_grid_grows_keeping_its_counts_and_a_state_file_restores_it() -> None:
    space = FreeSpace()
    space.add_robot(np.array([0.0, 0.0]))
    space.add_rays(np.array([0.0, 0.0, 0.0]), np.zeros(2), np.array([[-20.0, 15.0]]))
    assert _free_at(space, 0.05, 0.05) >= MIN_FREE, "the robot stands on free floor"
    assert _free_at(space, -10.0, 7.5) > 0, "one ray, far off"
    again = FreeSpace.from_json(space.to_json())
    assert (again.counts == space.counts).all()
    assert (again.origin == space.origin).all()


def test_counts_saturate_instead_of_wrapping() -> None:
    space = FreeSpace()
    for _ in range(100):
        space.add_robot(np.array([0.0, 0.0]))
    assert _free_at(space, 0.05, 0.05) == 255
