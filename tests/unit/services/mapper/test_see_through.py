"""What the sensor saw through is no wall; one surface seen as near-parallel lines is one wall."""

from __future__ import annotations

import numpy as np

from wallmap.common import se2
from wallmap.common.map_query import MapQuery
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.services.mapper import serving, state_file
from wallmap.services.mapper.wall_map import WallMap

NOISE = 0.01


def reply(wall_map, query=None) -> dict:
    """The map reply in the contract's plain form."""
    return serving.reply(wall_map, query).to_map()


def seen(wall: tuple[tuple[float, float], tuple[float, float]], pose: np.ndarray):
    """A wall (two map points) as the detector would report it from ``pose`` (x, y, yaw)."""
    rot = se2.rotation(pose[2])
    a, b = (rot.T @ (np.array(p) - pose[:2]) for p in wall)
    d = (b - a) / np.linalg.norm(b - a)
    closest = a - (a @ d) * d
    return WallObservation(closest, np.diag([NOISE**2, NOISE**2]), a, b, 40, NOISE)


def rays_to(far_x: float, pose: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Ray ends in the base frame: the map points (far_x, y) seen from ``pose``."""
    rot = se2.rotation(pose[2])
    return np.array([rot.T @ (np.array([far_x, y]) - pose[:2]) for y in ys])


def frames(n: int = 20):
    """Poses looking along +x from x = 0, drifting sideways, 0.2 m apart."""
    for i in range(n):
        yield i, np.array([0.0, -1.0 + 0.1 * i, 0.0])


def test_a_line_the_sensor_saw_through_is_not_served_and_the_wall_behind_is() -> None:
    wall_map = WallMap()
    phantom = ((2.0, -1.0), (2.0, 1.0))  # e.g. the tops of appliances joined into a line
    wall = ((4.0, -2.0), (4.0, 2.0))
    for i, pose in frames():
        # The phantom is reported from the first frames only; then rays pass it to the wall.
        walls = [seen(wall, pose)] + ([seen(phantom, pose)] if i < 5 else [])
        rays = None if i < 5 else rays_to(4.0, pose, np.linspace(-1.5, 1.5, 30))
        wall_map.integrate(
            Observations("r", i, float(i), "base_link", walls, ray_origin=np.zeros(2), rays=rays),
            Pose(float(i), *pose),
        )
    served = reply(wall_map, MapQuery())["walls"]
    assert len(served) == 1
    assert abs(served[0]["u"] - 4.0) < 0.05
    everything = reply(wall_map, MapQuery(tentative=True))["walls"]
    assert len(everything) == 2, "the phantom stays in the map, as tentative"


def test_a_door_seen_through_is_a_gap_in_its_wall() -> None:
    """A doorway the detector bridges in every third frame: the rays through it say it is open."""
    wall_map = WallMap()
    whole = ((3.0, -2.0), (3.0, 2.0))
    pieces = [((3.0, -2.0), (3.0, -0.4)), ((3.0, 0.4), (3.0, 2.0))]
    for i, pose in frames():
        rays = rays_to(6.0, pose, np.linspace(-0.3, 0.3, 12))  # through a doorway at |y| < 0.4
        walls = [seen(whole, pose)] if i % 3 == 0 else [seen(piece, pose) for piece in pieces]
        wall_map.integrate(
            Observations("r", i, float(i), "base_link", walls, ray_origin=np.zeros(2), rays=rays),
            Pose(float(i), *pose),
        )
    (record,) = reply(wall_map, MapQuery())["walls"]
    segments = np.array(record["segments"])
    assert len(segments) == 2, segments
    lows, highs = segments[:, :, 1].min(axis=1), segments[:, :, 1].max(axis=1)
    assert highs.min() < -0.2, "the doorway is open"
    assert lows.max() > 0.2


def test_rays_ending_on_a_wall_leave_it_whole_and_survive_the_state_file(tmp_path) -> None:
    wall_map = WallMap()
    wall = ((3.0, -2.0), (3.0, 2.0))
    for i, pose in frames():
        rays = rays_to(3.0, pose, np.linspace(-1.5, 1.5, 30))
        wall_map.integrate(
            Observations(
                "r", i, float(i), "base_link", [seen(wall, pose)], ray_origin=np.zeros(2), rays=rays
            ),
            Pose(float(i), *pose),
        )
    (record,) = reply(wall_map, MapQuery())["walls"]
    assert len(record["segments"]) == 1
    path = tmp_path / "map.json"
    state_file.write(path, state_file.to_json(wall_map))
    again = state_file.load(path, wall_map.config)
    np.testing.assert_array_equal(again.walls[0].extent.through, wall_map.walls[0].extent.through)


def test_two_lines_for_one_surface_serve_one_wall() -> None:
    """A fan: the same surface seen as two lines 5 degrees apart, crossing mid-way."""
    wall_map = WallMap()
    line_a = ((3.0, -1.5), (3.0, 1.5))
    tilt = np.radians(5.0)
    line_b = ((3.0 - 1.5 * np.sin(tilt), -1.5), (3.0 + 1.5 * np.sin(tilt), 1.5))
    for i, pose in frames():
        walls = [seen(line_a, pose)] + ([seen(line_b, pose)] if i % 2 else [])
        wall_map.integrate(
            Observations("r", i, float(i), "base_link", walls), Pose(float(i), *pose)
        )
    assert len(reply(wall_map, MapQuery(tentative=True))["walls"]) == 2
    (served,) = reply(wall_map, MapQuery())["walls"]
    assert served["n_obs"] == 20, "the better seen line is the one served"
