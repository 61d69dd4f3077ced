"""The wall measurement model against geometry and numeric differentiation."""

import numpy as np
import pytest
from numeric import numeric_jacobian

from wallmap.common import ekf, se2, wall_model


def closest_point_in_robot_frame(p0, p1, pose):
    """Ground truth by plain geometry: the foot of the perpendicular from the robot."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    t = np.asarray(pose[:2], float)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    foot = p0 + ((t - p0) @ d) * d
    return se2.rotation(pose[2]).T @ (foot - t)


def wall_from_points(p0, p1, anchor):
    p0, p1, anchor = (np.asarray(x, float) for x in (p0, p1, anchor))
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    foot = p0 + ((anchor - p0) @ d) * d
    return foot - anchor


RNG = np.random.default_rng(7)
CASES = [
    (RNG.uniform(-5, 5, 2), RNG.uniform(-5, 5, 2), RNG.uniform(-3, 3, 2), RNG.uniform(-3, 3, 3))
    for _ in range(50)
]


@pytest.mark.parametrize(("p0", "p1", "anchor", "pose"), CASES)
def test_prediction_matches_geometry(p0, p1, anchor, pose):
    s = wall_from_points(p0, p1, anchor)
    expected = closest_point_in_robot_frame(p0, p1, pose)
    np.testing.assert_allclose(wall_model.predict(s, anchor, pose), expected, atol=1e-9)


@pytest.mark.parametrize(("p0", "p1", "anchor", "pose"), CASES)
def test_jacobians_match_numeric_differentiation(p0, p1, anchor, pose):
    s = wall_from_points(p0, p1, anchor)
    num_s = numeric_jacobian(lambda x: wall_model.predict(x, anchor, pose), s)
    num_pose = numeric_jacobian(lambda x: wall_model.predict(s, anchor, x), pose)
    np.testing.assert_allclose(wall_model.jacobian_state(s, anchor, pose), num_s, atol=1e-6)
    np.testing.assert_allclose(wall_model.jacobian_pose(s, anchor, pose), num_pose, atol=1e-6)


@pytest.mark.parametrize(("p0", "p1", "anchor", "pose"), CASES[:20])
def test_from_observation_inverts_prediction(p0, p1, anchor, pose):
    z = closest_point_in_robot_frame(p0, p1, pose)
    s, new_anchor, ds_dz, ds_dpose = wall_model.from_observation(z, pose)
    np.testing.assert_allclose(wall_model.predict(s, new_anchor, pose), z, atol=1e-9)
    # The line it starts is the true line: same closest point from any other pose.
    other = np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(
        wall_model.predict(s, new_anchor, other),
        closest_point_in_robot_frame(p0, p1, other),
        atol=1e-9,
    )

    # Jacobians: the state is a function of (z, pose) with the anchor held where it was chosen.
    def state_of(z_, pose_):
        t, r = pose_[:2], se2.rotation(pose_[2])
        n = r @ z_ / np.linalg.norm(z_)
        return (n @ (t - new_anchor) + np.linalg.norm(z_)) * n

    np.testing.assert_allclose(ds_dz, numeric_jacobian(lambda x: state_of(x, pose), z), atol=1e-6)
    np.testing.assert_allclose(
        ds_dpose, numeric_jacobian(lambda x: state_of(z, x), pose), atol=1e-6
    )


@pytest.mark.parametrize(("p0", "p1", "anchor", "pose"), CASES[:20])
def test_map_frame_closest_point_and_its_jacobian(p0, p1, anchor, pose):
    s = wall_from_points(p0, p1, anchor)
    uv, jac = wall_model.to_map_frame(s, anchor)
    np.testing.assert_allclose(uv, wall_from_points(p0, p1, [0.0, 0.0]), atol=1e-9)
    np.testing.assert_allclose(
        jac, numeric_jacobian(lambda x: wall_model.to_map_frame(x, anchor)[0], s), atol=1e-5
    )


def test_line_through_the_map_origin_is_regular_in_the_anchored_state():
    # The wall y = x passes through the origin, where (u, v) = 0 loses its direction.
    anchor = np.array([2.0, 0.0])
    s = wall_from_points([-3, -3], [3, 3], anchor)
    uv, _ = wall_model.to_map_frame(s, anchor)
    np.testing.assert_allclose(uv, [0.0, 0.0], atol=1e-12)
    pose = np.array([1.0, -1.5, 0.4])
    np.testing.assert_allclose(
        wall_model.predict(s, anchor, pose),
        closest_point_in_robot_frame([-3, -3], [3, 3], pose),
        atol=1e-12,
    )


def test_driving_along_a_wall_leaves_the_observation_unchanged_unlike_the_point_model():
    # Wall y = 2; the robot drives 3 m along it facing +x.
    anchor = np.zeros(2)
    s = np.array([0.0, 2.0])
    for x in np.linspace(0, 3, 7):
        pose = np.array([x, 0.0, 0.0])
        np.testing.assert_allclose(wall_model.predict(s, anchor, pose), [0.0, 2.0], atol=1e-12)
    # The paper's equations move (u, v) as a point: after 3 m they predict (-3, 2), 3 m off.
    point_model = se2.rotation(0.0).T @ (s - np.array([3.0, 0.0]))
    np.testing.assert_allclose(point_model, [-3.0, 2.0])


def test_innovation_gates_with_the_innovation_covariance_not_the_wall_covariance():
    # A wall seen many times has a tiny covariance; a fresh observation 1 cm off is still fine.
    s, anchor = np.array([0.0, 2.0]), np.zeros(2)
    p = np.eye(2) * 1e-8
    r = np.eye(2) * 1e-4  # 1 cm
    pose, pose_cov = np.array([1.0, 0.0, 0.0]), np.zeros((3, 3))
    z = np.array([0.0, 2.01])
    innov = ekf.innovation(s, p, anchor, z, r, pose, pose_cov)
    assert innov.mahalanobis2 < ekf.CHI2_2DOF_999
    paper_style = float((z - [0.0, 2.0]) @ np.linalg.solve(p, z - [0.0, 2.0]))
    assert paper_style > 100 * ekf.CHI2_2DOF_999  # the paper would start a duplicate wall


def test_ekf_converges_and_is_consistent():
    rng = np.random.default_rng(3)
    true_p0, true_p1 = np.array([-4.0, 3.0]), np.array([5.0, 1.0])
    r = np.diag([0.02**2, 0.01**2])
    nees = []
    for _trial in range(40):
        pose0 = np.array([0.0, 0.0, 0.2])
        z0 = closest_point_in_robot_frame(true_p0, true_p1, pose0)
        s, p, anchor = ekf.initial_state(
            z0 + rng.multivariate_normal(np.zeros(2), r), r, pose0, np.zeros((3, 3))
        )
        for _ in range(30):
            pose = np.array([rng.uniform(-1, 2), rng.uniform(-1, 0.5), rng.uniform(-1, 1)])
            z = closest_point_in_robot_frame(true_p0, true_p1, pose)
            z = z + rng.multivariate_normal(np.zeros(2), r)
            innov = ekf.innovation(s, p, anchor, z, r, pose, np.zeros((3, 3)))
            s, p = ekf.update(s, p, innov)
        err = s - wall_from_points(true_p0, true_p1, anchor)
        nees.append(err @ np.linalg.solve(p, err))
        assert np.linalg.norm(err) < 0.02
    # Normalised estimation error squared averages the state dimension when P is honest.
    assert 1.0 < np.mean(nees) < 3.5


def test_the_line_jacobian_matches_numeric_differentiation():
    rng = np.random.default_rng(4)
    for _ in range(50):
        rho, theta = rng.uniform(0.3, 6.0), rng.uniform(-np.pi, np.pi)
        s = rho * np.array([np.cos(theta), np.sin(theta)])
        numeric = numeric_jacobian(
            lambda x: x[0] * np.array([np.cos(x[1]), np.sin(x[1])]), np.array([rho, theta])
        )
        np.testing.assert_allclose(ekf.line_jacobian(s), numeric, atol=1e-6)


def test_a_line_s_spread_is_its_jacobian_s_at_once_for_many():
    rng = np.random.default_rng(5)
    s = rng.uniform(-5.0, 5.0, (20, 2))
    sd = (0.01, 0.02)
    one_by_one = [ekf.line_jacobian(x) @ np.diag(np.square(sd)) @ ekf.line_jacobian(x).T for x in s]
    np.testing.assert_allclose(ekf.line_spread(s, sd), one_by_one, atol=1e-15)
    np.testing.assert_allclose(ekf.line_spread(s[3], sd), one_by_one[3], atol=1e-15)


def test_two_estimates_of_one_line_agree_and_of_two_lines_do_not():
    """The same line estimated from anchors 6 m apart, against one 5 cm or 2 degrees off."""
    anchor_a, anchor_b = np.array([0.0, -1.0]), np.array([6.0, -1.5])
    cov = np.diag([0.003**2, 0.003**2])  # a wall seen a few dozen times

    def state(anchor, offset=0.0, turn=0.0):
        normal = np.array([-np.sin(turn), np.cos(turn)])
        rho = 2.0 + offset - normal @ anchor  # the line n . p = 2 + offset, seen from anchor
        return rho * normal

    floor = (0.01, np.radians(0.5))
    same = ekf.line_agreement(state(anchor_a), cov, anchor_a, state(anchor_b), cov, anchor_b, floor)
    assert same < 1e-9
    for other in (state(anchor_b, offset=0.05), state(anchor_b, turn=np.radians(2.0))):
        chi2 = ekf.line_agreement(state(anchor_a), cov, anchor_a, other, cov, anchor_b, floor)
        assert chi2 > ekf.CHI2_2DOF_999
    loose = np.diag([0.05**2, 0.05**2])
    near = ekf.line_agreement(
        state(anchor_a), loose, anchor_a, state(anchor_b, offset=0.05), loose, anchor_b, floor
    )
    assert near < ekf.CHI2_2DOF_999, "uncertain estimates may be one line"
