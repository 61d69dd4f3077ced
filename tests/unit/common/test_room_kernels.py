"""Room segmentation's compiled loops, each against the plain numpy it stands for."""

import numpy as np
import pytest

from wallmap.common import room_kernels


@pytest.mark.parametrize("seed", range(3))
def test_near_pairs_are_the_points_in_each_box_by_point_then_box(seed: int) -> None:
    rng = np.random.default_rng(seed)
    points = rng.uniform(0.0, 10.0, (60, 2))
    lo = rng.uniform(0.0, 8.0, (40, 2))
    hi = lo + rng.uniform(0.0, 3.0, (40, 2))
    k, s = room_kernels.near_pairs(points, lo, hi)
    x, y = points[:, :1], points[:, 1:]
    want = np.nonzero((x >= lo[:, 0]) & (x <= hi[:, 0]) & (y >= lo[:, 1]) & (y <= hi[:, 1]))
    assert len(k) > 20
    np.testing.assert_array_equal(k, want[0])
    np.testing.assert_array_equal(s, want[1])


@pytest.mark.parametrize("seed", range(3))
def test_drawn_segments_are_the_cells_whose_centres_lie_within_the_radius(seed: int) -> None:
    """Every cell of the grid tested against every segment, at any angle."""
    rng = np.random.default_rng(seed)
    origin, cell, radius, shape = np.array([-20, 5], dtype=np.int64), 0.1, 0.13, (60, 50)
    p = (origin + rng.uniform(5, 45, (8, 2))) * cell
    q = p + rng.uniform(-1.5, 1.5, (8, 2))
    mask = np.zeros(shape, dtype=bool)
    lo = np.maximum(np.floor((np.minimum(p, q) - radius) / cell).astype(np.int64) - origin, 0)
    hi = np.minimum(
        np.floor((np.maximum(p, q) + radius) / cell).astype(np.int64) - origin,
        np.array(shape) - 1,
    )
    room_kernels.draw_segments(mask, lo, hi, p, q, origin, cell, radius)
    i, j = np.indices(shape)
    centres = (np.stack([i, j], axis=-1) + origin + 0.5) * cell
    want = np.zeros(shape, dtype=bool)
    for a, b in zip(p, q, strict=True):
        t = np.clip(((centres - a) @ (b - a)) / ((b - a) @ (b - a)), 0.0, 1.0)
        want |= np.hypot(*np.moveaxis(centres - a - t[..., None] * (b - a), -1, 0)) <= radius
    assert want.sum() > 100
    np.testing.assert_array_equal(mask, want)


def test_labels_grow_into_the_barrier_from_above_below_left_right_in_turn() -> None:
    """As four whole-grid shifts, each after the one before, would grow them."""
    rng = np.random.default_rng(4)
    labels = np.where(rng.random((30, 40)) < 0.3, rng.integers(0, 5, (30, 40)), -1).astype(np.int32)
    barrier = rng.random((30, 40)) < 0.5
    barrier[[0, -1]] = barrier[:, [0, -1]] = False  # the grid's edge is never barrier
    want = labels.copy()
    for _ in range(2):
        for shift, axis in ((1, 0), (-1, 0), (1, 1), (-1, 1)):
            moved = np.roll(want, shift, axis=axis)
            take = barrier & (want < 0) & (moved >= 0)
            want[take] = moved[take]
    room_kernels.grow(labels, barrier, 2)
    np.testing.assert_array_equal(labels, want)


def test_cells_come_grouped_by_label_row_major_with_their_counts() -> None:
    rng = np.random.default_rng(5)
    labels = rng.integers(-1, 4, (20, 30)).astype(np.int32)
    seen = rng.random((20, 30)) < 0.5
    origin = np.array([7, -3], dtype=np.int64)
    cells, ends = room_kernels.cells_by_label(labels, 4, origin)
    counts, seen_counts = room_kernels.label_counts(labels, 4, seen)
    for k, group in enumerate(np.split(cells, ends[:-1])):
        np.testing.assert_array_equal(group, np.argwhere(labels == k) + origin)
        assert counts[k] == (labels == k).sum()
        assert seen_counts[k] == ((labels == k) & seen).sum()


@pytest.mark.parametrize("seed", range(3))
def test_the_nearest_point_ahead_is_the_first_of_a_tie_in_kind_then_segment_order(
    seed: int,
) -> None:
    """Segments on a 0.5 m lattice, so that distances tie: a tie goes to the first of all
    segments' first ends, then their second ends, then the feet."""
    rng = np.random.default_rng(seed)
    a = rng.integers(0, 12, (30, 2)) * 0.5
    b = a + rng.integers(-4, 5, (30, 2)) * 0.5
    piece = rng.integers(0, 30, 40)
    point = np.where(rng.random((40, 1)) < 0.5, a[piece], b[piece])
    outward = rng.normal(size=(40, 2))
    outward /= np.hypot(*outward.T)[:, None]
    among = np.arange(0, 40, 2)
    reach, cos_max = 2.5, np.cos(np.radians(60.0))
    found = room_kernels.nearest_ahead(among, point, outward, piece, a, b, reach, cos_max)
    for k in range(40):
        rows = []  # (segment, point) in the order ties are settled
        for kind in range(3):
            for s in range(30):
                d = b[s] - a[s]
                t = np.clip((point[k] - a[s]) @ d / max(d @ d, 1e-12), 0.0, 1.0)
                rows.append((s, (a[s], b[s], a[s] + t * d)[kind]))
        best = None
        for s, target in rows:
            gap = target - point[k]
            dist = np.hypot(*gap)
            if s != piece[k] and 1e-6 < dist <= reach and gap @ outward[k] / dist >= cos_max:
                best = target if best is None or dist < np.hypot(*(best - point[k])) else best
        if k % 2 or best is None:
            assert np.isnan(found[k]).all()
        else:
            np.testing.assert_allclose(found[k], best, atol=1e-12)
