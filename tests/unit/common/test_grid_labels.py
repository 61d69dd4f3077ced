"""Connected components, outlines and simplification against brute-force statements."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from wallmap.common.grid_labels import (
    convex_hull,
    inside_polygon,
    label,
    outline,
    polygon_area,
    polygon_centroid,
    simplify,
    spread,
    touches_border,
)


def _bfs_components(mask: np.ndarray) -> list[set[tuple[int, int]]]:
    seen, parts = set(), []
    for start in zip(*np.nonzero(mask), strict=True):
        if start in seen:
            continue
        part, todo = set(), deque([start])
        seen.add(start)
        while todo:
            i, j = todo.popleft()
            part.add((i, j))
            for a, b in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
                inside = 0 <= a < mask.shape[0] and 0 <= b < mask.shape[1]
                if inside and mask[a, b] and (a, b) not in seen:
                    seen.add((a, b))
                    todo.append((a, b))
        parts.append(part)
    return parts


@pytest.mark.parametrize("seed", range(8))
def test_labels_are_the_four_connected_components(seed: int) -> None:
    mask = np.random.default_rng(seed).random((40, 55)) < 0.55
    labels, n = label(mask)
    expected = _bfs_components(mask)
    assert n == len(expected)
    assert (labels >= 0).sum() == mask.sum()
    assert (labels[~mask] == -1).all()
    for part in expected:
        values = {int(labels[c]) for c in part}
        assert len(values) == 1, "a component has one label"
    assert len({int(labels[next(iter(p))]) for p in expected}) == n, "and no two share one"


def test_a_serpentine_is_one_component_labelled_row_major() -> None:
    """A long chain of runs, each joined to the last only at one end: the joining rounds must
    carry one label the whole way. Components are numbered by their first cell, row-major."""
    mask = np.zeros((41, 30), dtype=bool)
    mask[::2, 1:-1] = True
    mask[1::4, -2] = True
    mask[3::4, 1] = True
    island = (1, 0)
    mask[island] = True
    labels, n = label(mask)
    assert n == 2
    assert labels[0, 1] == 0, "the serpentine's first cell comes first"
    assert labels[island] == 1
    assert set(np.unique(labels[mask]).tolist()) == {0, 1}
    assert (labels == 1).sum() == 1


def test_a_region_reaching_the_edge_is_open() -> None:
    mask = np.zeros((10, 10), dtype=bool)
    mask[2:5, 2:5] = True  # enclosed
    mask[7:, 0:3] = True  # on the edge
    labels, n = label(mask)
    border = touches_border(labels, n)
    assert border[labels[8, 1]]
    assert not border[labels[3, 3]]


def test_an_outline_encloses_its_cells_counter_clockwise() -> None:
    mask = np.zeros((12, 12), dtype=bool)
    mask[1:9, 1:4] = True
    mask[1:4, 1:10] = True  # an L of 8x3 + 3x6 cells
    loop = outline(mask)
    assert polygon_area(loop) == pytest.approx(mask.sum()), "counter-clockwise, cell units"
    corners = simplify(loop, 0.1)
    assert len(corners) == 6, "an L has six corners"
    centres = np.argwhere(np.ones_like(mask)) + 0.5
    assert (inside_polygon(centres, loop) == mask.ravel()).all()


def test_an_outline_is_the_outer_boundary_of_a_region_with_a_hole() -> None:
    mask = np.zeros((9, 9), dtype=bool)
    mask[1:8, 1:8] = True
    mask[3:6, 3:6] = False
    assert polygon_area(outline(mask)) == pytest.approx(49.0)


def test_simplify_keeps_a_jagged_diagonal_within_tolerance() -> None:
    steps = np.array([[i // 2 + (i % 2), i // 2] for i in range(40)], dtype=float)
    closed = np.vstack([steps, [[0.0, 19.0]]])
    simple = simplify(closed, 0.8)
    assert len(simple) <= 4
    assert polygon_centroid(np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)) == pytest.approx(
        [1.0, 1.0]
    )


def test_the_convex_hull_holds_every_point_and_only_corners() -> None:
    points = np.random.default_rng(3).random((200, 2)) * 10
    hull = convex_hull(points)
    assert polygon_area(hull) > 0
    assert inside_polygon(points * 0.999 + 0.005, hull).mean() > 0.97
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4], [2, 2], [2, 0]], dtype=float)
    assert sorted(map(tuple, convex_hull(square))) == [(0, 0), (0, 4), (4, 0), (4, 4)]


def test_spread_lists_each_groups_items_with_their_places() -> None:
    counts = np.array([2, 0, 3, 1])
    group, place = spread(counts)
    expected = [(g, k) for g, n in enumerate(counts) for k in range(n)]
    assert list(zip(group.tolist(), place.tolist(), strict=True)) == expected
    assert [len(x) for x in spread(np.zeros(0, dtype=np.int64))] == [0, 0]
