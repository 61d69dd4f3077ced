"""Keyframes that still say where every frame was: the straight-line test."""

from __future__ import annotations

import math

from wallmap.common.keyframes import interpolates

TOLERANCE = (0.01, math.radians(0.2))


def test_poses_on_the_line_between_two_keyframes_are_held_by_it() -> None:
    between = [(0.5, 0.5, 0.0, 0.05), (0.75, 0.75, 0.0, 0.075)]
    assert interpolates((0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.1), between, *TOLERANCE)
    assert interpolates((0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.1), [], *TOLERANCE)


def test_a_pose_off_the_line_by_more_than_the_tolerance_is_not() -> None:
    first, last = (0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.0)
    assert not interpolates(first, last, [(0.5, 0.5, 0.02, 0.0)], *TOLERANCE)
    assert not interpolates(first, last, [(0.5, 0.5, 0.0, math.radians(0.5))], *TOLERANCE)


def test_headings_interpolate_across_the_wrap() -> None:
    first, last = (0.0, 0.0, 0.0, math.pi - 0.01), (1.0, 0.0, 0.0, -math.pi + 0.01)
    assert interpolates(first, last, [(0.5, 0.0, 0.0, math.pi)], *TOLERANCE)
