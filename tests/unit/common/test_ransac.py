"""Line detection in one scan row: clusters, sequential RANSAC, fit covariance."""

import numpy as np
import pytest

from wallmap.common.line_fit import fit_line
from wallmap.common.ransac import RansacConfig, RowReport, detect_lines, split_at_nans
from wallmap.common.scan_row import RowSelection, select_scan


def test_split_at_nans_gives_runs_of_finite_points():
    scan = np.array([[1, 1], [np.nan, 0], [2, 2], [3, 3], [np.nan, np.nan], [4, 4]], float)
    runs = split_at_nans(scan)
    assert [r.tolist() for r in runs] == [[0], [2, 3], [5]]
    assert split_at_nans(np.full((4, 2), np.nan)) == []


def test_fit_covariance_matches_monte_carlo():
    rng = np.random.default_rng(0)
    t = np.linspace(-1.5, 1.0, 60)
    normal = np.array([np.cos(0.7), np.sin(0.7)])
    along = np.array([-normal[1], normal[0]])
    base = 2.5 * normal + t[:, None] * along
    sigma = 0.01
    closest = []
    fits = []
    for _ in range(2000):
        pts = base + rng.normal(0, sigma, len(t))[:, None] * normal
        fit = fit_line(pts)
        closest.append(fit.closest)
        fits.append(fit.cov)
    empirical = np.cov(np.array(closest).T)
    predicted = np.mean(fits, axis=0)
    np.testing.assert_allclose(predicted, empirical, rtol=0.15, atol=1e-8)
    np.testing.assert_allclose(np.mean(closest, axis=0), 2.5 * normal, atol=1e-3)


def room_scan(rng, noise=0.005):
    """A corner of two walls seen from the origin, with a gap of no return in one."""
    a = np.column_stack([np.full(80, 3.0), np.linspace(-2.0, 1.5, 80)])  # x = 3
    b = np.column_stack([np.linspace(2.9, 0.5, 60), np.full(60, 1.6)])  # y = 1.6
    scan = np.vstack([a, b]) + rng.normal(0, noise, (140, 2))
    scan[30:35] = np.nan  # glass or a dark patch
    return scan


def test_sequential_ransac_finds_both_walls_of_a_corner():
    rng = np.random.default_rng(1)
    lines = detect_lines(room_scan(rng), RansacConfig(noise_k=0.0), rng)
    got = sorted((round(float(line.offset), 2), tuple(np.round(line.normal, 2))) for line in lines)
    # x = 3 appears twice: split by the gap of no return (two clusters), as the paper does.
    assert got == [(1.6, (0.0, 1.0)), (3.0, (1.0, 0.0)), (3.0, (1.0, 0.0))]
    for line in lines:
        assert line.rms < 0.01
        assert np.all(np.linalg.eigvalsh(line.cov) > 0)


def test_ransac_ignores_scattered_clutter():
    rng = np.random.default_rng(2)
    wall = np.column_stack([np.linspace(-2, 2, 100), np.full(100, 2.0)])
    clutter = rng.uniform([-2, 0.5], [2, 1.8], (40, 2))
    scan = np.vstack([wall[:50], clutter, wall[50:]])
    lines = detect_lines(scan, RansacConfig(noise_k=0.0), rng)
    assert len(lines) == 1
    assert lines[0].offset == pytest.approx(2.0, abs=0.005)
    assert lines[0].length == pytest.approx(4.0, abs=0.1)


def test_ransac_splits_collinear_walls_across_a_doorway():
    rng = np.random.default_rng(3)
    left = np.column_stack([np.linspace(-3, -0.5, 60), np.full(60, 2.0)])
    right = np.column_stack([np.linspace(0.5, 3, 60), np.full(60, 2.0)])
    lines = detect_lines(np.vstack([left, right]), RansacConfig(noise_k=0.0), rng)
    assert len(lines) == 2
    assert sorted(round(float(line.p0[0] + line.p1[0]) / 2, 1) for line in lines) == [-1.8, 1.8]


def camera_on_base(height=1.0, pitch=0.0):
    """T_base_sensor for an optical frame (z forward, x right, y down) at `height`."""
    optical = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], float)
    c, s = np.cos(pitch), np.sin(pitch)
    tilt = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # pitch about base y (nose down > 0)
    t = np.eye(4)
    t[:3, :3] = tilt @ optical
    t[:3, 3] = [0.1, 0.0, height]
    return t


def test_band_scan_takes_points_inside_the_height_band_per_column():
    T_base_sensor = camera_on_base()
    rows = np.linspace(-1.5, 1.5, 7)  # optical y (down) at 3 m: heights 2.5 .. -0.5 above camera
    cols = np.linspace(-1, 1, 5)
    pts = np.zeros((7, 5, 3), np.float32)
    pts[..., 0] = cols[None, :]
    pts[..., 1] = rows[:, None]
    pts[..., 2] = 3.0
    pts[3, 2] = np.nan  # the centre pixel has no return
    xy = select_scan(pts, T_base_sensor, RowSelection(band=(1.3, 2.1)))
    # Heights are 1 - y: rows with y in [-1.1, -0.3] qualify: y = -0.5 (height 1.5), -1.0 (2.0).
    assert np.allclose(xy[:, 0], 3.1)
    np.testing.assert_allclose(xy[:, 1], -cols)
    one_row = select_scan(pts, T_base_sensor, RowSelection(mode="row", row_fraction=0.5))
    assert np.isnan(one_row[2]).all()
    assert np.isfinite(one_row[[0, 1, 3, 4]]).all()


def far_glimpse(rng, share_of_cluster: bool) -> np.ndarray:
    """18 points over 0.7 m of a wall 5 m away (a Kinect's noise), alone or beside a near wall."""
    wall = np.column_stack([np.linspace(-0.35, 0.35, 18), np.full(18, 5.0)])
    wall[:, 1] += rng.normal(0, 1.425e-3 * 25, 18)
    if not share_of_cluster:
        return wall
    near = np.column_stack([np.linspace(0.4, 2.0, 40), np.linspace(4.9, 3.0, 40)])
    return np.vstack([wall, near + rng.normal(0, 0.005, (40, 2))])


def test_a_far_wall_alone_in_its_cluster_is_kept_though_its_direction_is_unsure():
    params = RansacConfig()
    scan = far_glimpse(np.random.default_rng(5), False)
    (line,) = detect_lines(scan, params, np.random.default_rng(0))
    assert params.max_angle_sd < line.angle_sd <= params.lone_angle_sd  # the rule was needed
    assert abs(line.normal[1]) == pytest.approx(1.0, abs=0.02)
    assert line.offset == pytest.approx(5.0, abs=0.05)


def test_the_same_glimpse_beside_another_wall_is_refused_as_unsure():
    scan = far_glimpse(np.random.default_rng(5), True)
    lines = detect_lines(scan, RansacConfig(), np.random.default_rng(0))
    loose = detect_lines(scan, RansacConfig(max_angle_sd=1.0), np.random.default_rng(0))
    far = [line for line in loose if line.offset > 4.5 and abs(line.normal[1]) > 0.99]
    assert far  # found...
    assert far[0].angle_sd > RansacConfig().max_angle_sd  # ...but unsure...
    assert not [line for line in lines if line.offset > 4.5 and abs(line.normal[1]) > 0.99]
    assert len(lines) == 1  # ...so only the near wall is kept


def test_a_wall_split_at_its_neighbours_corner_is_joined_again():
    # A 0.8 m wall at 3 m meeting a long one at 29 degrees, with twice a Kinect's noise: the long
    # line's inlier band takes the end of the short wall, the kink test cuts it off, and both
    # pieces of the short wall are too short to be sure of on their own.
    rng = np.random.default_rng(4)
    p0, corner, p2 = np.array([2.65, 1.38]), np.array([3.32, 0.95]), np.array([4.7, -1.6])
    short = p0 + np.outer(np.linspace(0, 1, 36, endpoint=False), corner - p0)
    long = corner + np.outer(np.linspace(0, 1, 95), p2 - corner)
    scan = np.vstack([short, long])
    ranges = np.linalg.norm(scan, axis=1)
    scan += scan / ranges[:, None] * rng.normal(0, 2 * 1.425e-3 * ranges**2)[:, None]
    report = RowReport()
    lines = detect_lines(scan, RansacConfig(noise_scale=1.5), np.random.default_rng(0), report)
    assert report.rejected["direction less sure than max_angle_sd"] >= 2  # two unsure pieces...
    angles = sorted(np.degrees(np.arctan2(-line.normal[0], line.normal[1])) for line in lines)
    assert len(lines) == 2  # ...joined into the short wall
    assert angles[1] == pytest.approx(-32.7, abs=2.0)
    assert angles[0] == pytest.approx(-61.6, abs=1.0)
