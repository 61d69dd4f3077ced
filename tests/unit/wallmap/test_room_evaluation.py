"""Rooms scored against truth: matches, false and split rooms, doors and the rooms they join."""

from __future__ import annotations

import numpy as np
import pytest

from wallmap.common.free_space import MIN_FREE, FreeSpace
from wallmap.room_evaluation import evaluate_rooms, iou, seen_shares
from wallmap.scene.floorplan import Door, FloorPlan, Room

SQUARE = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]
NEXT = [[4.0, 0.0], [8.0, 0.0], [8.0, 4.0], [4.0, 4.0]]
PLAN = FloorPlan(
    walls=(),
    rooms=(Room(0, tuple(map(tuple, SQUARE))), Room(1, tuple(map(tuple, NEXT)))),
    doors=(Door(0, (4.0, 1.5), (4.0, 2.5), (0, 1)),),
)


def _room(room_id: int, polygon: list) -> dict:
    return {"id": room_id, "polygon": polygon}


def _door(rooms: list[int], centre_y: float = 2.0) -> dict:
    return {"id": 0, "center": [4.0, centre_y], "width": 1.1, "rooms": rooms}


def test_iou_of_a_square_and_its_half() -> None:
    half = [[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]]
    assert iou(SQUARE, SQUARE) == pytest.approx(1.0)
    assert iou(SQUARE, half) == pytest.approx(0.5, abs=0.03)


def test_the_truth_itself_scores_perfectly_under_other_ids() -> None:
    body = {"rooms": [_room(7, NEXT), _room(3, SQUARE)], "doors": [_door([3, 7])]}
    score = evaluate_rooms(body, PLAN)
    assert score.matched == {3: 0, 7: 1}
    assert min(score.ious.values()) == pytest.approx(1.0, abs=0.02)
    assert (score.false, score.split) == (0, 0)
    assert (score.doors_found, score.doors_joined) == (1, 1)
    assert score.width_err == pytest.approx(0.1)
    assert "rooms entered 2 of 2 found" in score.summary()


def test_a_split_room_a_false_room_and_a_door_to_the_wrong_room() -> None:
    left = [[0.0, 0.0], [2.0, 0.0], [2.0, 4.0], [0.0, 4.0]]
    right = [[2.0, 0.0], [4.0, 0.0], [4.0, 4.0], [2.0, 4.0]]
    far = [[20.0, 0.0], [22.0, 0.0], [22.0, 2.0], [20.0, 2.0]]
    body = {
        "rooms": [_room(1, left), _room(2, right), _room(5, NEXT), _room(9, far)],
        "doors": [_door([2, 9]), _door([5], centre_y=30.0)],
    }
    score = evaluate_rooms(body, PLAN)
    assert (score.split, score.false) == (1, 1)
    assert score.doors_found == 1
    assert score.doors_joined == 0


def test_only_the_rooms_the_robot_entered_and_the_doors_between_them_are_asked_for() -> None:
    path = [[1.0, 1.0], [2.0, 2.0]]  # in the first room only: the second glimpsed
    body = {"rooms": [_room(3, SQUARE)], "doors": []}
    score = evaluate_rooms(body, PLAN, path)
    assert score.entered == {0}
    assert score.entered_ious == [pytest.approx(1.0, abs=0.02)]
    assert score.false == 0
    assert score.truth_doors == 0  # the door leads to a room not entered
    assert "rooms entered 1 of 1 found" in score.summary()
    walked = evaluate_rooms(body, PLAN, [[1.0, 1.0], [6.0, 2.0]])
    assert walked.entered_ious == [pytest.approx(1.0, abs=0.02), 0.0]
    assert (walked.truth_doors, walked.doors_found) == (1, 0)


def test_the_seen_share_is_of_the_floor_near_floor_seen_free() -> None:
    """A robot that saw the left half of the first room: that half and 0.3 m past it count,
    the other room not at all."""
    free = FreeSpace()
    xs, ys = np.meshgrid(np.arange(0.05, 2.0, 0.1), np.arange(0.05, 4.0, 0.1))
    free.add_points(np.repeat(np.stack([xs.ravel(), ys.ravel()], axis=1), MIN_FREE, axis=0))
    shares = seen_shares({0: np.array(SQUARE), 1: np.array(NEXT)}, free)
    assert shares[0] == pytest.approx(2.3 / 4.0, abs=0.02)
    assert shares[1] == 0.0
    score = evaluate_rooms({"rooms": [], "doors": []}, PLAN, [[1.0, 1.0]], free)
    assert score.seen == {0: pytest.approx(0.575, abs=0.02)}
    assert f"floor seen min {score.seen[0]:.2f}" in score.summary()
    assert evaluate_rooms({"rooms": [], "doors": []}, PLAN, [[1.0, 1.0]]).seen == {}
