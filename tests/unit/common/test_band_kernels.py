"""The compiled band loops against a brute-force numpy statement of the same rule."""

import numpy as np
import pytest

from wallmap.common import band_kernels, compiled, scan_row
from wallmap.common.scan_row import (
    UPRIGHT_CELL,
    UPRIGHT_SHARE,
    UPRIGHT_TOP,
    band_stack,
    free_rays,
    upright_points,
)

MOUNT = np.array(
    [[0.0, 0.0, 1.0, 0.1], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.6], [0, 0, 0, 1]]
)  # an optical frame (z ahead, y down) 0.6 m up


def cluttered_stack(rng: np.random.Generator, width: int = 80) -> np.ndarray:
    """Six heights a column: a wall 3 m ahead, boxes and a table top in front, holes."""
    heights = np.linspace(1.35, 2.05, 6)[:, None] + rng.normal(0, 0.01, (6, width))
    ahead = np.full((6, width), 3.0) + rng.normal(0, 0.005, (6, width))
    box = rng.random(width) < 0.3
    ahead[:2, box] = 1.5  # boxes up to the second height
    ahead[3, rng.random(width) < 0.2] = 2.0  # a shelf edge at one height
    lateral = np.linspace(-1.5, 1.5, width)[None, :] * ahead / 3.0
    stack = np.stack([-lateral, 0.6 - heights, ahead - 0.1], axis=-1).astype(np.float32)
    stack[rng.random((6, width)) < 0.1] = np.nan
    return stack


def brute_force_upright(stack: np.ndarray) -> np.ndarray:
    """Per column, the upright point, every point's spread found by looking at all others."""
    height = (stack.astype(np.float64) @ MOUNT[2, :3] + MOUNT[2, 3]).astype(np.float64)
    xy = stack.astype(np.float64) @ MOUNT[:2, :3].T + MOUNT[:2, 3]
    valid = np.isfinite(height) & np.isfinite(xy).all(axis=-1)
    cells = np.floor(xy / UPRIGHT_CELL)
    rise, top = np.zeros(valid.shape), np.full(valid.shape, -np.inf)
    for k, j in zip(*np.nonzero(valid), strict=True):
        near = valid & (np.abs(cells - cells[k, j]) <= 1).all(axis=-1)
        top[k, j] = height[near].max()
        rise[k, j] = top[k, j] - height[near].min()
    column_top = np.where(valid, height, -np.inf).max(axis=0)
    column_bottom = np.where(valid, height, np.inf).min(axis=0)
    seen = valid.any(axis=0)
    visible = np.where(seen, column_top - column_bottom, 0.0)
    band = column_top[seen].max() - column_bottom[seen].min()
    kept = valid & (rise >= np.minimum(UPRIGHT_SHARE * band, UPRIGHT_SHARE * visible))
    kept &= top >= column_top - UPRIGHT_TOP
    out = np.full((stack.shape[1], 3), np.nan, dtype=np.float32)
    for j in np.flatnonzero(kept.any(axis=0)):
        levels = np.flatnonzero(kept[:, j])
        best = levels[np.argmax(rise[levels, j] - 1e-3 * np.abs(levels - 2.5))]
        same = levels[np.hypot(*(xy[levels, j] - xy[best, j]).T) <= 2 * UPRIGHT_CELL]
        out[j] = stack[same, j].mean(axis=0)
    return out


@pytest.mark.parametrize("seed", range(5))
def test_upright_points_are_the_brute_force_rule_s(seed: int) -> None:
    stack = cluttered_stack(np.random.default_rng(seed))
    found, expected = upright_points(stack, MOUNT), brute_force_upright(stack)
    np.testing.assert_array_equal(np.isnan(found), np.isnan(expected))
    np.testing.assert_allclose(found, expected, atol=1e-5, equal_nan=True)
    assert np.isnan(found[:, 0]).mean() < 0.5  # the wall is found where seen


def test_free_rays_end_at_each_column_s_farthest_point() -> None:
    stack = cluttered_stack(np.random.default_rng(9), width=40)
    origin, ends = free_rays(stack, MOUNT)
    xy = stack.astype(np.float64) @ MOUNT[:2, :3].T + MOUNT[:2, 3]
    reach = np.where(np.isfinite(xy).all(axis=-1), np.hypot(*(xy - origin).transpose(2, 0, 1)), -1)
    seen = (reach > 0).any(axis=0)
    expected = xy[reach.argmax(axis=0), np.arange(40)][seen]
    np.testing.assert_allclose(ends, expected)
    _, xy_k, valid, _ = band_kernels.base_positions(stack, MOUNT, UPRIGHT_CELL)
    np.testing.assert_allclose(xy_k[valid], xy[valid])


def _numpy_band_stack(
    points: np.ndarray, mount: np.ndarray, band: tuple[float, float]
) -> np.ndarray:
    """The band's stack as numpy picked it before it was compiled: six whole-array passes."""
    low, high = band
    spacing = (high - low) / 6
    a, b, c, d = mount[2].astype(np.float32)
    height = points[..., 0] * a
    height += points[..., 1] * b
    height += points[..., 2] * c
    height += d
    columns = np.arange(points.shape[1])
    stack = np.full((6, points.shape[1], 3), np.nan, dtype=np.float32)
    for level in range(6):
        cost = np.abs(height - (low + (level + 0.5) * spacing))
        cost[~(cost <= 0.5 * spacing)] = np.inf  # NaN heights too
        best = np.argmin(cost, axis=0)
        found = np.isfinite(cost[best, columns])
        stack[level, found] = points[best[found], columns[found]]
    return stack


@pytest.mark.parametrize("seed", range(4))
def test_the_band_stack_is_numpy_s_to_the_bit(seed: int) -> None:
    """A tilted camera's rows, with holes, as a strided read-only view over a message's bytes
    (a cloud's 16-byte points) and as a contiguous array: the same points picked as numpy's."""
    rng = np.random.default_rng(seed)
    rows, width = 40, 96
    up = np.linspace(1.0, -0.4, rows)[:, None] + rng.normal(0, 0.02, (rows, width))
    ahead = rng.uniform(0.5, 5.0, (rows, width))
    lateral = np.linspace(-1.0, 1.0, width)[None, :] * ahead
    points = np.stack([lateral, -up * ahead, ahead], axis=-1).astype(np.float32)
    points[rng.random((rows, width)) < 0.1] = np.nan
    points[0, :4] = points[1, :4]  # the same heights on two rows, elsewhere: the first is taken
    points[0, :4, 0] += 0.5
    message = np.zeros((rows, width, 4), dtype=np.float32)
    message[..., :3] = points
    view = np.ndarray(
        (rows, width, 3), dtype=np.float32, buffer=message.tobytes(), strides=(width * 16, 16, 4)
    )
    assert not view.flags.writeable
    assert not view.flags.c_contiguous
    band = (1.3, 2.1)
    want = _numpy_band_stack(points, MOUNT, band)
    assert np.isfinite(want).all(axis=-1).sum() > 200
    for given in (points, view):
        got = band_kernels.band_stack(given, MOUNT, *band, 6)
        np.testing.assert_array_equal(got, want)
    for given in (points, view, points.astype(">f4")):
        np.testing.assert_array_equal(scan_row._band_stack_numpy(given, MOUNT, band), want)


def test_heights_on_the_levels_edges_are_picked_as_numpy_picks_them() -> None:
    """Heights on the edges between levels (a tie between two levels), just inside and just
    outside them, and beyond the band: the kernel tries three levels a point, numpy all six."""
    low, high = 1.3, 2.1
    spacing = (high - low) / 6
    edges = np.float32(low + spacing * np.arange(-1.0, 7.5, 0.5))
    heights = np.concatenate(
        [
            edges,
            np.nextafter(edges, np.float32(np.inf)),
            np.nextafter(edges, np.float32(-np.inf)),
            np.float32([0.0, 5.0, np.inf, -np.inf, np.nan]),
        ]
    )
    # One point a column, the rest of it holes: no other point hides a level missed for it.
    points = np.full((3, heights.size, 3), np.nan, dtype=np.float32)
    points[1, :, 0] = np.linspace(0.5, 4.0, heights.size)
    points[1, :, 1] = 0.0
    points[1, :, 2] = heights  # the mount below reads a point's height off its z
    level = np.eye(4)
    want = _numpy_band_stack(points, level, (low, high))
    assert np.isfinite(want).all(axis=-1).sum() > 30
    np.testing.assert_array_equal(band_kernels.band_stack(points, level, low, high, 6), want)


def test_a_point_missing_a_coordinate_is_never_stacked() -> None:
    """A cloud's point with one coordinate NaN or infinite (a driver's partial return) has no
    height: the stack holds whole points or NaN, and the player hands it out as it is."""
    rng = np.random.default_rng(11)
    points = cluttered_stack(rng, width=64).repeat(4, axis=0)
    broken = rng.random(points.shape[:2]) < 0.3
    axis = rng.integers(0, 3, points.shape[:2])
    points[broken, axis[broken]] = rng.choice([np.nan, np.inf, -np.inf], broken.sum())
    assert (MOUNT[2, :3] == 0).any()  # a coordinate times a zero coefficient: NaN, no height
    for stack in (
        band_kernels.band_stack(points, MOUNT, 1.3, 2.1, 6),
        scan_row._band_stack_numpy(points, MOUNT, (1.3, 2.1)),
    ):
        finite = np.isfinite(stack)
        assert finite.all(axis=-1).sum() > 20
        np.testing.assert_array_equal(finite.all(axis=-1), finite.any(axis=-1))


def test_the_loop_loaded_meanwhile_is_the_one_picking(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(7)
    points = cluttered_stack(rng, width=64).repeat(4, axis=0)  # 24 rows
    compiled.load_band_stack_meanwhile().join()
    assert compiled.loaded_band_kernels() is band_kernels
    picked = []
    loop = band_kernels.band_stack
    monkeypatch.setattr(band_kernels, "band_stack", lambda *args: picked.append(1) or loop(*args))
    stack = band_stack(points, MOUNT, (1.3, 2.1))
    assert picked == [1]
    np.testing.assert_array_equal(stack, scan_row._band_stack_numpy(points, MOUNT, (1.3, 2.1)))
