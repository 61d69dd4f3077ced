"""Fusing robots' walls: placed in the fleet's frame exactly, each physical wall once, ids kept."""

from __future__ import annotations

import math

import numpy as np

from wallmap.common import se2
from wallmap.common.map_fusion import FleetIds, FuseConfig, fuse_walls, place
from wallmap.common.map_records import WallRecord


def _wall(
    wall_id: int, p: tuple[float, float], q: tuple[float, float], n_obs: int = 10
) -> WallRecord:
    return WallRecord.from_segment(wall_id, p, q, n_obs, cov=((4e-4, 1e-5), (1e-5, 2e-4)))


def _closest_point(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    d = q - p
    normal = np.array([-d[1], d[0]]) / np.hypot(*d)
    return (normal @ p) * normal


def test_a_placed_wall_is_the_wall_moved_and_its_covariance_the_jacobians_of_it() -> None:
    wall = _wall(3, (1.0, 2.0), (4.0, 3.5))
    pose = np.array([2.0, -1.5, 0.7])
    pose_cov = np.diag([1e-4, 2e-4, 1e-5])
    moved = place(wall, pose, pose_cov)
    p, q = se2.transform_points(np.array([wall.p0, wall.p1]), pose)
    assert np.allclose([moved.p0, moved.p1], [p, q])
    assert np.allclose([moved.u, moved.v], _closest_point(p, q))

    def closest(s: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """(u, v) of the line of closest point ``s`` after moving by ``frame``, by its points."""
        d = np.array([-s[1], s[0]])
        ends = se2.transform_points(np.array([s, s + d]), frame)
        return _closest_point(*ends)

    s = np.array([wall.u, wall.v])
    h = 1e-6
    j_wall = np.column_stack(
        [(closest(s + e, pose) - closest(s - e, pose)) / (2 * h) for e in h * np.eye(2)]
    )
    j_pose = np.column_stack(
        [(closest(s, pose + e) - closest(s, pose - e)) / (2 * h) for e in h * np.eye(3)]
    )
    expected = j_wall @ np.array(wall.cov) @ j_wall.T + j_pose @ pose_cov @ j_pose.T
    assert np.allclose(moved.cov, expected, rtol=1e-5, atol=1e-12)


def test_each_physical_wall_is_fused_once_and_a_robots_overlapping_walls_never() -> None:
    a = [
        _wall(1, (0.0, 1.0), (5.0, 1.0)),
        _wall(2, (6.0, 1.02), (9.0, 1.02)),  # a's wall beyond a gap, on the same line
        _wall(3, (1.0, 1.0), (1.0, 5.0)),
        _wall(4, (2.0, 8.0), (6.0, 8.0)),  # the two faces of a thin wall, both seen by a
        _wall(5, (2.0, 8.1), (6.0, 8.1)),
    ]
    b = [
        _wall(7, (3.0, 1.03), (8.0, 1.03)),  # across a's gap: a's two pieces are one wall
        _wall(8, (1.02, 3.5), (1.02, 7.0)),  # overlaps a's wall 3
        _wall(9, (12.0, 1.0), (14.0, 1.0)),  # on the line, 3 m past a's walls: its own
        _wall(10, (2.0, 8.05), (6.0, 8.05)),  # between the faces: joins one of them only
    ]
    fused = fuse_walls([("a", w) for w in a] + [("b", w) for w in b])
    groups = sorted(sorted(sources) for _, sources in fused)
    assert [("a", 1), ("a", 2), ("b", 7)] in groups
    assert [("a", 3), ("b", 8)] in groups
    assert [("b", 9)] in groups
    faces = [g for g in groups if {("a", 4), ("a", 5)} & set(g)]
    assert len(faces) == 2, "a's overlapping walls stay two"
    assert sorted(len(g) for g in faces) == [1, 2]
    wall = next(w for w, sources in fused if ("b", 8) in sources)
    assert wall.n_obs == 20
    assert np.allclose([wall.p0, wall.p1], [(1.01, 1.0), (1.01, 7.0)], atol=0.02)
    assert abs(wall.u - 1.01) < 0.011
    assert abs(wall.v) < 1e-9
    pieces = next(w for w, sources in fused if ("b", 7) in sources)
    assert len(pieces.segments) == 1, "a's gap is covered by b's wall: one stretch"


def test_a_gap_wider_than_join_gap_keeps_two_walls() -> None:
    a, b = _wall(1, (0.0, 1.0), (3.0, 1.0)), _wall(2, (3.5, 1.0), (6.0, 1.0))
    assert len(fuse_walls([("a", a), ("b", b)])) == 1
    assert len(fuse_walls([("a", a), ("b", b)], FuseConfig(join_gap=0.3))) == 2
    rise = 1.5 * math.tan(math.radians(10.0))  # turned about a's middle: the lines cross there
    turned = _wall(3, (0.0, 1.0 - rise), (3.0, 1.0 + rise))
    assert len(fuse_walls([("a", a), ("b", turned)])) == 2, "10 degrees apart: two walls"


def test_fleet_ids_stay_and_a_merge_is_reported() -> None:
    ids = FleetIds()
    first, merges = ids.assign([(("a", 1),), (("b", 7),), (("a", 2),)])
    assert first == [0, 1, 2]
    assert merges == []
    again, merges = ids.assign([(("a", 2),), (("a", 1), ("b", 7)), (("b", 9),)])
    assert again[0] == 2, "the same sources, the same id"
    assert again[1] in (0, 1)
    assert merges == [(1 - again[1], again[1])], "the other id was merged into it"
    assert again[2] == 3, "new, and never a reused id"


def test_a_long_wall_a_few_degrees_off_is_one_wall_and_a_parallel_wall_beside_it_is_not() -> None:
    """The Jackal arena's left wall as two robots placed it: 2.6 m, 4.5 degrees apart, the ends
    12-13 cm apart while the lines cross at the middle (one robot's odometry drifted there)."""
    a = _wall(1, (-0.671, 0.634), (-0.496, -1.924))
    b = _wall(2, (-0.795, 0.648), (-0.414, -1.936))
    assert len(fuse_walls([("a", a), ("b", b)])) == 1
    beside = _wall(3, (-0.871, 0.634), (-0.696, -1.924))  # a's wall moved 20 cm: another wall
    assert len(fuse_walls([("a", a), ("b", beside)])) == 2
