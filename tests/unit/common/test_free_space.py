"""The floor seen free: rays counted up to short of their ends, a grid that grows, a state."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wallmap.common import se2
from wallmap.common.free_space import CELL, MIN_FREE, RAY_SHORT, FreeSpace, _disc_offsets

Array = NDArray[np.float64]


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


def _counted_in_numpy(space: FreeSpace, frames: list[tuple[Array, Array, Array | None]]) -> None:
    """``add_frames`` written out in numpy: every sample made, then counted (the spec)."""
    points = []
    for pose, origin, ends in frames:
        rot = se2.rotation(float(pose[2]))
        start = pose[:2] + rot @ origin
        disc = start + _disc_offsets(space.cell)
        if ends is None or not len(ends):
            points.append(disc)
            continue
        rays = pose[:2] + ends @ rot.T - start
        length = np.hypot(rays[:, 0], rays[:, 1])
        usable = length - RAY_SHORT
        keep = usable > 0
        if not keep.any():
            points.append(disc)
            continue
        rays, length, usable = rays[keep], length[keep], usable[keep]
        step = 0.5 * space.cell
        along = np.arange(int(np.ceil(usable.max() / step)) + 1)[None, :] * step
        unit = rays / length[:, None]
        samples = start + along[..., None] * unit[:, None, :]
        points += [samples[along <= usable[:, None]], disc]
    space.add_points(np.concatenate(points))


def test_the_compiled_count_is_numpys_to_the_cell() -> None:
    """Batches of frames (poses anywhere, rays of every length, some too short, some frames
    without rays) give the grid numpy's samples give: counts, origin and shape."""
    rng = np.random.default_rng(3)
    compiled, spec = FreeSpace(), FreeSpace()
    # Rays whose last sample falls exactly at their usable length, from a pose at the origin.
    step = 0.5 * CELL
    exact = np.array([[RAY_SHORT + m * step, 0.0] for m in range(1, 40)])
    for batch in range(61):
        frames = [(np.zeros(3), np.zeros(2), exact)] if batch == 0 else []
        for _ in range(int(rng.integers(1, 5)) if batch else 0):
            pose = np.array([*rng.uniform(-30, 30, 2), rng.uniform(-np.pi, np.pi)])
            n = int(rng.choice([0, 1, 40, 320]))
            ends = rng.uniform(-8, 8, (n, 2)) * rng.choice([0.01, 1.0])
            frames.append(
                (pose, rng.uniform(-0.3, 0.3, 2), ends if n or rng.random() < 0.5 else None)
            )
        compiled.add_frames(frames)
        _counted_in_numpy(spec, frames)
        assert compiled.counts.shape == spec.counts.shape
        np.testing.assert_array_equal(compiled.origin, spec.origin)
        np.testing.assert_array_equal(compiled.counts, spec.counts)
    assert compiled.counts.max() == 255
    assert (compiled.counts == 1).any()
