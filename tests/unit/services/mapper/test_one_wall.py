"""One mapped wall per physical wall: collinear pieces across a gap, and T-junctions.

Observations are simulated as the detector reports them, for walls given in map coordinates;
each test drives the map through the situation and checks what it serves.
"""

from __future__ import annotations

import numpy as np
import pytest

from wallmap.common import se2
from wallmap.common.map_query import MapQuery
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.services.mapper import serving
from wallmap.services.mapper.wall_map import WallMap

NOISE = 0.005
POSE_COV = np.diag([0.005**2, 0.005**2, np.radians(0.1) ** 2])  # a good localiser
RNG = np.random.default_rng(3)


def reply(wall_map, query=None) -> dict:
    """The map reply in the contract's plain form."""
    return serving.reply(wall_map, query).to_map()


def seen(wall, pose) -> WallObservation:
    """A wall (two map points) as the detector would report it from ``pose`` (x, y, yaw)."""
    rot = se2.rotation(pose[2])
    a, b = (rot.T @ (np.array(p, float) - pose[:2]) for p in wall)
    d = (b - a) / np.linalg.norm(b - a)
    closest = a - (a @ d) * d + RNG.normal(0, NOISE, 2)
    return WallObservation(closest, np.diag([NOISE**2, NOISE**2]), a, b, 40, NOISE)


def drive(wall_map: WallMap, frames, start: int = 0) -> None:
    """frames: per frame, (pose, walls seen, optional free-space ray ends in the map)."""
    for i, (where, walls, ends) in enumerate(frames, start=start):
        pose = np.asarray(where, float)
        rays = None
        if ends is not None:
            rot = se2.rotation(pose[2])
            rays = (np.asarray(ends, float) - pose[:2]) @ rot
        wall_map.integrate(
            Observations(
                "r",
                i,
                float(i),
                "base_link",
                [seen(w, pose) for w in walls],
                ray_origin=np.zeros(2) if rays is not None else None,
                rays=rays,
            ),
            Pose(float(i), *pose, cov=POSE_COV),
        )


def along_x(y: float, x0: float, x1: float):
    return ((x0, y), (x1, y))


def passing(n: int, x0: float, x1: float, y: float = -1.0):
    """Poses looking towards +y, moving along x."""
    return [(x0 + (x1 - x0) * i / (n - 1), y, np.pi / 2) for i in range(n)]


def served(wall_map: WallMap) -> list[dict]:
    return reply(wall_map, MapQuery())["walls"]


def two_pieces(gap: float, rays_through: bool = False, offset: float = 0.0) -> WallMap:
    """A wall at y = 2 seen left of a gap first, then right of it: the gap [0, gap]."""
    wall_map = WallMap()
    left, right = along_x(2.0, -3.0, 0.0), along_x(2.0 + offset, gap, gap + 3.0)
    first = [(pose, [left], None) for pose in passing(10, -3.0, -0.5)]
    second = [
        (pose, [right], through(pose, gap) if rays_through else None)
        for pose in passing(10, gap + 0.5, gap + 3.0)
    ]
    drive(wall_map, first + second)
    return wall_map


def through(pose, gap: float) -> np.ndarray:
    """Rays from ``pose`` through the gap [0, gap] of the line y = 2, ending at y = 6."""
    aims = np.column_stack([np.linspace(0.1, gap - 0.1, 12), np.full(12, 2.0)])
    origin = np.asarray(pose[:2], float)
    return origin + (aims - origin) * (6.0 - origin[1]) / (2.0 - origin[1])


def test_a_wall_with_a_window_across_the_band_is_one_wall_with_a_gap() -> None:
    wall_map = two_pieces(2.0)  # a 2 m window: glass, nothing seen through it
    (wall,) = served(wall_map)
    assert wall["id"] == 0, "the older id survives"
    xs = np.sort(np.array(wall["segments"])[:, :, 0], axis=1)
    xs = xs[np.argsort(xs[:, 0])]
    assert len(xs) == 2
    assert xs[0, 1] == pytest.approx(0.0, abs=0.06)
    assert xs[1, 0] == pytest.approx(2.0, abs=0.06)
    assert wall_map.merges == [(1, 0, pytest.approx(19.0, abs=9.0))]
    assert 1 in serving.take_changes(wall_map).to_map()["removed"]


def test_pieces_too_far_apart_stay_two_walls() -> None:
    assert len(served(two_pieces(4.5))) == 2


def test_pieces_across_an_unseen_stretch_of_glass_are_one_wall() -> None:
    """3.5 m that nothing was seen through (glass returns no depth): within merge_gap, 4 m."""
    assert len(served(two_pieces(3.5))) == 1


def test_a_door_seen_through_is_still_a_door_but_a_wide_opening_seen_through_is_not() -> None:
    assert len(served(two_pieces(1.5, rays_through=True))) == 1, "a door: one wall"
    assert len(served(two_pieces(2.5, rays_through=True))) == 2, "seen through, wider than a door"
    assert len(served(two_pieces(2.5, rays_through=False))) == 1, "a window or an occlusion"


def test_parallel_pieces_a_few_centimetres_apart_are_two_walls() -> None:
    """A step in a wall (a pilaster, a recess): 6 cm is well within the fixed guard of 10 cm,
    but not within what the estimates' covariances allow."""
    assert len(served(two_pieces(1.5, offset=0.06))) == 2
    assert len(served(two_pieces(1.5, offset=0.005))) == 1


def test_a_wall_crossing_the_gap_keeps_the_pieces_apart() -> None:
    wall_map = WallMap()
    left, right = along_x(2.0, -3.0, 0.0), along_x(2.0, 1.5, 4.5)
    crossing = ((0.75, 0.5), (0.75, 4.0))  # passes through the line between the pieces
    frames = [(pose, [left, crossing], None) for pose in passing(10, -3.0, -0.5)]
    frames += [(pose, [right, crossing], None) for pose in passing(10, 2.0, 4.5)]
    drive(wall_map, frames)
    assert len(served(wall_map)) == 3


def test_a_t_at_the_origin_cuts_only_the_wall_that_ends_there() -> None:
    """The outer wall y = 0 runs through the map origin; a corridor wall x = 0 ends on it.

    From the left room the outer wall is seen up to the junction; from the right room from
    1.2 m past it (the corridor wall hides the rest), so it is first mapped as two pieces.
    """
    wall_map = WallMap()
    outer_left, outer_right = along_x(0.0, -5.0, 0.0), along_x(0.0, 1.2, 5.0)
    stem = ((0.0, 0.0), (0.0, 4.0))
    room = [((x, 2.5, -np.pi / 2)) for x in np.linspace(-4.5, -0.8, 12)]
    other = [((x, 2.5, -np.pi / 2)) for x in np.linspace(0.8, 4.5, 12)]
    frames = [(pose, [outer_left, stem], None) for pose in room]
    frames += [(pose, [outer_right, stem], None) for pose in other]
    drive(wall_map, frames)
    walls = served(wall_map)
    assert len(walls) == 2, "the outer wall is one wall, not cut at the junction"
    outer = next(w for w in walls if abs(w["v"]) < 0.05 and abs(w["p1"][0] - w["p0"][0]) > 5)
    xs = np.array(outer["segments"])[:, :, 0]
    assert xs.min() < -4.9
    assert xs.max() > 4.9
    corridor = next(w for w in walls if w is not outer)
    ends = np.array([corridor["p0"], corridor["p1"]])
    assert np.min(np.linalg.norm(ends, axis=1)) < 0.02, "the stem ends at the origin"


def test_an_l_corner_still_joins_both_ends() -> None:
    wall_map = WallMap()
    a = ((-4.0, 3.0), (0.3, 3.0))  # overshoots the corner at (0, 3) a little
    b = ((0.0, 3.2), (0.0, -1.0))
    frames = [(pose, [a, b], None) for pose in [((x, 0.5, 2.3)) for x in np.linspace(-3, -1, 12)]]
    drive(wall_map, frames)
    walls = served(wall_map)
    assert len(walls) == 2
    for wall in walls:
        ends = np.array([wall["p0"], wall["p1"]])
        assert np.min(np.linalg.norm(ends - [0.0, 3.0], axis=1)) < 0.02
