"""Per image column, the point on something that rises through the band: walls, not clutter."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wallmap.common.messages import Frame
from wallmap.common.scan_row import (
    STACK,
    RowSelection,
    band_stack,
    finite_scan,
    free_rays,
    select_points,
    select_scan,
    upright_points,
)

BAND = (0.9, 1.5)
HEIGHTS = np.linspace(BAND[0], BAND[1], STACK, endpoint=False) + 0.05  # the stack's targets
WIDTH = 40


def stack_of(surfaces) -> np.ndarray:
    """A stack (base frame = sensor frame) from per column and level the distance hit."""
    ys = np.linspace(-1.0, 1.0, WIDTH)
    stack = np.full((STACK, WIDTH, 3), np.nan, np.float32)
    for level, height in enumerate(HEIGHTS):
        for column, y in enumerate(ys):
            x = surfaces(level, column)
            if x is not None:
                stack[level, column] = (x, y, height)
    return stack


def test_a_wall_is_kept_at_every_column() -> None:
    row = upright_points(stack_of(lambda level, column: 3.0), np.eye(4))
    assert np.isfinite(row).all()
    np.testing.assert_allclose(row[:, 0], 3.0)


def test_a_kettle_in_front_of_the_wall_gives_way_to_the_wall_seen_above_it() -> None:
    def scene(level, column):
        return 2.0 if 10 <= column < 20 and level < 2 else 3.0

    row = upright_points(stack_of(scene), np.eye(4))
    np.testing.assert_allclose(row[:, 0], 3.0)


def test_a_box_that_does_not_reach_the_top_of_what_is_seen_is_no_wall() -> None:
    """Columns 10-19 see a 0.3 m box at 2 m and, above it, open space up to a far wall."""

    def scene(level, column):
        if 10 <= column < 20:
            return 2.0 if level < 3 else 4.0
        return 4.0

    row = upright_points(stack_of(scene), np.eye(4))
    assert not np.any(np.isclose(row[:, 0], 2.0)), "the box is not taken for a wall"
    assert np.isfinite(row[:10, 0]).all()


def test_a_level_surface_alone_among_walls_is_dropped() -> None:
    """A counter top seen at one height only, in columns where other heights see the wall."""

    def scene(level, column):
        if 10 <= column < 20 and level == 0:
            return 1.2  # the front edge of a counter top, in the band's lowest slice
        return 3.0

    row = upright_points(stack_of(scene), np.eye(4))
    assert not np.any(np.isclose(row[:, 0], 1.2))
    np.testing.assert_allclose(row[:, 0], 3.0)


def test_a_whole_cloud_and_the_players_stack_give_the_same_row() -> None:
    rng = np.random.default_rng(0)
    cloud = np.full((64, WIDTH, 3), np.nan, np.float32)
    heights = np.linspace(2.2, 0.2, 64)
    cloud[..., 0] = 3.0 + rng.normal(0, 0.003, (64, WIDTH))
    cloud[..., 1] = np.linspace(-1, 1, WIDTH)
    cloud[..., 2] = heights[:, None]
    how = RowSelection(band=BAND)
    stack = band_stack(cloud, np.eye(4), BAND)
    np.testing.assert_array_equal(
        select_points(cloud, np.eye(4), how), select_points(stack, np.eye(4), how, stacked=True)
    )


def test_a_frames_finite_scan_is_its_scan_row_without_the_missing_points() -> None:
    """A cloud's and the player's stack's frames give the same returns, every point finite."""
    cloud = np.full((64, WIDTH, 3), np.nan, np.float32)
    cloud[..., 0] = 3.0
    cloud[..., 1] = np.linspace(-1, 1, WIDTH)
    cloud[..., 2] = np.linspace(2.2, 0.2, 64)[:, None]
    cloud[:, :5] = np.nan  # columns that saw nothing
    how = RowSelection(band=BAND)
    whole = Frame("run", 0, 1.0, "camera", cloud, np.eye(4))
    stacked = replace(whole, points=band_stack(cloud, np.eye(4), BAND), band=BAND)
    scan = finite_scan(whole, how)
    assert scan.shape == (WIDTH - 5, 2)
    np.testing.assert_array_equal(scan, select_scan(cloud, np.eye(4), how)[5:])
    np.testing.assert_array_equal(finite_scan(stacked, how), scan)


def test_free_rays_end_at_the_farthest_return_of_each_column() -> None:
    def scene(level, column):
        return 2.0 if level < 3 else 4.0

    T_base_sensor = np.eye(4)
    T_base_sensor[:2, 3] = (0.1, 0.0)
    origin, ends = free_rays(stack_of(scene), T_base_sensor)
    np.testing.assert_allclose(origin, (0.1, 0.0))
    assert len(ends) == WIDTH
    np.testing.assert_allclose(ends[:, 0], 4.1)  # shifted by the mount, like every point
