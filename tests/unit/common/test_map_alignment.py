"""Aligning two maps by their walls: the transform found against the one that made the maps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallmap.common.map_alignment import (
    Walls,
    align,
    point_line_jacobian,
    point_line_residuals,
)
from wallmap.scene.floorplan import generate_floorplan


def _seen_from(segments: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """Segments of the world as a robot whose map frame lies at ``frame`` has them."""
    c, s = math.cos(frame[2]), math.sin(frame[2])
    return (segments - frame[:2]) @ np.array([[c, -s], [s, c]])


def _solid_walls(seed: int, layout: str) -> np.ndarray:
    plan = generate_floorplan(seed, layout=layout)
    return np.array([[w.p0, w.p1] for w in plan.walls if not w.glass])


def test_the_residuals_jacobian_is_their_derivative() -> None:
    rng = np.random.default_rng(3)
    pose = np.array([1.2, -0.4, 2.3])
    points = rng.normal(0, 4, (6, 2))
    normal = rng.normal(0, 1, (6, 2))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    rho = rng.normal(0, 3, 6)
    numeric = np.column_stack(
        [
            (
                point_line_residuals(pose + h, points, normal, rho)
                - point_line_residuals(pose - h, points, normal, rho)
            )
            / 2e-6
            for h in 1e-6 * np.eye(3)
        ]
    )
    assert np.allclose(point_line_jacobian(pose, points, normal), numeric, atol=1e-7)


@pytest.mark.parametrize(
    ("seed", "layout"), [(s, k) for s in range(4) for k in ("rooms", "corridor")]
)
def test_a_partial_noisy_map_is_placed_to_the_centimetre(seed: int, layout: str) -> None:
    """B has 80 % of the walls, each end 1 cm off, in a frame turned and moved anyhow."""
    rng = np.random.default_rng(seed)
    world = _solid_walls(seed, layout)
    frame = np.array([*rng.uniform(-6, 6, 2), rng.uniform(-math.pi, math.pi)])
    keep = rng.random(len(world)) < 0.8
    seen = _seen_from(world[keep], frame) + rng.normal(0, 0.01, world[keep].shape)
    found = align(Walls.of(world), Walls.of(seen))
    assert found is not None
    assert np.hypot(*(found.pose[:2] - frame[:2])) < 0.02
    assert abs(math.remainder(found.pose[2] - frame[2], 2 * math.pi)) < math.radians(0.1)
    assert found.matched >= 8
    assert found.runner_up < 0.7
    assert np.all(np.linalg.eigvalsh(found.cov) > 0), "a covariance"


def test_a_row_of_equal_rooms_seen_in_part_is_not_aligned() -> None:
    """Equal rooms in a row; B saw the walls of the middle two only (no outer end): it fits one
    room further along as well, so no alignment is given: wait for more of the map."""
    walls = [[(0, 0), (18, 0)], [(0, 4), (18, 4)]]
    walls += [[(x, 0.0), (x, 4.0)] for x in (0.0, 4.0, 8.0, 12.0, 18.0)]  # the last room longer
    world = np.array(walls, dtype=float)
    middle = np.array(
        [[(5.0, 0.0), (11.0, 0.0)], [(5.0, 4.0), (11.0, 4.0)], [(8.0, 0), (8.0, 4.0)]]
    )
    seen = _seen_from(middle, np.array([2.0, 1.0, 0.3]))
    assert align(Walls.of(world), Walls.of(seen)) is None
    seen_all = _seen_from(world, np.array([2.0, 1.0, 0.3]))
    found = align(Walls.of(world), Walls.of(seen_all))
    assert found is not None, "the whole row, with its longer last room, fits one way only"
    assert np.allclose(found.pose, [2.0, 1.0, 0.3], atol=1e-6)


def test_too_few_walls_give_no_alignment() -> None:
    world = _solid_walls(0, "rooms")
    assert align(Walls.of(world), Walls.of(world[:3])) is None
    assert align(Walls.of(world), Walls.of(np.zeros((0, 2, 2)))) is None
