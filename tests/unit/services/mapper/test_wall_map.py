"""The wall map on observations simulated from known walls, the pose buffer and the state file."""

import json

import numpy as np
import pytest

from wallmap.common import se2
from wallmap.common.map_query import MapQuery
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.services.mapper import serving, state_file
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.pose_buffer import Lookup, PoseBuffer, PoseBufferConfig, SourcePose
from wallmap.services.mapper.wall_map import WallMap

# A non-Manhattan room of five walls with a doorway, and a free-standing wall through the origin.
WALLS = [
    ((-4.0, -3.0), (5.0, -2.0)),
    ((5.0, -2.0), (4.0, 4.0)),
    ((4.0, 4.0), (0.6, 4.3)),
    ((-0.6, 4.4), (-4.0, 4.7)),  # beyond a 1.2 m doorway
    ((-4.0, 4.7), (-4.0, -3.0)),
    ((-2.0, -2.0), (2.0, 2.0)),  # a free-standing wall on the line y = x, through the origin
]


def reply(wall_map, query=None) -> dict:
    """The map reply in the contract's plain form."""
    return serving.reply(wall_map, query).to_map()


def observe(pose, rng, noise=0.01, max_range=6.0):
    """What the detector would report: visible walls as closest point, covariance, extent."""
    x, y, yaw = pose
    rot = se2.rotation(yaw)
    out = []
    for a, b in WALLS:
        p0, p1 = np.array(a), np.array(b)
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        t = np.linspace(0, np.linalg.norm(p1 - p0), 40)
        pts = p0 + t[:, None] * d
        rel = (pts - [x, y]) @ rot  # robot frame
        keep = (np.linalg.norm(rel, axis=1) < max_range) & (rel[:, 0] > 0.3)
        if keep.sum() < 10:
            continue
        foot = p0 + ((np.array([x, y]) - p0) @ d) * d
        z = rot.T @ (foot - [x, y])
        if np.linalg.norm(z) < 0.3:
            continue
        cov = np.diag([noise**2, noise**2])
        z = z + rng.normal(0, noise, 2)
        seen = rel[keep]
        out.append(WallObservation(z, cov, seen[0], seen[-1], int(keep.sum()), noise))
    return out


def drive(rng, n=300):
    t = np.linspace(0, 2 * np.pi, n)
    return np.column_stack(
        [1.8 * np.cos(t) + 0.5, 1.5 * np.sin(t), t + np.pi / 2 + 0.6 * np.sin(5 * t)]
    )


def build_map(rng, config=None):
    wall_map = WallMap(config)
    for i, pose in enumerate(drive(rng)):
        obs = Observations("run", i, 100.0 + i / 15, "base_link", observe(pose, rng))
        wall_map.integrate(obs, Pose(100.0 + i / 15, *pose))
    return wall_map


def line_error(wall_reply, p0, p1):
    p0, p1 = np.array(p0), np.array(p1)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    n = np.array([-d[1], d[0]])
    q0, q1 = np.array(wall_reply["p0"]), np.array(wall_reply["p1"])
    return max(abs((q0 - p0) @ n), abs((q1 - p0) @ n))


def test_every_wall_is_mapped_once_and_accurately():
    rng = np.random.default_rng(5)
    wall_map = build_map(rng)
    walls = reply(wall_map, MapQuery(min_obs=3))["walls"]
    # The two pieces either side of the doorway are one wall, its segments showing the door.
    assert len(walls) == len(WALLS) - 1, [w["n_obs"] for w in walls]
    for p0, p1 in WALLS:
        errors = [line_error(w, p0, p1) for w in walls]
        assert min(errors) < 0.01
    door = min(walls, key=lambda w: line_error(w, *WALLS[2]))
    assert line_error(door, *WALLS[3]) < 0.01
    segments = np.array(door["segments"])
    assert len(segments) == 2
    lows, highs = segments[:, :, 0].min(axis=1), segments[:, :, 0].max(axis=1)
    assert highs.min() < -0.4, "the doorway between x = -0.6 and 0.6 stays open"
    assert lows.max() > 0.4
    assert wall_map.frames == 300


def test_reported_closest_point_and_covariance_are_in_the_map_frame():
    rng = np.random.default_rng(6)
    wall_map = build_map(rng)
    for w in reply(wall_map, MapQuery(min_obs=3))["walls"]:
        p0, p1 = np.array(w["p0"]), np.array(w["p1"])
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        foot = p0 - (p0 @ d) * d  # the line's closest point to the origin
        np.testing.assert_allclose([w["u"], w["v"]], foot, atol=1e-6)
        assert np.all(np.linalg.eigvalsh(np.array(w["cov"])) >= 0)


def test_observations_with_the_paper_point_model_would_fragment_walls():
    # The same observations, but states moved as points (the paper's eqs 1-3): count new walls.
    rng = np.random.default_rng(5)
    walls_point_model = []
    for pose in drive(rng):
        rot = se2.rotation(pose[2])
        for obs in observe(pose, rng):
            uv = pose[:2] + rot @ obs.closest  # the paper: a point moved into the map
            if not any(np.linalg.norm(uv - w) < 0.1 for w in walls_point_model):
                walls_point_model.append(uv)
    assert len(walls_point_model) > 5 * len(WALLS)


def test_collinear_walls_far_apart_stay_separate():
    config = MapperConfig(max_extent_gap=1.0)
    wall_map = WallMap(config)
    cov = np.eye(2) * 1e-4
    left = WallObservation(
        np.array([0.0, 2.0]), cov, np.array([-6.0, 2.0]), np.array([-3.0, 2.0]), 40, 0.01
    )
    right = WallObservation(
        np.array([0.0, 2.0]), cov, np.array([3.0, 2.0]), np.array([6.0, 2.0]), 40, 0.01
    )
    wall_map.integrate(Observations("r", 0, 1.0, "base_link", [left, right]), Pose(1.0, 0, 0, 0))
    assert len(wall_map.walls) == 2
    near = WallObservation(
        np.array([0.0, 2.0]), cov, np.array([-2.5, 2.0]), np.array([0.0, 2.0]), 40, 0.01
    )
    ids = wall_map.integrate(Observations("r", 1, 2.0, "base_link", [near]), Pose(2.0, 0, 0, 0))
    assert ids == [0]
    wall = reply(wall_map, MapQuery(tentative=True))["walls"][0]  # seen once: tentative
    assert wall["tentative"]
    assert sorted([wall["p0"][0], wall["p1"][0]]) == pytest.approx([-6.0, 0.0])


def test_state_round_trip_keeps_ids_and_numbers(tmp_path):
    rng = np.random.default_rng(7)
    wall_map = build_map(rng)
    path = tmp_path / "map.json"
    state_file.write(path, state_file.to_json(wall_map))
    again = state_file.load(path, MapperConfig())
    assert reply(again, MapQuery(trajectory=True)) == reply(wall_map, MapQuery(trajectory=True))
    assert again.next_id == wall_map.next_id
    assert len(again.trajectory) > 20


def test_unusable_state_file_is_refused_with_a_reason(tmp_path):
    path = tmp_path / "map.json"
    path.write_text("{not json")
    with pytest.raises(state_file.StateError, match="unusable"):
        state_file.load(path, MapperConfig())
    path.write_text(json.dumps({"v": 99}))
    with pytest.raises(state_file.StateError, match="version"):
        state_file.load(path, MapperConfig())
    assert state_file.load(tmp_path / "absent.json", MapperConfig()).walls == {}


def test_pose_buffer_interpolates_waits_and_refuses():
    buf = PoseBuffer()
    assert buf.lookup(1.0) is Lookup.WAIT
    buf.add(Pose(1.0, 0.0, 0.0, np.pi - 0.1))
    buf.add(Pose(1.2, 2.0, 0.0, -np.pi + 0.1))
    mid = buf.lookup(1.1)
    assert mid.x == pytest.approx(1.0)
    assert abs(abs(mid.yaw) - np.pi) < 1e-9  # through +-pi, not through 0
    assert buf.lookup(1.2).x == 2.0
    assert buf.lookup(1.21) is Lookup.WAIT, "the next pose, when it comes, decides"
    carried = buf.sample(1.21, extrapolate=0.02)
    assert isinstance(carried, SourcePose)
    assert carried.pose.x == pytest.approx(2.1)
    assert buf.lookup(1.3) is Lookup.WAIT
    assert buf.lookup(0.5) is Lookup.MISSING
    buf.add(Pose(3.0, 9.0, 0.0, 0.0))  # a gap of 1.8 s: not interpolated across
    assert buf.lookup(2.0) is Lookup.MISSING
    buf.add(Pose(1.1, 5.0, 0.0, 0.0))  # out of order: inserted in place
    assert buf.lookup(1.1).x == 5.0
    buf.add(Pose(-500.0, 0.0, 0.0, 0.0))  # time jumped back: a new run
    assert len(buf) == 1


def test_walls_that_converge_onto_one_line_merge_and_the_older_id_survives(tmp_path):
    wall_map = WallMap()
    cov = np.eye(2) * 1e-4

    def seen(x0, x1, stamp):
        obs = WallObservation(
            np.array([0.0, 2.0]), cov, np.array([x0, 2.0]), np.array([x1, 2.0]), 40, 0.01
        )
        return wall_map.integrate(
            Observations("r", 0, stamp, "base_link", [obs]), Pose(stamp, 0, 0, 0)
        )

    assert seen(-6.0, -4.0, 1.0) == seen(-6.0, -4.0, 1.1) == [0]
    # 2.5 m away along the line: another wall, for now.
    assert seen(-1.5, 2.0, 2.0) == seen(-1.5, 2.0, 2.1) == [1]
    assert len(wall_map.walls) == 2
    assert seen(-4.5, -1.0, 3.0) == [0]  # the gap is seen: one wall
    assert seen(-4.5, -1.0, 3.1) == [0]
    assert list(wall_map.walls) == [0]
    assert wall_map.merges == [(1, 0, 3.0)]
    wall = reply(wall_map, MapQuery(tentative=True))["walls"][0]
    assert sorted([wall["p0"][0], wall["p1"][0]]) == pytest.approx([-6.0, 2.0])
    assert wall["n_obs"] == 6
    assert reply(wall_map)["merges"] == [[1, 0, 3.0]]
    path = tmp_path / "map.json"
    state_file.write(path, state_file.to_json(wall_map))
    again = state_file.load(path, MapperConfig())
    assert again.merges == [(1, 0, 3.0)]
    assert reply(again, MapQuery(tentative=True)) == reply(wall_map, MapQuery(tentative=True))


def test_changes_held_while_nothing_listens_go_out_whole_with_the_next_update():
    """A subscriber's copy of the map, from updates with a stretch held between, is the map."""
    wall_map = WallMap()
    cov = np.eye(2) * 1e-4
    view: dict[int, dict] = {}  # what a subscriber that applies the updates holds

    def seen(x0, x1, stamp):
        obs = WallObservation(
            np.array([0.0, 2.0]), cov, np.array([x0, 2.0]), np.array([x1, 2.0]), 40, 0.01
        )
        wall_map.integrate(Observations("r", 0, stamp, "base_link", [obs]), Pose(stamp, 0, 0, 0))

    def hear(update):
        for wall in update["walls"]:
            view[wall["id"]] = wall
        for gone in update["removed"]:
            view.pop(gone, None)

    seen(-6.0, -4.0, 1.0)
    seen(-6.0, -4.0, 1.1)
    hear(serving.take_changes(wall_map).to_map())
    assert list(view) == [0]
    held = serving.HeldChanges()
    seen(-1.5, 2.0, 2.0)  # another wall, with nothing listening...
    seen(-1.5, 2.0, 2.1)
    held.hold(wall_map)
    assert (wall_map.changed, wall_map.removed, held.changed) == (set(), set(), {1})
    seen(-4.5, -1.0, 3.0)  # ...that merges into the first while held
    seen(-4.5, -1.0, 3.1)
    held.hold(wall_map)
    held.give_back(wall_map)
    assert (wall_map.changed, wall_map.removed) == ({0}, {1})  # only walls that are there
    hear(serving.take_changes(wall_map).to_map())
    assert view == {w["id"]: w for w in reply(wall_map, MapQuery(tentative=True))["walls"]}
    assert (held.changed, held.removed) == (set(), set())


def test_two_faces_of_a_real_wall_stay_apart():
    wall_map = WallMap()
    cov = np.eye(2) * 1e-4
    near = WallObservation(
        np.array([0.0, 2.0]), cov, np.array([-2.0, 2.0]), np.array([2.0, 2.0]), 40, 0.01
    )
    exact = np.eye(3) * 1e-8  # a precise pose source: the gate alone keeps the faces apart
    wall_map.integrate(Observations("r", 0, 1.0, "base_link", [near]), Pose(1.0, 0, 0, 0, exact))
    far_face = WallObservation(
        np.array([0.0, -1.9]), cov, np.array([2.0, -1.9]), np.array([-2.0, -1.9]), 40, 0.01
    )
    # From the other room, 4 m further: the wall's other face, 10 cm thick.
    wall_map.integrate(
        Observations("r", 1, 2.0, "base_link", [far_face]), Pose(2.0, 0, 4.0, 0, exact)
    )
    assert len(wall_map.walls) == 2
    assert wall_map.merges == []


def test_pose_buffer_headings_follow_every_insert_replace_trim_and_restart():
    """The headings a latency estimate reads are the poses' own, whatever the buffer did."""
    buf = PoseBuffer(PoseBufferConfig(max_age=5.0))
    rng = np.random.default_rng(3)
    stamps = np.arange(0.0, 12.0, 0.25).reshape(-1, 2)[:, ::-1].ravel()  # pairs swapped
    for stamp in stamps:  # each pair's second out of order: inserted in place
        buf.add(Pose(float(stamp), 0.0, 0.0, float(rng.uniform(-np.pi, np.pi))))
    buf.add(Pose(10.0, 0.0, 0.0, 0.5))  # a stamp again: replaced
    kept = [buf.lookup(t) for t in np.arange(6.75, 12.0, 0.25)]  # older than 5 s: trimmed
    stamps, yaw = buf.headings(8.0, 11.0)
    want = [p for p in kept if 7.75 <= p.stamp <= 11.0]  # one before the start
    assert stamps.tolist() == [p.stamp for p in want]
    assert yaw.tolist() == np.unwrap([p.yaw for p in want]).tolist()
    assert [p.yaw for p in want if p.stamp == 10.0] == [0.5]  # the replaced one among them
    buf.add(Pose(-100.0, 0.0, 0.0, 0.25))  # time jumped back: a new run
    assert buf.headings(-101.0, 0.0)[1].tolist() == [0.25]


def test_pose_jumps_are_logged(caplog):
    buf = PoseBuffer()
    buf.add(Pose(1.0, 0.0, 0.0, 0.0))
    buf.add(Pose(1.1, 0.05, 0.0, 0.0))
    assert "jumped" not in caplog.text
    buf.add(Pose(1.2, 2.05, 0.0, 0.0))  # 2 m in 0.1 s: a localiser correcting itself
    assert "pose jumped by 2.00 m" in caplog.text


def along_wall(x0: float, x1: float, y: float = 2.0) -> WallObservation:
    """A wall y = 2 seen from the origin between x0 and x1, robot facing +x."""
    cov = np.eye(2) * 1e-4
    return WallObservation(np.array([0.0, y]), cov, np.array([x0, y]), np.array([x1, y]), 40, 0.01)


def test_a_door_splits_the_extent_into_segments_and_strays_do_not_stretch_it():
    wall_map = WallMap()
    for i in range(6):
        pose = Pose(float(i), 0.1 * i, 0.0, 0.0)  # driving along: distinct views
        shift = -0.1 * i  # the robot moved: the same wall parts, in its own frame
        parts = [along_wall(-3.0 + shift, -0.5 + shift), along_wall(0.5 + shift, 3.0 + shift)]
        wall_map.integrate(Observations("r", i, float(i), "base_link", parts), pose)
    wall_map.integrate(
        Observations("r", 9, 9.0, "base_link", [along_wall(2.5, 6.0)]), Pose(9, 0, 0, 0)
    )
    (wall,) = reply(wall_map)["walls"]
    segments = np.array(wall["segments"])[:, :, 0]
    spans = sorted(np.sort(segments, axis=1).tolist())
    np.testing.assert_allclose(spans, [[-3.0, -0.5], [0.5, 3.0]], atol=0.05)
    assert sorted([wall["p0"][0], wall["p1"][0]]) == pytest.approx([-3.0, 3.0], abs=0.05)


def test_walls_are_tentative_until_seen_from_distinct_viewpoints():
    wall_map = WallMap()
    for i in range(5):  # five times from the same spot
        wall_map.integrate(
            Observations("r", i, float(i), "base_link", [along_wall(-1, 1)]), Pose(i, 0, 0, 0)
        )
    assert reply(wall_map)["walls"] == []
    assert len(reply(wall_map, MapQuery(tentative=True))["walls"]) == 1
    wall_map.integrate(
        Observations("r", 5, 5.0, "base_link", [along_wall(-1.5, 0.5)]), Pose(5, 0.5, 0, 0)
    )
    (wall,) = reply(wall_map)["walls"]
    assert (wall["n_views"], wall["tentative"]) == (2, False)


def test_query_filters_and_their_errors():
    wall_map = WallMap()
    for i in range(4):
        obs = [along_wall(-1, 1), along_wall(4, 6, y=-3.0)]
        wall_map.integrate(
            Observations("r", i, 10.0 + i, "base_link", obs), Pose(10.0 + i, 0.3 * i, 0, 0)
        )
    assert len(reply(wall_map)["walls"]) == 2
    box = MapQuery.from_parameters({"bbox": "-2,1,2,3"})
    assert [w["v"] for w in reply(wall_map, box)["walls"]] == [pytest.approx(2.0)]
    assert reply(wall_map, MapQuery.from_parameters({"since": "13.5"}))["walls"] == []
    assert len(reply(wall_map, MapQuery.from_parameters({"since": "13"}))["walls"]) == 2
    for params, reason in [
        ({"bbox": "1,2,3"}, "bbox must be"),
        ({"bbox": "3,0,1,1"}, "xmin <= xmax"),
        ({"since": "yesterday"}, "since must be"),
        ({"tentative": "yes"}, "tentative must be true or false"),
        ({"colour": "red"}, "unknown parameter 'colour'"),
    ]:
        with pytest.raises(ValueError, match=reason):
            MapQuery.from_parameters(params)
    changes = serving.take_changes(wall_map).to_map()
    assert len(changes["walls"]) == 2
    assert serving.take_changes(wall_map).to_map()["walls"] == []


def test_a_wall_passing_close_to_the_sensor_is_mapped_as_well_as_any_other():
    # The robot drives 35 cm beside the wall y = 0.35, then moves away to 3 m.
    rng = np.random.default_rng(11)
    wall_map = WallMap()
    for i in range(80):
        y = 0.0 if i < 40 else -0.07 * (i - 40)
        pose = np.array([0.05 * i, y, rng.uniform(-0.3, 0.3)])
        rot = se2.rotation(pose[2])
        z = rot.T @ np.array([0.0, 0.35 - y]) + rng.normal(0, 0.005, 2)
        ends = [rot.T @ (np.array([x, 0.35]) - pose[:2]) for x in (pose[0] - 1.0, pose[0] + 1.5)]
        obs = WallObservation(z, np.eye(2) * 0.005**2, ends[0], ends[1], 40, 0.005)
        wall_map.integrate(
            Observations("r", i, float(i), "base_link", [obs]), Pose(float(i), *pose)
        )
    (wall,) = reply(wall_map)["walls"]
    assert wall["u"] == pytest.approx(0.0, abs=0.005)
    assert wall["v"] == pytest.approx(0.35, abs=0.005)
    assert line_error(wall, (-1.0, 0.35), (5.0, 0.35)) < 0.01


def test_a_line_blended_across_a_shallow_corner_is_a_shadow_not_a_wall():
    wall_map = WallMap()
    for i in range(12):  # the real wall y = 2, seen often from distinct places
        wall_map.integrate(
            Observations("r", i, float(i), "base_link", [along_wall(-3, 3)]), Pose(i, 0.2 * i, 0, 0)
        )
    # A few views of a line 4 degrees off along the same stretch (too far off to merge).
    tilt = np.radians(4.0)
    n = np.array([-np.sin(tilt), np.cos(tilt)])
    for i in range(3):
        closest = 2.0 * n
        d = np.array([n[1], -n[0]])
        obs = WallObservation(
            closest, np.eye(2) * 1e-6, closest - 1.5 * d, closest + 1.5 * d, 40, 0.01
        )
        wall_map.integrate(
            Observations("r", 20 + i, 20.0 + i, "base_link", [obs]), Pose(20.0 + i, 0.3 * i, 0, 0)
        )
    served = reply(wall_map)["walls"]
    assert len(wall_map.walls) == 2
    assert [w["id"] for w in served] == [0]
    shadow = [w for w in reply(wall_map, MapQuery(tentative=True))["walls"] if w["id"] == 1]
    assert shadow[0]["tentative"]


def seen_from(pose: tuple[float, float, float], a, b) -> WallObservation:
    """A precise observation of the map segment a-b from ``pose``, in the robot frame."""
    x, y, yaw = pose
    rot = se2.rotation(yaw)
    pa, pb = rot.T @ (np.asarray(a, float) - [x, y]), rot.T @ (np.asarray(b, float) - [x, y])
    d = (pb - pa) / np.linalg.norm(pb - pa)
    return WallObservation(pa - (pa @ d) * d, np.eye(2) * 1e-6, pa, pb, 40, 0.01)


def turned(degrees: float, length: float, start=(0.0, 2.0)) -> np.ndarray:
    """The point ``length`` from ``start`` in the direction ``degrees`` from +x."""
    angle = np.radians(degrees)
    return np.asarray(start) + length * np.array([np.cos(angle), np.sin(angle)])


def integrate_views(wall_map: WallMap, segments, times: int, first: int = 0) -> None:
    """Each map segment seen ``times`` times, from the robot driving along y = 0."""
    for i in range(first, first + times):
        pose = (-1.0 + 0.2 * (i - first), 0.0, np.pi / 2)
        obs = [seen_from(pose, a, b) for a, b in segments]
        wall_map.integrate(Observations("r", i, float(i), "base_link", obs), Pose(float(i), *pose))


def nearest_end(wall: dict, point) -> np.ndarray:
    """The end of a served wall nearest to ``point``."""
    ends = np.array([wall["p0"], wall["p1"]])
    return ends[np.argmin(np.linalg.norm(ends - point, axis=1))]


def test_walls_meeting_at_a_shallow_corner_end_at_it_though_seen_past_it():
    # A 12 degree kink at (0, 2); each wall is seen 0.5 m past the corner, as the inlier band
    # of a far line takes in the other wall's points there: 0.1 m / sin 12 deg.
    corner = np.array([0.0, 2.0])
    past_a = ((-3.0, 2.0), (0.5, 2.0))
    past_b = (turned(12.0, -0.5), turned(12.0, 3.0))
    misses = {}
    for band in (0.0, MapperConfig().corner_band):
        wall_map = WallMap(MapperConfig(corner_band=band))
        integrate_views(wall_map, [past_a, past_b], 6)
        walls = reply(wall_map)["walls"]
        assert len(walls) == 2
        misses[band] = [float(np.linalg.norm(nearest_end(w, corner) - corner)) for w in walls]
    assert max(misses[MapperConfig().corner_band]) < 0.02
    assert min(misses[0.0]) == pytest.approx(0.5, abs=0.02)  # without it: 0.5 m past


def test_a_doorway_at_a_square_corner_stays_open():
    wall_map = WallMap()
    integrate_views(wall_map, [((-3.0, 2.0), (-0.6, 2.0)), ((0.0, 2.0), (0.0, 5.0))], 6)
    walls = reply(wall_map)["walls"]
    assert len(walls) == 2
    ends = sorted(nearest_end(w, (0.0, 2.0)).tolist() for w in walls)
    np.testing.assert_allclose(ends, [[-0.6, 2.0], [0.0, 2.0]], atol=0.02)


def test_a_line_blended_across_a_corner_lies_on_both_walls_and_is_a_shadow():
    wall_map = WallMap()
    integrate_views(wall_map, [((-3.0, 2.0), (0.0, 2.0)), ((0.0, 2.0), turned(14.0, 3.0))], 12)
    # Seen from far, the corner came out as one short line halfway between the two walls.
    integrate_views(wall_map, [(turned(7.0, -0.4), turned(7.0, 0.4))], 4, first=20)
    assert len(wall_map.walls) == 3
    served = reply(wall_map)["walls"]
    assert len(served) == 2
    blend = [w for w in reply(wall_map, MapQuery(tentative=True))["walls"] if w["tentative"]]
    assert len(blend) == 1
    assert blend[0]["n_obs"] == 4


def test_a_wall_beside_a_better_seen_neighbour_at_a_shallow_corner_is_no_shadow():
    wall_map = WallMap()
    # The neighbour, seen 30 times; the wall, 6 times; both seen 0.5 m past their corner.
    integrate_views(wall_map, [(turned(12.5, -0.5), turned(12.5, 4.0))], 30)
    integrate_views(wall_map, [((-1.9, 2.0), (0.5, 2.0))], 6, first=40)
    assert len(reply(wall_map)["walls"]) == 2


def test_the_trajectory_interpolates_to_every_pose_used_however_they_jitter():
    """Judged poses are corrected frame by frame: keyframes a step of travel apart would lose
    that, so a frame the straight line between keyframes misplaces is kept too."""
    wall_map = WallMap()
    rng = np.random.default_rng(3)
    used = []
    for k in range(200):
        jitter = rng.normal(0.0, np.radians(1.0)) if 50 <= k < 100 else 0.0
        pose = Pose(k * 0.1, 0.01 * k, 0.0, 0.002 * k + jitter)
        used.append(pose)
        wall_map.integrate(Observations("test", k, pose.stamp, "base_link", ()), pose)
    path = np.array(wall_map.path())
    assert path[-1, 0] == used[-1].stamp, "the newest pose ends it"
    smooth = np.sum((path[:, 0] < 5.0) | (path[:, 0] >= 10.0))
    assert smooth < 40, "smooth motion: a keyframe a step of travel or turn"
    yaw = np.interp([p.stamp for p in used], path[:, 0], path[:, 3])
    assert np.abs(yaw - [p.yaw for p in used]).max() <= np.radians(0.2) + 1e-9
