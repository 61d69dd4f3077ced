import json
import math
from collections import Counter, defaultdict

import numpy as np
import pytest
from conftest import ROOT, run_wallmap
from rosbags.highlevel import AnyReader

from wallmap import offline
from wallmap.evaluation import evaluate_map
from wallmap.scene import (
    AMCL_POSE_TOPIC,
    CAMERA_INFO_TOPIC,
    GROUND_TRUTH_TOPIC,
    IMAGE_TOPIC,
    ODOM_TOPIC,
    POINTS_TOPIC,
    SCAN_TOPIC,
    SCENE_KINDS,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    Camera,
    FloorPlan,
    Furniture,
    PoseFaults,
    Scanner,
    Wall,
    clearance,
    depth_to_points,
    drifting_odometry,
    generate_floorplan,
    generate_trajectory,
    load_map_in_world,
    load_truth,
    read_tum,
    render_depth,
    render_scan,
    scan_walls_seen,
    stamp_to_ns,
    walls_seen,
    write_scene_bag,
    write_tum,
)
from wallmap.scene.floorplan import point_segment_distance, segment_distances

SEEDS = [0, 1, 2, 3, 11, 42]
SAMPLE_TRUTH = ROOT / "wallmap" / "data" / "sample.bag.truth.json"


def wall_angles_deg(plan):
    return np.array(
        [math.degrees(math.atan2(w.p1[1] - w.p0[1], w.p1[0] - w.p0[0])) for w in plan.walls]
    )


def doorway_centres(plan):
    """Jamb ends are the only wall ends not shared with another wall; they come in pairs."""
    ends = Counter(p for w in plan.walls for p in (w.p0, w.p1))
    free = np.array([p for p, k in ends.items() if k == 1])
    centres = []
    for i, p in enumerate(free):
        j = np.argsort(np.linalg.norm(free - p, axis=1))[1]
        if i < j:
            centres.append((p + free[j]) / 2)
    return np.array(centres)


def se2(x, y, yaw):
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def quat_yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def quat_matrix(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def header_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def read_bag(path):
    """Messages per topic as (bag time ns, message), and the message type per topic."""
    messages, types = defaultdict(list), {}
    with AnyReader([path]) as reader:
        for connection in reader.connections:
            types[connection.topic] = connection.msgtype
        for connection, ns, raw in reader.messages():
            messages[connection.topic].append((ns, reader.deserialize(raw, connection.msgtype)))
    return messages, types


def bag_path(tmp_path, fmt, name="scene"):
    return tmp_path / (f"{name}.bag" if fmt == "ros1" else name)


# --- floor plans ---------------------------------------------------------------------------


def test_plans_are_deterministic_and_differ_by_seed():
    assert generate_floorplan(7) == generate_floorplan(7)
    assert generate_floorplan(7).to_json() != generate_floorplan(8).to_json()
    plan = generate_floorplan(7)
    assert FloorPlan.from_json(json.loads(json.dumps(plan.to_json()))) == plan


@pytest.mark.parametrize("seed", SEEDS)
def test_plans_are_non_manhattan_and_well_formed(seed):
    plan = generate_floorplan(seed, n_rooms=3)

    # Relative angles, so the random global rotation does not count.
    relative = (wall_angles_deg(plan) - wall_angles_deg(plan)[0]) % 90.0
    assert np.sum((relative > 10.0) & (relative < 80.0)) >= 3
    lengths = np.array([w.length for w in plan.walls])
    assert lengths.min() >= 1.0
    assert lengths.max() <= 8.0
    assert len({w.id for w in plan.walls}) == len(plan.walls)
    assert any(w.glass for w in plan.walls)
    assert len(doorway_centres(plan)) == 2  # three rooms in a row
    starts = np.array([w.p0 for w in plan.walls])
    ends = np.array([w.p1 for w in plan.walls])
    gaps = segment_distances(starts, ends, starts, ends)
    shares_end = np.zeros_like(gaps, dtype=bool)
    for u in (starts, ends):
        for v in (starts, ends):
            shares_end |= np.all(u[:, None] == v[None], axis=2)
    assert gaps[~shares_end].min() > 0.2  # walls meet only at corners
    assert plan.furniture
    for box in plan.furniture:
        assert 0.4 <= box.height <= 1.1
    assert plan.route[0] == (0.0, 0.0)


def test_more_rooms_make_more_doorways():
    assert len(doorway_centres(generate_floorplan(5, n_rooms=5))) == 4


def test_default_plan_is_still_the_one_the_sample_bag_was_made_from():
    truth = json.loads(SAMPLE_TRUTH.read_text())
    plan = generate_floorplan(truth["seed"]).to_json()

    # The room truth came later than the sample: the rest of the plan is what made it.
    assert {k: v for k, v in plan.items() if k in truth["plan"]} == truth["plan"]
    assert len(plan["rooms"]) == 3


def walls_meet_only_where_joined(plan):
    """Walls come close only at a shared vertex or where one ends on the other (a T)."""
    starts = np.array([w.p0 for w in plan.walls])
    ends = np.array([w.p1 for w in plan.walls])
    gaps = segment_distances(starts, ends, starts, ends)
    joined = np.zeros_like(gaps, dtype=bool)
    for u in (starts, ends):
        on = point_segment_distance(u, starts, ends) < 1e-9
        joined |= on | on.T
    return gaps[~joined].min() > 0.2


@pytest.mark.parametrize("name", SCENE_KINDS)
@pytest.mark.parametrize("seed", [3, 500])
def test_scene_kinds_give_valid_deterministic_plans(name, seed):
    kind = SCENE_KINDS[name]
    plan = kind.plan(seed)
    traj = generate_trajectory(plan, seed)

    assert kind.plan(seed) == plan
    assert kind.plan(seed + 1).to_json() != plan.to_json()
    assert len({w.id for w in plan.walls}) == len(plan.walls)
    assert walls_meet_only_where_joined(plan)
    if kind.junction:  # drawn by hand: two rooms, the divider standing on the outer wall
        outer, stem = plan.walls[0], plan.walls[1]
        assert (
            point_segment_distance(np.zeros((1, 2)), np.array([outer.p0]), np.array([outer.p1]))[
                0, 0
            ]
            < 1e-9
        )
        assert min(math.dist(stem.p0, (0, 0)), math.dist(stem.p1, (0, 0))) < 1e-9
        assert clearance(plan, traj.positions).min() >= 0.6
        return
    pillar_face = pytest.approx(0.3)
    assert all(1.0 <= w.length <= 8.0 or w.length == pillar_face for w in plan.walls)
    relative = (wall_angles_deg(plan) - wall_angles_deg(plan)[0]) % 90.0
    assert np.sum((relative > 10.0) & (relative < 80.0)) >= 3
    assert all(box.height <= 1.1 for box in plan.furniture if box.base == 0.0)
    on_counters = [box for box in plan.furniture if box.base > 0.0]  # appliances
    assert all(box.base == 0.9 and box.height <= 1.35 for box in on_counters)
    assert bool(on_counters) == (kind.counters > 0)
    assert plan.route[0] == (0.0, 0.0)
    assert clearance(plan, traj.positions).min() >= 0.6


@pytest.mark.parametrize("name", ["non-manhattan", "tilted", "noisy"])
def test_camera_kinds_share_the_default_plan(name):
    assert SCENE_KINDS[name].plan(500) == generate_floorplan(500)


@pytest.mark.parametrize("seed", [3, 500, 501])
def test_corridor_is_long_and_narrow_with_doors_on_both_sides(seed):
    plan = SCENE_KINDS["corridor"].plan(seed)
    route = np.array(plan.route)
    # Door jambs are the free wall ends: on no wall but their own. A side room's walls end
    # on the side wall in a T: on two walls, but no other wall's vertex.
    starts = np.array([w.p0 for w in plan.walls])
    ends = np.array([w.p1 for w in plan.walls])
    points = [p for w in plan.walls for p in (w.p0, w.p1)]
    on_walls = (point_segment_distance(np.array(points), starts, ends) < 1e-9).sum(axis=1)
    vertex_of = Counter(points)
    free = np.array([p for p, k in zip(points, on_walls, strict=True) if k == 1])
    tees = [p for p, k in zip(points, on_walls, strict=True) if k == 2 and vertex_of[p] == 1]
    jambs = np.linalg.norm(free[:, None] - free[None], axis=2)
    np.fill_diagonal(jambs, np.inf)
    door_widths = jambs.min(axis=1)
    # Which side of the route each jamb is on, against the route's nearest leg.
    nearest = point_segment_distance(free, route[:-1], route[1:]).argmin(axis=1)
    leg = route[nearest + 1] - route[nearest]
    rel = free - route[nearest]
    side = np.sign(leg[:, 0] * rel[:, 1] - leg[:, 1] * rel[:, 0])

    assert np.linalg.norm(np.diff(route, axis=0), axis=1).sum() >= 15.0
    assert len(free) >= 6
    assert door_widths.min() >= 0.9 - 1e-9
    assert door_widths.max() <= 1.2 + 1e-9
    assert set(side.tolist()) == {1.0, -1.0}
    assert len(tees) >= 2  # at least one side room
    near_walls = clearance(plan, np.array(plan.route))
    assert near_walls.max() <= 1.25 + 1e-9  # at most 2.5 m wide
    assert near_walls.min() >= 0.9 - 1e-9  # at least 1.8 m wide


@pytest.mark.parametrize("seed", [3, 500])
def test_glass_scene_is_mostly_glass(seed):
    plan = SCENE_KINDS["glass"].plan(seed)

    assert sum(w.glass for w in plan.walls) / len(plan.walls) >= 0.4


@pytest.mark.parametrize("seed", [3, 500])
def test_clutter_scene_has_dense_furniture_and_pillars(seed):
    plan = SCENE_KINDS["clutter"].plan(seed)
    pillars = [w for w in plan.walls if w.length < 0.5]
    ends = Counter(p for w in pillars for p in (w.p0, w.p1))

    assert len(plan.furniture) >= 12
    assert len(pillars) >= 8  # two pillars or more
    assert all(w.length == pytest.approx(0.3) for w in pillars)
    assert all(k == 2 for k in ends.values())  # closed squares
    assert not any(w.glass for w in pillars)
    assert all(w.height == plan.ceiling_height for w in pillars)


def test_pillars_only_in_rooms():
    with pytest.raises(ValueError, match="pillars"):
        generate_floorplan(1, layout="corridor", pillars_per_room=1)


@pytest.mark.parametrize(
    ("name", "key", "value"), [("tilted", "tilt_deg", 8.0), ("noisy", "noise_k", 2.85e-3)]
)
def test_camera_kinds_are_in_the_truth_file(tmp_path, name, key, value):
    kind = SCENE_KINDS[name]
    info = write_scene_bag(
        tmp_path / "scene.bag",
        seed=500,
        n_frames=2,
        fmt="ros1",
        sensor="depth16",
        camera=kind.camera,
        plan=kind.plan(500),
    )

    assert json.loads(info.truth_path.read_text())["camera"][key] == pytest.approx(value)


# --- trajectories --------------------------------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
def test_trajectory_drives_through_all_rooms_with_clearance(seed):
    plan = generate_floorplan(seed)
    traj = generate_trajectory(plan, seed, rate_hz=15.0)
    xy = traj.positions

    assert len(traj) >= 600  # 40 s of driving at 15 Hz
    assert clearance(plan, xy).min() >= 0.6
    for centre in doorway_centres(plan):
        assert np.linalg.norm(xy - centre, axis=1).min() < 0.03
    np.testing.assert_allclose(np.diff(traj.stamps), 1 / 15, atol=1e-6)


def test_trajectory_is_smooth_and_sweeps_the_view():
    plan = generate_floorplan(3)
    traj = generate_trajectory(plan, 3, rate_hz=15.0, speed=0.4)
    velocity = np.column_stack([np.diff(traj.x), np.diff(traj.y)]) * 15.0
    speed = np.linalg.norm(velocity, axis=1)

    assert speed[0] < 0.05  # starts from rest
    assert speed.max() == pytest.approx(0.4, abs=1e-3)
    # Continuous velocity: the change per frame is bounded by the 0.4 m/s^2 ramps and the
    # path's curvature.
    assert np.linalg.norm(np.diff(velocity, axis=0), axis=1).max() < 0.05
    assert np.abs(np.diff(np.unwrap(traj.yaw))).max() < math.radians(5.0)
    moving = speed > 0.2
    heading = np.arctan2(velocity[:, 1], velocity[:, 0])
    off_heading = np.degrees(np.angle(np.exp(1j * (traj.yaw[1:] - heading))))[moving]
    assert off_heading.max() > 50.0
    assert off_heading.min() < -50.0
    assert np.abs(off_heading).max() < 62.0


def test_same_trajectory_at_another_rate():
    plan = generate_floorplan(2)
    slow = generate_trajectory(plan, 9, rate_hz=15.0)
    fast = generate_trajectory(plan, 9, rate_hz=30.0)

    np.testing.assert_allclose(fast.x[::2][: len(slow)], slow.x, atol=1e-9)
    np.testing.assert_allclose(fast.yaw[::2][: len(slow)], slow.yaw, atol=1e-9)


def test_odometry_starts_true_and_drifts():
    plan = generate_floorplan(1)
    traj = generate_trajectory(plan, 1)
    odom = drifting_odometry(traj, 5, drift_xy=0.02, drift_yaw_deg=1.0)
    error = np.hypot(odom.x - traj.x, odom.y - traj.y)
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(traj.x), np.diff(traj.y)))])

    assert odom.pose_at(0) == pytest.approx(traj.pose_at(0))
    assert error[travelled < 1.0].max() < 0.05
    assert error[-1] > 0.3
    yaw_error = np.degrees(np.angle(np.exp(1j * (odom.yaw - traj.yaw))))
    assert 5.0 < abs(yaw_error[-1]) < 3.0 * travelled[-1]
    exact = drifting_odometry(traj, 5, drift_xy=0.0, drift_yaw_deg=0.0)
    np.testing.assert_allclose(exact.x, traj.x, atol=1e-9)
    np.testing.assert_allclose(exact.yaw, traj.yaw, atol=1e-9)


# --- rendering -----------------------------------------------------------------------------

CAMERA = Camera()


def wall_ahead(distance, *, glass=False, height=2.6):
    """One wide wall perpendicular to the view of a robot at the origin facing +x."""
    x = CAMERA.mount_xyz[0] + distance
    return FloorPlan(walls=(Wall(7, (x, -6.0), (x, 6.0), glass=glass, height=height),))


def test_camera_defaults_are_kinect_like():
    assert math.degrees(2 * math.atan(CAMERA.width / 2 / CAMERA.fx)) == pytest.approx(57.0)
    assert math.degrees(2 * math.atan(CAMERA.height / 2 / CAMERA.fy)) == pytest.approx(43.0)
    big = Camera(width=640, height=480)
    assert big.fx == pytest.approx(4 * CAMERA.fx)
    optical = CAMERA.T_base_camera
    np.testing.assert_allclose(optical[:3, 2], [1, 0, 0], atol=1e-12)  # z looks forward
    np.testing.assert_allclose(optical[:3, 0], [0, -1, 0], atol=1e-12)  # x to the right
    np.testing.assert_allclose(optical[:3, 3], [0.1, 0.0, 1.0])
    up = Camera(tilt_deg=10.0).T_base_camera
    assert up[2, 2] == pytest.approx(math.sin(math.radians(10.0)))


def test_wall_straight_ahead_gives_its_distance():
    depth, hit = render_depth(wall_ahead(3.0), 0.0, 0.0, 0.0, CAMERA, None)

    assert depth.dtype == np.float32
    assert hit.dtype == np.int32
    assert depth.shape == hit.shape == (120, 160)
    assert depth[60, 80] == pytest.approx(3.0, abs=1e-5)
    assert hit[60, 80] == 7
    # A plane facing the camera has the same optical z everywhere.
    np.testing.assert_allclose(depth[hit == 7], 3.0, atol=1e-5)
    # Rays steep enough to reach the floor before the wall see the floor.
    assert (hit[-1] == -1).all()
    assert depth[-1, 80] < 3.0


def test_wall_ahead_after_turning():
    plan = FloorPlan(walls=(Wall(1, (-6.0, 4.1), (6.0, 4.1)),))  # north of the robot
    depth, hit = render_depth(plan, 0.0, 0.0, math.pi / 2, CAMERA, None)

    assert depth[60, 80] == pytest.approx(4.0, abs=1e-5)
    assert hit[60, 80] == 1


def test_glass_gives_no_return():
    depth, hit = render_depth(wall_ahead(3.0, glass=True), 0.0, 0.0, 0.0, CAMERA, None)

    assert np.isnan(depth[60, 80])
    assert hit[60, 80] == 7
    assert np.isnan(depth[hit == 7]).all()
    assert np.isfinite(depth[-1]).all()  # the floor in front of the glass still returns


def test_range_limits():
    far, far_hit = render_depth(wall_ahead(5.5), 0.0, 0.0, 0.0, CAMERA, None)
    near, _ = render_depth(wall_ahead(0.4), 0.0, 0.0, 0.0, CAMERA, None)

    assert np.isnan(far[60, 80])
    assert far_hit[60, 80] == -1
    assert np.isnan(near).all()


def test_points_lie_on_a_slanted_wall():
    plan = FloorPlan(walls=(Wall(3, (1.0, -4.0), (5.0, 2.0), height=2.4),))
    x, y, yaw = 0.5, 0.2, 0.3
    depth, hit = render_depth(plan, x, y, yaw, CAMERA, None)
    points = depth_to_points(depth, CAMERA)[hit == 3].astype(float)
    mount = CAMERA.T_base_camera
    base = points @ mount[:3, :3].T + mount[:3, 3]
    world = base[:, :2] @ se2(x, y, yaw)[:2, :2].T + [x, y]

    assert len(points) > 1000
    a, b = np.array([1.0, -4.0]), np.array([5.0, 2.0])
    d = (b - a) / np.linalg.norm(b - a)
    distance = np.abs((world - a) @ np.array([-d[1], d[0]]))
    assert distance.max() < 1e-4
    assert base[:, 2].min() >= -1e-4
    assert base[:, 2].max() <= 2.4 + 1e-4
    assert np.isnan(depth_to_points(depth, CAMERA)[np.isnan(depth)]).all()


def test_furniture_hides_the_wall_behind_it():
    box = Furniture(center=(2.0, 0.0), size=(0.6, 1.0), yaw=0.0, height=0.8)
    plan = FloorPlan(walls=wall_ahead(3.0).walls, furniture=(box,))
    depth, hit = render_depth(plan, 0.0, 0.0, 0.0, CAMERA, None)

    assert hit[60, 80] == 7  # above the box
    column = depth[:, 80]
    box_rows = (hit[:, 80] == -1) & (column < 2.0)
    assert box_rows.any()
    # The box's front face is at x = 1.7, i.e. 1.6 m in front of the camera.
    assert column[box_rows].min() == pytest.approx(1.6, abs=1e-5)


def test_depth_noise_grows_with_distance_squared():
    depth, _ = render_depth(wall_ahead(4.0), 0.0, 0.0, 0.0, CAMERA, np.random.default_rng(1))
    centre = depth[40:80, 40:120]

    assert np.std(centre) == pytest.approx(CAMERA.noise_k * 16.0, rel=0.1)
    assert np.mean(centre) == pytest.approx(4.0, abs=0.005)


def test_walls_seen_needs_the_height_band():
    for distance, expected in ((3.0, {7}), (1.2, {7}), (0.7, set())):
        depth, hit = render_depth(wall_ahead(distance), 0.0, 0.0, 0.0, CAMERA, None)
        # At 0.7 m the top rows reach only 1.0 + 0.7 tan(21.5 deg) = 1.28 m.
        assert walls_seen(hit, depth, CAMERA) == expected, distance
    low, low_hit = render_depth(wall_ahead(3.0, height=1.2), 0.0, 0.0, 0.0, CAMERA, None)
    assert walls_seen(low_hit, low, CAMERA) == set()
    glass, glass_hit = render_depth(wall_ahead(3.0, glass=True), 0.0, 0.0, 0.0, CAMERA, None)
    assert walls_seen(glass_hit, glass, CAMERA) == set()


# --- laser scans ---------------------------------------------------------------------------

SCANNER = Scanner()
CENTRE_BEAM = 270


def wall_ahead_of_scanner(distance, *, glass=False, furniture=()):
    """One wide wall perpendicular to the centre beam of a robot at the origin facing +x."""
    x = SCANNER.mount_xyz[0] + distance
    return FloorPlan(walls=(Wall(7, (x, -20.0), (x, 20.0), glass=glass),), furniture=furniture)


def test_scanner_defaults():
    assert SCANNER.n_beams == 541
    assert math.degrees(SCANNER.angle_increment) == pytest.approx(0.5)
    assert SCANNER.angles[[0, CENTRE_BEAM, -1]] == pytest.approx(
        [-3 * math.pi / 4, 0, 3 * math.pi / 4]
    )
    np.testing.assert_allclose(SCANNER.T_base_laser[:3, :3], np.eye(3))
    np.testing.assert_allclose(SCANNER.T_base_laser[:3, 3], [0.15, 0.0, 1.2])
    assert Scanner.from_json(json.loads(json.dumps(SCANNER.to_json()))) == SCANNER
    narrow = Scanner(angle_min=-0.5, angle_max=0.5, n_beams=11, mount_xyz=(0.0, 0.1, 1.5))
    assert Scanner.from_json(json.loads(json.dumps(narrow.to_json()))) == narrow


def test_scan_of_a_wall_straight_ahead():
    ranges, hit = render_scan(wall_ahead_of_scanner(3.0), 0.0, 0.0, 0.0, SCANNER)

    assert ranges.dtype == np.float32
    assert hit.dtype == np.int32
    assert ranges.shape == hit.shape == (541,)
    assert ranges[CENTRE_BEAM] == 3.0
    assert hit[CENTRE_BEAM] == 7
    # A flat wall: range = 3 / cos(angle) out to where that passes range_max.
    seen = hit == 7
    np.testing.assert_allclose(ranges[seen], 3.0 / np.cos(SCANNER.angles[seen]), rtol=1e-6)
    assert seen.sum() == 2 * math.floor(math.degrees(math.acos(3.0 / 8.0)) / 0.5) + 1
    assert np.isnan(ranges[~seen]).all()  # past range_max or behind: nothing
    assert (hit[~seen] == -1).all()
    assert scan_walls_seen(hit, ranges) == {7}


def test_scan_after_moving_and_turning():
    plan = FloorPlan(walls=(Wall(1, (-20.0, 5.0), (20.0, 5.0)),))  # north of the robot
    ranges, hit = render_scan(plan, 1.0, 0.5, math.pi / 2, SCANNER)

    assert ranges[CENTRE_BEAM] == pytest.approx(5.0 - 0.5 - 0.15, abs=1e-6)
    assert hit[CENTRE_BEAM] == 1


def test_scan_through_glass_gives_no_return():
    ranges, hit = render_scan(wall_ahead_of_scanner(3.0, glass=True), 0.0, 0.0, 0.0, SCANNER)

    assert np.isnan(ranges).all()
    assert hit[CENTRE_BEAM] == 7
    assert scan_walls_seen(hit, ranges) == set()


def test_scan_sees_only_furniture_taller_than_the_mount():
    def box(height):
        return Furniture(center=(2.0, 0.0), size=(0.6, 1.0), yaw=0.0, height=height)

    low, low_hit = render_scan(wall_ahead_of_scanner(3.0, furniture=(box(1.1),)), 0, 0, 0, SCANNER)
    assert low[CENTRE_BEAM] == 3.0
    assert low_hit[CENTRE_BEAM] == 7

    tall, tall_hit = render_scan(
        wall_ahead_of_scanner(3.0, furniture=(box(1.5),)), 0, 0, 0, SCANNER
    )
    # The box's front face is at x = 1.7, i.e. 1.55 m in front of the laser.
    assert tall[CENTRE_BEAM] == pytest.approx(1.55, abs=1e-6)
    assert tall_hit[CENTRE_BEAM] == -1
    assert (tall_hit == -1).sum() > (low_hit == -1).sum()


def test_scan_range_limits_and_walls_below_the_beam():
    far, far_hit = render_scan(wall_ahead_of_scanner(8.5), 0.0, 0.0, 0.0, SCANNER)
    assert np.isnan(far).all()
    assert (far_hit == -1).all()
    short_wall = FloorPlan(walls=(Wall(7, (3.15, -20.0), (3.15, 20.0), height=1.0),))
    under, under_hit = render_scan(short_wall, 0.0, 0.0, 0.0, SCANNER)
    assert np.isnan(under).all()
    assert (under_hit == -1).all()


def test_scan_noise_and_seen_threshold():
    ranges, hit = render_scan(
        wall_ahead_of_scanner(2.0), 0.0, 0.0, 0.0, SCANNER, np.random.default_rng(4)
    )
    seen = hit == 7
    error = ranges[seen] - 2.0 / np.cos(SCANNER.angles[seen])
    assert np.std(error) == pytest.approx(SCANNER.noise_sigma, rel=0.15)
    assert abs(np.mean(error)) < 0.003

    # A 20 cm wall at 3 m spans 7 beams (3.8 degrees): not enough for a line.
    stub = FloorPlan(walls=(Wall(2, (3.15, -0.1), (3.15, 0.1)),))
    ranges, hit = render_scan(stub, 0.0, 0.0, 0.0, SCANNER)
    assert (hit == 2).sum() == 7
    assert scan_walls_seen(hit, ranges) == set()
    assert scan_walls_seen(hit, ranges, min_beams=7) == {2}


# --- bags ----------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["ros1", "ros2-mcap", "ros2-sqlite3"])
@pytest.mark.parametrize("sensor", ["pointcloud", "depth16", "depth32"])
def test_bag_round_trip(tmp_path, fmt, sensor):
    path = bag_path(tmp_path, fmt)
    info = write_scene_bag(path, seed=3, n_frames=8, fmt=fmt, sensor=sensor)
    messages, types = read_bag(path)

    assert info.n_frames == 8
    assert info.truth_path == tmp_path / f"{path.name}.truth.json"
    expected_types = {
        TF_STATIC_TOPIC: "tf2_msgs/msg/TFMessage",
        TF_TOPIC: "tf2_msgs/msg/TFMessage",
        ODOM_TOPIC: "nav_msgs/msg/Odometry",
        GROUND_TRUTH_TOPIC: "geometry_msgs/msg/PoseStamped",
        AMCL_POSE_TOPIC: "geometry_msgs/msg/PoseWithCovarianceStamped",
    }
    if sensor == "pointcloud":
        expected_types[POINTS_TOPIC] = "sensor_msgs/msg/PointCloud2"
    else:
        expected_types[IMAGE_TOPIC] = "sensor_msgs/msg/Image"
        expected_types[CAMERA_INFO_TOPIC] = "sensor_msgs/msg/CameraInfo"
    assert types == expected_types
    sensor_topic = POINTS_TOPIC if sensor == "pointcloud" else IMAGE_TOPIC
    for topic in (ODOM_TOPIC, GROUND_TRUTH_TOPIC, AMCL_POSE_TOPIC, sensor_topic):
        assert len(messages[topic]) == 8
    # Odom → base_link at the 8 stamps and the 7 midpoints, map → odom at 10 Hz (5) plus
    # one at the last stamp so that it can be interpolated up to the end.
    assert len(messages[TF_TOPIC]) == 15 + 6
    assert len(messages[TF_STATIC_TOPIC]) == 1

    frame_ns = [stamp_to_ns(s) for s in info.trajectory.stamps]
    for topic in (ODOM_TOPIC, GROUND_TRUTH_TOPIC, AMCL_POSE_TOPIC, sensor_topic):
        assert [ns for ns, _ in messages[topic]] == frame_ns
        assert [header_ns(m.header) for _, m in messages[topic]] == frame_ns
    for ns, msg in messages[GROUND_TRUTH_TOPIC]:
        i = frame_ns.index(ns)
        assert msg.header.frame_id == "map"
        assert (msg.pose.position.x, msg.pose.position.y) == pytest.approx(
            info.trajectory.pose_at(i)[:2]
        )
    assert_amcl_is_the_truth(messages)
    if fmt == "ros1":
        assert [m.header.seq for _, m in messages[ODOM_TOPIC]] == list(range(8))

    camera = Camera()
    _, msg = messages[sensor_topic][4]
    assert msg.header.frame_id == "camera_optical_frame"
    assert (msg.height, msg.width) == (camera.height, camera.width)
    if sensor == "pointcloud":
        assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
            ("x", 0, 7, 1),
            ("y", 4, 7, 1),
            ("z", 8, 7, 1),
            ("rgb", 16, 7, 1),
        ]
        assert (msg.point_step, msg.row_step, msg.is_dense) == (32, 32 * 160, False)
        raw = np.frombuffer(msg.data, dtype=np.uint8).reshape(120, 160, 32)
        xyz = np.stack([raw[..., o : o + 4].copy().view("<f4")[..., 0] for o in (0, 4, 8)], -1)
        depth = xyz[..., 2]
        np.testing.assert_allclose(xyz, depth_to_points(depth, camera), rtol=1e-6)
    else:
        assert msg.step == msg.width * (2 if sensor == "depth16" else 4)
        if sensor == "depth16":
            assert msg.encoding == "16UC1"
            mm = np.frombuffer(msg.data, dtype="<u2").reshape(120, 160)
            depth = np.where(mm == 0, np.nan, mm / 1000.0)
        else:
            assert msg.encoding == "32FC1"
            depth = np.frombuffer(msg.data, dtype="<f4").reshape(120, 160)
        _, cam_info = messages[CAMERA_INFO_TOPIC][4]
        k = cam_info.K if fmt == "ros1" else cam_info.k
        np.testing.assert_allclose(np.reshape(k, (3, 3)), camera.K)
        assert cam_info.distortion_model == "plumb_bob"
        assert header_ns(cam_info.header) == header_ns(msg.header)
    # Returns are in range and land on true walls (or floor/ceiling/furniture).
    valid = np.isfinite(depth)
    assert valid.any()
    assert depth[valid].min() >= camera.min_range - 0.01
    assert depth[valid].max() <= camera.max_range + 0.1

    truth = json.loads(info.truth_path.read_text())
    assert Camera.from_json(truth["camera"]) == camera
    assert (truth["seed"], truth["n_frames"], truth["stamps_ns"]) == (3, 8, frame_ns)
    plan, trajectory, seen = load_truth(info.truth_path)
    assert plan == info.plan
    np.testing.assert_array_equal(trajectory.stamps, info.trajectory.stamps)
    assert seen == info.seen_counts


def assert_amcl_is_the_truth(messages):
    """/amcl_pose repeats /ground_truth with a 2 cm, 1 degree covariance."""
    expected = np.zeros(36)
    expected[[0, 7]] = 0.02**2
    expected[35] = math.radians(1.0) ** 2
    amcl, truth = messages[AMCL_POSE_TOPIC], messages[GROUND_TRUTH_TOPIC]
    assert len(amcl) == len(truth)
    for (ns, msg), (truth_ns, truth_msg) in zip(amcl, truth, strict=True):
        assert ns == truth_ns
        assert header_ns(msg.header) == header_ns(truth_msg.header)
        assert msg.header.frame_id == "map"
        assert msg.pose.pose == truth_msg.pose
        np.testing.assert_array_equal(msg.pose.covariance, expected)


def interpolate_planar(samples, ns):
    """tf2-style interpolation of planar transforms {ns: (x, y, yaw)} at time ns."""
    times = sorted(samples)
    if ns in samples:
        return samples[ns]
    after = next(t for t in times if t > ns)
    before = max(t for t in times if t < ns)
    a = (ns - before) / (after - before)
    (x0, y0, w0), (x1, y1, w1) = samples[before], samples[after]
    return (
        x0 + a * (x1 - x0),
        y0 + a * (y1 - y0),
        w0 + a * math.remainder(w1 - w0, 2 * math.pi),
    )


def test_tf_chain_gives_the_true_pose_over_a_whole_drive(tmp_path):
    camera = Camera(width=8, height=6)  # tiny: this test is about tf, not pixels
    path = bag_path(tmp_path, "ros2-mcap")
    info = write_scene_bag(
        path, seed=12, n_frames=100_000, fmt="ros2-mcap", sensor="depth32", camera=camera
    )
    messages, _ = read_bag(path)

    assert info.n_frames >= 600  # the route ended first: a natural 40+ s drive
    assert len(messages[GROUND_TRUTH_TOPIC]) == info.n_frames
    map_odom, odom_base = {}, {}
    for _, msg in messages[TF_TOPIC]:
        for tf in msg.transforms:
            pose = (
                tf.transform.translation.x,
                tf.transform.translation.y,
                quat_yaw(tf.transform.rotation),
            )
            key = (tf.header.frame_id, tf.child_frame_id)
            {("map", "odom"): map_odom, ("odom", "base_link"): odom_base}[key][
                header_ns(tf.header)
            ] = pose
    rate = len(map_odom) / (max(map_odom) - min(map_odom)) * 1e9
    assert rate == pytest.approx(10.0, rel=0.02)

    worst, drift = 0.0, 0.0
    for i, stamp in enumerate(info.trajectory.stamps):
        ns = stamp_to_ns(stamp)
        assert ns in odom_base  # published at every sensor stamp
        chain = se2(*interpolate_planar(map_odom, ns)) @ se2(*odom_base[ns])
        x, y, yaw = info.trajectory.pose_at(i)
        worst = max(worst, math.hypot(chain[0, 2] - x, chain[1, 2] - y))
        assert math.remainder(math.atan2(chain[1, 0], chain[0, 0]) - yaw, 2 * math.pi) == (
            pytest.approx(0.0, abs=1e-4)
        )
        drift = max(drift, math.hypot(odom_base[ns][0] - x, odom_base[ns][1] - y))
    assert worst < 1e-3
    assert drift > 0.3  # the odometry alone is clearly wrong

    odom_msgs = messages[ODOM_TOPIC]
    assert odom_msgs[0][1].pose.pose.position.x == pytest.approx(info.trajectory.x[0])
    speeds = [math.hypot(m.twist.twist.linear.x, m.twist.twist.linear.y) for _, m in odom_msgs]
    assert max(speeds) == pytest.approx(0.4, rel=0.1)

    ((_, static),) = messages[TF_STATIC_TOPIC]
    chain = np.eye(4)
    for tf, (parent, child) in zip(
        static.transforms,
        [("base_link", "camera_link"), ("camera_link", "camera_optical_frame")],
        strict=True,
    ):
        assert (tf.header.frame_id, tf.child_frame_id) == (parent, child)
        step = np.eye(4)
        step[:3, :3] = quat_matrix(tf.transform.rotation)
        step[:3, 3] = [
            tf.transform.translation.x,
            tf.transform.translation.y,
            tf.transform.translation.z,
        ]
        chain = chain @ step
    np.testing.assert_allclose(chain, camera.T_base_camera, atol=1e-12)


def test_point_cloud_lands_on_the_true_walls(tmp_path):
    path = bag_path(tmp_path, "ros1")
    info = write_scene_bag(path, seed=5, n_frames=30, fmt="ros1", sensor="pointcloud")
    messages, _ = read_bag(path)
    camera = Camera()
    mount = camera.T_base_camera
    walls = [w for w in info.plan.walls if not w.glass]
    a = np.array([w.p0 for w in walls])
    b = np.array([w.p1 for w in walls])

    on_walls = 0
    for i, (_, msg) in enumerate(messages[POINTS_TOPIC][::5]):
        raw = np.frombuffer(msg.data, dtype=np.uint8).reshape(-1, 32)
        xyz = np.stack([raw[:, o : o + 4].copy().view("<f4")[:, 0] for o in (0, 4, 8)], -1)
        base = xyz.astype(float) @ mount[:3, :3].T + mount[:3, 3]
        band = np.isfinite(base[:, 2]) & (base[:, 2] > 1.3) & (base[:, 2] < 2.1)
        x, y, yaw = info.trajectory.pose_at(5 * i)
        world = base[band, :2] @ se2(x, y, yaw)[:2, :2].T + [x, y]
        d = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
        rel = world[:, None, :] - a[None]
        along = np.einsum("kmi,mi->km", rel, d)
        across = np.abs(np.einsum("kmi,mi->km", rel, d[:, ::-1] * [-1, 1]))
        inside = (along >= -0.05) & (along <= np.linalg.norm(b - a, axis=1) + 0.05)
        nearest = np.where(inside, across, np.inf).min(axis=1)
        # Depth noise at 5 m is 3.6 cm; the band is above all furniture.
        assert (nearest < 0.15).all()
        on_walls += len(nearest)
    assert on_walls > 1000

    seen = info.seen_counts
    assert set(seen) == {w.id for w in info.plan.walls}
    assert sum(k >= 3 for k in seen.values()) >= 2
    assert max(seen.values()) <= 30
    assert all(seen[w.id] == 0 for w in info.plan.walls if w.glass)


def test_short_custom_plan_needs_a_route(tmp_path):
    with pytest.raises(ValueError, match="route"):
        write_scene_bag(
            tmp_path / "x.bag",
            seed=0,
            n_frames=3,
            fmt="ros1",
            sensor="depth16",
            plan=wall_ahead(3.0),
        )


@pytest.mark.parametrize("fmt", ["ros1", "ros2-mcap"])
def test_laserscan_bag_round_trip(tmp_path, fmt):
    path = bag_path(tmp_path, fmt)
    scanner = Scanner(mount_xyz=(0.2, -0.05, 1.3))
    info = write_scene_bag(path, seed=4, n_frames=40, fmt=fmt, sensor="laserscan", scanner=scanner)
    messages, types = read_bag(path)

    assert types == {
        TF_STATIC_TOPIC: "tf2_msgs/msg/TFMessage",
        TF_TOPIC: "tf2_msgs/msg/TFMessage",
        ODOM_TOPIC: "nav_msgs/msg/Odometry",
        GROUND_TRUTH_TOPIC: "geometry_msgs/msg/PoseStamped",
        AMCL_POSE_TOPIC: "geometry_msgs/msg/PoseWithCovarianceStamped",
        SCAN_TOPIC: "sensor_msgs/msg/LaserScan",
    }
    frame_ns = [stamp_to_ns(s) for s in info.trajectory.stamps]
    assert [ns for ns, _ in messages[SCAN_TOPIC]] == frame_ns
    assert [header_ns(m.header) for _, m in messages[SCAN_TOPIC]] == frame_ns
    assert len(messages[TF_TOPIC]) == 79 + 27
    assert_amcl_is_the_truth(messages)

    ((_, static),) = messages[TF_STATIC_TOPIC]
    ((tf,),) = [static.transforms]
    assert (tf.header.frame_id, tf.child_frame_id) == ("base_link", "laser")
    translation = tf.transform.translation
    assert (translation.x, translation.y, translation.z) == (0.2, -0.05, 1.3)
    rotation = tf.transform.rotation
    assert (rotation.x, rotation.y, rotation.z, rotation.w) == (0.0, 0.0, 0.0, 1.0)

    walls = [w for w in info.plan.walls if not w.glass]
    a = np.array([w.p0 for w in walls])
    b = np.array([w.p1 for w in walls])
    returns = 0
    for i, (_, msg) in enumerate(messages[SCAN_TOPIC]):
        assert msg.header.frame_id == "laser"
        assert msg.angle_min == pytest.approx(-3 * math.pi / 4)
        assert msg.angle_max == pytest.approx(3 * math.pi / 4)
        assert msg.angle_increment == pytest.approx(math.radians(0.5))
        assert (msg.range_min, msg.range_max) == pytest.approx((0.1, 8.0))
        assert msg.scan_time == pytest.approx(1 / 15)
        assert msg.ranges.dtype == np.float32
        assert len(msg.ranges) == 541
        assert len(msg.intensities) == 0
        finite = np.isfinite(msg.ranges)
        assert np.isnan(msg.ranges).sum() == 0  # no return is +inf, REP 117
        assert (msg.ranges[finite] >= 0.1).all()
        assert (msg.ranges[finite] <= 8.0).all()
        # Every return lies on a real wall: the plan's furniture is below the beam.
        angles = msg.angle_min + msg.angle_increment * np.arange(541)
        local = np.column_stack([np.cos(angles), np.sin(angles)])[finite] * msg.ranges[
            finite, None
        ].astype(float) + [0.2, -0.05]
        x, y, yaw = info.trajectory.pose_at(i)
        world = local @ se2(x, y, yaw)[:2, :2].T + [x, y]
        distance = segment_distances(world, world, a, b).min(axis=1)
        assert distance.max() < 0.06  # 0.01 m noise, 6 sigma
        returns += finite.sum()
    assert returns > 40 * 100

    truth = json.loads(info.truth_path.read_text())
    assert "camera" not in truth
    assert Scanner.from_json(truth["scanner"]) == scanner
    assert truth["sensor"] == "laserscan"
    _, _, seen = load_truth(info.truth_path)
    assert seen == info.seen_counts
    assert sum(k >= 3 for k in seen.values()) >= 3
    assert max(seen.values()) <= 40
    assert all(seen[w.id] == 0 for w in info.plan.walls if w.glass)


def test_laserscan_bag_in_sqlite3_with_the_default_scanner(tmp_path):
    path = bag_path(tmp_path, "ros2-sqlite3")
    info = write_scene_bag(path, seed=4, n_frames=3, fmt="ros2-sqlite3", sensor="laserscan")
    messages, _ = read_bag(path)

    assert len(messages[SCAN_TOPIC]) == 3
    ((_, static),) = messages[TF_STATIC_TOPIC]
    assert static.transforms[0].transform.translation.z == 1.2
    truth = json.loads(info.truth_path.read_text())
    assert Scanner.from_json(truth["scanner"]) == Scanner()


def test_bags_are_reproducible(tmp_path):
    paths = [tmp_path / f"{name}.bag" for name in "ab"]
    for path in paths:
        write_scene_bag(path, seed=6, n_frames=5, fmt="ros1", sensor="depth16", compress=True)
    assert paths[0].read_bytes() == paths[1].read_bytes()


def test_tum_round_trip(tmp_path):
    traj = generate_trajectory(generate_floorplan(2), 2).sliced(slice(0, 200))
    path = tmp_path / "truth.tum"
    write_tum(traj, path)
    lines = path.read_text().splitlines()

    assert lines[0].startswith("#")
    assert len(lines) == 201
    fields = lines[1].split()
    assert len(fields) == 8
    assert fields[0] == f"{traj.stamps[0]:.9f}"
    assert float(fields[3]) == 0.0
    assert (float(fields[6]), float(fields[7])) == pytest.approx(
        (math.sin(traj.yaw[0] / 2), math.cos(traj.yaw[0] / 2)), abs=1e-9
    )
    back = read_tum(path)
    assert len(back) == len(traj)
    np.testing.assert_allclose(back.stamps, traj.stamps, rtol=0, atol=1e-9)
    assert [stamp_to_ns(s) for s in back.stamps] == [stamp_to_ns(s) for s in traj.stamps]
    np.testing.assert_allclose(back.x, traj.x, atol=1e-9)
    np.testing.assert_allclose(back.y, traj.y, atol=1e-9)
    np.testing.assert_allclose(np.angle(np.exp(1j * (back.yaw - traj.yaw))), 0.0, atol=1e-8)


# --- a fleet's second robot: the route driven backwards, poses in its own map frame --------


@pytest.mark.parametrize("seed", [0, 3])
def test_reversed_drive_starts_where_the_forward_one_ends(seed):
    plan = generate_floorplan(seed)
    forward = generate_trajectory(plan, seed, rate_hz=15.0)
    backward = generate_trajectory(plan, seed, rate_hz=15.0, reverse=True)
    xy = backward.positions

    np.testing.assert_allclose(xy[0], plan.route[-1], atol=1e-9)
    # A drive's last sample is up to one frame before its end: 1 mm short, braking.
    np.testing.assert_allclose(xy[0], forward.positions[-1], atol=1e-3)
    np.testing.assert_allclose(xy[-1], plan.route[0], atol=1e-3)
    assert len(backward) == len(forward)  # the same path, as long
    # The same building: the same path (to within half a 2.7 cm step), every doorway, clear.
    gaps = np.linalg.norm(xy[:, None] - forward.positions[None], axis=2)
    assert max(gaps.min(axis=0).max(), gaps.min(axis=1).max()) < 0.015
    assert clearance(plan, xy).min() >= 0.6
    for centre in doorway_centres(plan):
        assert np.linalg.norm(xy - centre, axis=1).min() < 0.03

    # As smooth as the forward drive, and it faces along its own way, not back along the route.
    velocity = np.diff(xy, axis=0) * 15.0
    speed = np.linalg.norm(velocity, axis=1)
    assert speed[0] < 0.05
    assert speed.max() == pytest.approx(0.4, abs=1e-3)
    assert np.linalg.norm(np.diff(velocity, axis=0), axis=1).max() < 0.05
    assert np.abs(np.diff(np.unwrap(backward.yaw))).max() < math.radians(5.0)
    heading = np.arctan2(velocity[:, 1], velocity[:, 0])
    off_heading = np.degrees(np.angle(np.exp(1j * (backward.yaw[1:] - heading))))
    assert np.abs(off_heading[speed > 0.01]).max() < 62.0


def planar_poses(messages):
    """/ground_truth, /amcl_pose and /odom as {topic: [(x, y, yaw)]}, and tf as {ns: pose}."""
    poses = {
        topic: [
            (p.position.x, p.position.y, quat_yaw(p.orientation))
            for p in (m.pose if topic == GROUND_TRUTH_TOPIC else m.pose.pose for _, m in msgs)
        ]
        for topic, msgs in messages.items()
        if topic in (GROUND_TRUTH_TOPIC, AMCL_POSE_TOPIC, ODOM_TOPIC)
    }
    map_odom, odom_base = {}, {}
    for _, msg in messages[TF_TOPIC]:
        for tf in msg.transforms:
            t = tf.transform
            pose = (t.translation.x, t.translation.y, quat_yaw(t.rotation))
            key = (tf.header.frame_id, tf.child_frame_id)
            {("map", "odom"): map_odom, ("odom", "base_link"): odom_base}[key][
                header_ns(tf.header)
            ] = pose
    return poses, map_odom, odom_base


def assert_in_world(pose, map_in_world, world):
    """``map_in_world * pose`` is the world pose, to 1 mm and 0.01 degrees."""
    moved = se2(*map_in_world) @ se2(*pose)
    assert math.dist(moved[:2, 2], world[:2]) < 1e-3
    yaw_error = math.remainder(math.atan2(moved[1, 0], moved[0, 0]) - world[2], 2 * math.pi)
    assert abs(math.degrees(yaw_error)) < 0.01


def sensor_data(messages):
    """The sensor messages' payloads and frames, which a map frame must not change."""
    return [
        (bytes(msg.data) if hasattr(msg, "data") else msg.ranges.tobytes(), msg.header.frame_id)
        for topic in (POINTS_TOPIC, IMAGE_TOPIC, SCAN_TOPIC)
        for _, msg in messages.get(topic, [])
    ]


@pytest.mark.parametrize(
    ("fmt", "sensor"),
    [("ros1", "depth16"), ("ros2-mcap", "laserscan"), ("ros2-sqlite3", "pointcloud")],
)
def test_own_frame_bag_starts_at_zero_and_maps_onto_the_world(tmp_path, fmt, sensor):
    kwargs = dict(seed=4, n_frames=40, fmt=fmt, sensor=sensor, camera=Camera(width=32, height=24))
    world_info = write_scene_bag(bag_path(tmp_path, fmt, "world"), reverse=True, **kwargs)
    path = bag_path(tmp_path, fmt)
    info = write_scene_bag(path, reverse=True, own_frame=True, **kwargs)
    messages, _ = read_bag(path)
    poses, map_odom, odom_base = planar_poses(messages)

    # A robot's own map frame: its first true pose, with odometry starting there too.
    for topic in (GROUND_TRUTH_TOPIC, AMCL_POSE_TOPIC, ODOM_TOPIC):
        assert poses[topic][0] == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    map_in_world = load_map_in_world(info.truth_path)
    assert map_in_world == info.map_in_world == world_info.trajectory.pose_at(0)
    assert math.hypot(*map_in_world[:2]) > 1.0  # the reversed drive starts far from the origin

    # The truth file is in the world, as without the option; the transform puts the bag there.
    plan, trajectory, seen = load_truth(info.truth_path)
    assert plan == world_info.plan
    assert seen == world_info.seen_counts
    np.testing.assert_array_equal(trajectory.x, world_info.trajectory.x)
    for i, stamp in enumerate(trajectory.stamps):
        world = trajectory.pose_at(i)
        assert_in_world(poses[GROUND_TRUTH_TOPIC][i], map_in_world, world)
        assert_in_world(poses[AMCL_POSE_TOPIC][i], map_in_world, world)
        ns = stamp_to_ns(stamp)
        chain = se2(*interpolate_planar(map_odom, ns)) @ se2(*odom_base[ns])
        chain_pose = (chain[0, 2], chain[1, 2], math.atan2(chain[1, 0], chain[0, 0]))
        assert_in_world(chain_pose, map_in_world, world)

    # The same drift and the same sensor data as the same drive in the plan's frame.
    world_messages, _ = read_bag(world_info.path)
    for pose, world in zip(
        poses[ODOM_TOPIC], planar_poses(world_messages)[0][ODOM_TOPIC], strict=True
    ):
        assert_in_world(pose, map_in_world, world)
    assert sensor_data(messages) == sensor_data(world_messages)
    assert len(sensor_data(messages)) == 40
    assert load_map_in_world(world_info.truth_path) == (0.0, 0.0, 0.0)
    assert load_map_in_world(SAMPLE_TRUTH) == (0.0, 0.0, 0.0)  # an old file, without the key


def test_own_frame_faulty_poses_and_their_tum_file(tmp_path):
    path = bag_path(tmp_path, "ros1")
    faults = PoseFaults(latency=0.2, seed=1)
    info = write_scene_bag(
        path, seed=4, n_frames=20, fmt="ros1", sensor="laserscan", faults=faults, own_frame=True
    )
    messages, _ = read_bag(path)
    poses, _, _ = planar_poses(messages)
    tum = read_tum(f"{path}.poses.tum")

    # The faulty source holds the first pose through its latency: the origin of its map.
    assert tum.pose_at(0) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    sensor_rows = tum.sliced(slice(None, None, 2))
    np.testing.assert_allclose(
        np.column_stack([sensor_rows.x, sensor_rows.y, sensor_rows.yaw]),
        poses[GROUND_TRUTH_TOPIC],
        atol=1e-6,
    )
    late = round(0.2 * 15)  # frames: the source says where the robot was 0.2 s before
    for i in range(late, len(info.trajectory)):
        world = info.trajectory.pose_at(i - late)
        assert_in_world(poses[GROUND_TRUTH_TOPIC][i], info.map_in_world, world)


def walls_in_world(walls, map_in_world):
    """Mapped walls, records of a map reply, moved by ``map_in_world`` into the plan's frame."""
    move = se2(*map_in_world)

    def moved(point):
        return (move @ [point[0], point[1], 1.0])[:2].tolist()

    records = []
    for wall in walls:
        record = wall.to_map()
        p0, p1 = moved(record["p0"]), moved(record["p1"])
        on_line = np.array(moved((record["u"], record["v"])))
        along = np.subtract(p1, p0) / math.dist(p0, p1)
        closest = on_line - (on_line @ along) * along  # to the origin, as (u, v) is
        segments = [[moved(a), moved(b)] for a, b in record["segments"]]
        record.update(u=closest[0], v=closest[1], p0=p0, p1=p1, segments=segments)
        records.append(record)
    return records


def test_second_robots_bag_maps_the_plan_once_moved_into_the_world(tmp_path):
    path = bag_path(tmp_path, "ros1")
    camera = Camera(width=160, height=120)
    kwargs = dict(fmt="ros1", sensor="depth16", camera=camera, reverse=True, own_frame=True)
    info = write_scene_bag(path, seed=5, n_frames=200, **kwargs)
    walls = offline.walls(offline.run_bag(path).map)
    plan, _, seen = load_truth(info.truth_path)

    score = evaluate_map(walls_in_world(walls, load_map_in_world(info.truth_path)), plan, seen)
    assert score.n_mapped >= 5
    assert score.precision == 1.0
    assert score.recall >= 0.85
    assert score.median_angle_deg < 0.5
    assert score.median_offset_m < 0.02
    # Not by luck: in the robot's own frame the same walls match nothing of the plan.
    assert evaluate_map(walls, plan, seen).n_mapped_matched == 0


@pytest.mark.parametrize(("flag", "fmt"), [("--reverse", "ros1"), ("--own-frame", "ros2-mcap")])
def test_scene_command_reverse_and_own_frame_flags(tmp_path, flag, fmt):
    out = bag_path(tmp_path, fmt)
    args = ["--seed", "2", "--frames", "5", "--format", fmt, "--sensor", "laserscan", flag]
    done = run_wallmap("scene", str(out), *args, cwd=tmp_path)
    truth_path = out.with_name(f"{out.name}.truth.json")
    plan, trajectory, _ = load_truth(truth_path)
    messages, _ = read_bag(out)
    first = planar_poses(messages)[0][GROUND_TRUTH_TOPIC][0]
    map_in_world = load_map_in_world(truth_path)
    assert json.loads(truth_path.read_text())["reverse"] == (flag == "--reverse")

    if flag == "--reverse":  # from the route's end, poses in the plan's frame
        np.testing.assert_allclose(trajectory.positions[0], plan.route[-1], atol=1e-9)
        assert math.dist(plan.route[-1], plan.route[0]) > 1.0
        assert map_in_world == (0.0, 0.0, 0.0)
        assert first == pytest.approx(trajectory.pose_at(0), abs=1e-9)
        assert "map_in_world" not in done.stdout
    else:  # from the route's start, poses in a map frame there
        np.testing.assert_allclose(trajectory.positions[0], plan.route[0], atol=1e-9)
        assert map_in_world == pytest.approx(trajectory.pose_at(0), abs=1e-12)
        assert abs(map_in_world[2]) > 0.1  # not the plan's frame: turned at least
        assert first == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
        assert "map_in_world" in done.stdout


def test_scene_command_keep_leaves_a_written_scene_and_only_that(tmp_path):
    """``--keep``: a setup step run again (docker-compose's fleet) keeps the bag it wrote; a path
    holding anything else is still refused."""
    out = tmp_path / "kept.bag"
    run_wallmap("scene", str(out), "--frames", "5", "--sensor", "laserscan", cwd=tmp_path)
    before = out.read_bytes()
    again = run_wallmap("scene", str(out), "--frames", "9", "--keep", cwd=tmp_path)
    assert again.stdout.startswith(f"kept {out}: written before")
    assert out.read_bytes() == before
    refused = run_wallmap("scene", str(out), "--frames", "5", cwd=tmp_path, expect=1)
    assert "exists; choose a new path" in refused.stderr
    other = tmp_path / "other.bag"
    other.write_bytes(b"not a scene")
    refused = run_wallmap("scene", str(other), "--keep", cwd=tmp_path, expect=1)
    assert "exists; choose a new path" in refused.stderr
