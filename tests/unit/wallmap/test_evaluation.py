import math

import numpy as np
import pytest

from wallmap.evaluation import evaluate_map, mapped_line, physical_walls
from wallmap.scene import FloorPlan, Wall, generate_floorplan


def as_mapped(p0, p1, wall_id=None):
    """A mapped wall dict for the segment p0→p1: (u, v) is its line's closest point to 0."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    closest = p0 - (p0 @ d) * d
    wall = {"u": float(closest[0]), "v": float(closest[1]), "p0": p0.tolist(), "p1": p1.tolist()}
    if wall_id is not None:
        wall["id"] = wall_id
    return wall


def shifted(wall, distance):
    p0, p1 = np.asarray(wall.p0), np.asarray(wall.p1)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    n = np.array([-d[1], d[0]])
    return as_mapped(p0 + distance * n, p1 + distance * n)


def rotated(wall, degrees):
    p0, p1 = np.asarray(wall.p0), np.asarray(wall.p1)
    mid = (p0 + p1) / 2
    a = math.radians(degrees)
    r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return as_mapped(mid + r @ (p0 - mid), mid + r @ (p1 - mid))


SQUARE = FloorPlan(
    walls=(
        Wall(0, (1.0, -2.0), (5.0, -2.0)),
        Wall(1, (5.0, -2.0), (5.0, 2.0)),
        Wall(2, (5.0, 2.0), (1.0, 2.0)),
        Wall(3, (1.0, 2.0), (1.0, -2.0), glass=True),
    )
)
ALL_SEEN = {0: 10, 1: 10, 2: 10, 3: 10}


def test_perfect_map_of_a_generated_plan_scores_one():
    """One mapped wall per physical wall: the pieces either side of a doorway are one wall."""
    plan = generate_floorplan(4)
    groups = physical_walls(plan)
    assert any(len(g) == 2 for g in groups), "the plan has walls with doorways"
    mapped = []
    for pieces in groups:
        ends = np.array([p for w in pieces for p in (w.p0, w.p1)], dtype=float)
        along = ends[1] - ends[0]
        order = np.argsort(ends @ along)
        wall = as_mapped(ends[order[0]], ends[order[-1]], pieces[0].id)
        wall["segments"] = [[list(w.p0), list(w.p1)] for w in pieces]
        mapped.append(wall)
    seen = {w.id: 20 for w in plan.walls}

    score = evaluate_map(mapped, plan, seen)

    assert score.precision == 1.0
    assert score.recall == 1.0
    assert score.duplicates == 0
    assert score.median_angle_deg == pytest.approx(0.0, abs=1e-6)
    assert score.median_offset_m == pytest.approx(0.0, abs=1e-9)
    assert score.median_endpoint_m == pytest.approx(0.0, abs=1e-9)
    assert score.n_true == len(groups)
    # Mapped piece by piece instead, a wall with a doorway comes out twice: a duplicate.
    pieces = [as_mapped(w.p0, w.p1, w.id) for w in plan.walls if not w.glass]
    split = evaluate_map(pieces, plan, seen)
    assert split.duplicates == sum(len(g) > 1 for g in groups)
    assert split.precision == 1.0
    assert split.recall == 1.0


def test_end_point_error_of_walls_mapped_20_cm_short_at_one_end():
    plan = generate_floorplan(4)
    mapped = []
    for w in plan.walls:
        if not w.glass:
            p0, p1 = np.asarray(w.p0), np.asarray(w.p1)
            # Reversed, to show that each mapped end is compared with the nearer true end.
            mapped.append(as_mapped(p1 - 0.2 * (p1 - p0) / w.length, p0))

    score = evaluate_map(mapped, plan, {w.id: 20 for w in plan.walls})

    assert score.precision == 1.0
    assert score.median_offset_m == pytest.approx(0.0, abs=1e-9)
    assert score.median_endpoint_m == pytest.approx(0.1)  # mean of 0 and 0.2


def test_end_point_error_shows_a_wall_merged_across_two():
    plan = FloorPlan(walls=(Wall(0, (0.0, 3.0), (2.0, 3.0)), Wall(1, (2.0, 3.0), (4.0, 3.0))))

    score = evaluate_map([as_mapped((0.0, 3.0), (4.0, 3.0))], plan, {0: 5, 1: 5})

    # Each true wall has one mapped end on its own end and the other 2 m past it.
    assert score.median_endpoint_m == pytest.approx(1.0)


def test_end_point_error_of_a_wall_with_a_door_uses_its_segments():
    # Two walls on one line with a 1 m door between them, mapped as one wall whose segments
    # stop 10 cm short of the jambs.
    plan = FloorPlan(walls=(Wall(0, (0.0, 3.0), (2.0, 3.0)), Wall(1, (3.0, 3.0), (5.0, 3.0))))
    wall = as_mapped((0.0, 3.0), (5.0, 3.0))
    wall["segments"] = [[[0.0, 3.0], [1.9, 3.0]], [[3.1, 3.0], [5.0, 3.0]]]

    score = evaluate_map([wall], plan, {0: 5, 1: 5})

    assert score.recall == 1.0
    assert score.median_endpoint_m == pytest.approx(0.05)


def test_shift_of_20_cm_does_not_match_but_10_cm_does():
    far = evaluate_map([shifted(SQUARE.walls[1], 0.20)], SQUARE, ALL_SEEN)
    near = evaluate_map([shifted(SQUARE.walls[1], -0.10)], SQUARE, ALL_SEEN)

    assert far.precision == 0.0
    assert far.unmatched_mapped == [0]
    assert 1 in far.unmatched_true
    assert near.precision == 1.0
    assert near.median_offset_m == pytest.approx(0.10)
    assert near.recall == pytest.approx(1 / 3)


def test_angle_limit_is_five_degrees():
    tilted = evaluate_map([rotated(SQUARE.walls[0], 4.0)], SQUARE, ALL_SEEN)
    too_tilted = evaluate_map([rotated(SQUARE.walls[0], 6.0)], SQUARE, ALL_SEEN)

    assert tilted.precision == 1.0
    assert tilted.median_angle_deg == pytest.approx(4.0)
    # Rotated about the midpoint, the mapped line passes through the overlap's middle.
    assert tilted.median_offset_m == pytest.approx(0.0, abs=1e-9)
    assert too_tilted.precision == 0.0


def test_duplicate_walls_are_counted_and_best_match_is_reported():
    mapped = [
        as_mapped((1.0, -2.0), (5.0, -2.0)),
        shifted(SQUARE.walls[0], 0.05),
        as_mapped((5.0, -2.0), (5.0, 2.0)),
    ]

    score = evaluate_map(mapped, SQUARE, ALL_SEEN)

    assert score.duplicates == 1
    assert score.precision == 1.0
    assert score.median_offset_m == pytest.approx(0.0, abs=1e-9)


def test_extents_must_overlap():
    beyond_the_end = as_mapped((5.5, -2.0), (7.0, -2.0))
    touching_the_end = as_mapped((4.0, -2.0), (7.0, -2.0))

    assert evaluate_map([beyond_the_end], SQUARE, ALL_SEEN).precision == 0.0
    assert evaluate_map([touching_the_end], SQUARE, ALL_SEEN).precision == 1.0


def test_offset_is_measured_at_the_middle_of_the_overlap():
    # Tilted 3 degrees about the wall's start (1, -2) and 1 m long: the overlap's middle
    # is 0.5 m along, 0.5 * sin(3 deg) = 2.6 cm from the mapped line; the true wall's far
    # end would be 21 cm away.
    a = math.radians(3.0)
    short = as_mapped((1.0, -2.0), (2.0, -2.0 + math.tan(a)))

    score = evaluate_map([short], SQUARE, ALL_SEEN)

    assert score.precision == 1.0
    assert score.median_offset_m == pytest.approx(0.5 * math.sin(a))


def test_wall_through_origin_uses_end_points_for_direction():
    plan = FloorPlan(walls=(Wall(0, (-2.0, -2.0), (2.0, 2.0)),))
    mapped = {"u": 0.0, "v": 0.0, "p0": [-1.0, -1.0], "p1": [1.5, 1.5], "id": "a"}
    slightly_off = {"u": 1e-4, "v": -1e-4, "p0": [-1.0, -1.0], "p1": [1.5, 1.5], "id": "b"}

    score = evaluate_map([mapped, slightly_off], plan, {0: 5})

    assert score.precision == 1.0
    assert score.recall == 1.0
    assert score.duplicates == 1
    assert score.median_angle_deg == pytest.approx(0.0, abs=1e-6)
    direction, offset = mapped_line(mapped)
    assert abs(direction @ np.array([1.0, 1.0])) == pytest.approx(math.sqrt(2))
    assert offset == 0.0


def test_parallel_line_through_origin_is_not_the_wall():
    # The true wall lies on y = 1; a mapped wall on y = 0 (through the origin) is 1 m off.
    plan = FloorPlan(walls=(Wall(0, (-2.0, 1.0), (2.0, 1.0)),))
    mapped = {"u": 0.0, "v": 0.0, "p0": [-1.0, 0.0], "p1": [1.0, 0.0]}

    assert evaluate_map([mapped], plan, {0: 5}).precision == 0.0


def test_glass_and_rarely_seen_walls_are_not_required():
    mapped = [as_mapped(w.p0, w.p1) for w in SQUARE.walls[:3]]
    seen = {0: 10, 1: 2, 2: 10, 3: 10}

    score = evaluate_map(mapped, SQUARE, seen)

    assert score.n_true == 2  # wall 1 seen too rarely, wall 3 is glass
    assert score.recall == 1.0
    assert score.precision == 1.0  # matching a rarely seen wall is still correct


def test_mapping_glass_is_a_false_positive():
    score = evaluate_map([as_mapped((1.0, 2.0), (1.0, -2.0))], SQUARE, ALL_SEEN)

    assert score.precision == 0.0
    assert score.recall == 0.0
    assert score.unmatched_true == [0, 1, 2]


def test_empty_map():
    score = evaluate_map([], SQUARE, ALL_SEEN)

    assert score.precision == 1.0
    assert score.n_mapped == 0
    assert score.recall == 0.0
    assert math.isnan(score.median_angle_deg)
    assert math.isnan(score.median_offset_m)
    assert math.isnan(score.median_endpoint_m)


def test_one_long_mapped_wall_over_two_collinear_walls_counts_once():
    plan = FloorPlan(walls=(Wall(0, (0.0, 3.0), (2.0, 3.0)), Wall(1, (2.0, 3.0), (4.0, 3.0))))

    score = evaluate_map([as_mapped((0.0, 3.0), (4.0, 3.0))], plan, {0: 5, 1: 5})

    assert score.n_mapped_matched == 1
    assert score.precision == 1.0
    assert score.recall == 1.0
    assert score.duplicates == 0
