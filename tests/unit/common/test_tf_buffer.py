"""TfBuffer: interpolation, chained lookups in both directions, and its error messages."""

import math
import time

import numpy as np
import pytest

from wallmap.common.tf_buffer import TfBuffer, TfError, transform_matrix


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def yaw_of(matrix: np.ndarray) -> float:
    return math.atan2(matrix[1, 0], matrix[0, 0])


def robot_tree() -> TfBuffer:
    """map -> odom -> base_link -> camera_link -> camera_optical, plus base_link -> laser."""
    tf = TfBuffer()
    for stamp, x in ((10.0, 0.0), (12.0, 1.0)):
        tf.add_transform("map", "odom", stamp, (x, 0.5, 0.0), yaw_quaternion(0.1), static=False)
    for stamp, x, yaw in ((10.0, 0.0, 0.0), (11.0, 1.0, 0.2), (12.0, 3.0, 0.4)):
        tf.add_transform("/odom", "/base_link", stamp, (x, 0, 0), yaw_quaternion(yaw), static=False)
    tf.add_transform(
        "base_link", "camera_link", 0.0, (0.2, 0.0, 0.5), yaw_quaternion(0), static=True
    )
    optical = (-0.5, 0.5, -0.5, 0.5)  # z forward, x right, y down
    tf.add_transform("camera_link", "camera_optical", 0.0, (0, 0, 0), optical, static=True)
    tf.add_transform(
        "base_link", "laser", 0.0, (0.1, 0.0, 0.3), yaw_quaternion(math.pi), static=True
    )
    return tf


def test_halfway_interpolates_translation_and_slerps_yaw() -> None:
    tf = TfBuffer()
    tf.add_transform("odom", "base_link", 0.0, (0, 0, 0), yaw_quaternion(0), static=False)
    tf.add_transform("odom", "base_link", 2.0, (2, 4, 1), yaw_quaternion(math.pi / 2), static=False)
    halfway = tf.lookup("odom", "base_link", 1.0)
    np.testing.assert_allclose(halfway[:3, 3], [1, 2, 0.5])
    assert yaw_of(halfway) == pytest.approx(math.pi / 4)
    np.testing.assert_allclose(halfway[:3, :3] @ halfway[:3, :3].T, np.eye(3), atol=1e-12)
    quarter = tf.lookup("odom", "base_link", 0.5)
    assert yaw_of(quarter) == pytest.approx(math.pi / 8)
    exact = tf.lookup("odom", "base_link", 2.0)
    np.testing.assert_allclose(exact, transform_matrix((2, 4, 1), yaw_quaternion(math.pi / 2)))


def test_slerp_takes_the_short_way_across_pi() -> None:
    tf = TfBuffer()
    tf.add_transform("a", "b", 0.0, (0, 0, 0), yaw_quaternion(math.radians(170)), static=False)
    tf.add_transform("a", "b", 1.0, (0, 0, 0), yaw_quaternion(math.radians(-170)), static=False)
    assert abs(yaw_of(tf.lookup("a", "b", 0.5))) == pytest.approx(math.pi)


def test_chained_lookup_through_four_edges_both_directions() -> None:
    tf = robot_tree()
    stamp = 11.5
    map_odom = transform_matrix((0.75, 0.5, 0), yaw_quaternion(0.1))
    odom_base = transform_matrix((2.0, 0, 0), yaw_quaternion(0.3))
    base_camera = transform_matrix((0.2, 0, 0.5), yaw_quaternion(0))
    camera_optical = transform_matrix((0, 0, 0), (-0.5, 0.5, -0.5, 0.5))
    expected = map_odom @ odom_base @ base_camera @ camera_optical

    forward = tf.lookup("map", "camera_optical", stamp)
    np.testing.assert_allclose(forward, expected, atol=1e-12)
    backward = tf.lookup("/camera_optical", "/map", stamp)
    np.testing.assert_allclose(backward, np.linalg.inv(expected), atol=1e-12)

    # The optical frame's z axis (forward) is the base's x axis.
    optical_in_base = tf.lookup("base_link", "camera_optical", 123.0)
    np.testing.assert_allclose(optical_in_base[:3, :3] @ [0, 0, 1], [1, 0, 0], atol=1e-12)


def test_lookup_between_siblings_goes_up_then_down() -> None:
    tf = robot_tree()
    laser_in_camera = tf.lookup("camera_link", "laser", 0.0)
    # Laser origin (0.1, 0, 0.3) in base is (-0.1, 0, -0.2) in camera_link; it faces backwards.
    np.testing.assert_allclose(laser_in_camera[:3, 3], [-0.1, 0, -0.2], atol=1e-12)
    np.testing.assert_allclose(laser_in_camera[:3, :3] @ [1, 0, 0], [-1, 0, 0], atol=1e-12)
    assert tf.has_path("laser", "camera_optical")
    np.testing.assert_array_equal(tf.lookup("laser", "/laser", 0.0), np.eye(4))


def test_extrapolation_errors_name_edge_stamp_and_range() -> None:
    tf = robot_tree()
    with pytest.raises(TfError) as err:
        tf.lookup("map", "base_link", 12.5)
    text = str(err.value)
    assert "extrapolation into the future" in text
    assert "edge odom -> base_link" in text or "edge map -> odom" in text
    assert "12.500000" in text
    assert "[10.000000, 12.000000]" in text
    with pytest.raises(TfError, match=r"into the past: edge map -> odom .*\[10\.0+, 12\.0+\]"):
        tf.lookup("camera_link", "map", 9.0)
    assert isinstance(err.value, LookupError)


def test_tolerance_uses_the_end_sample() -> None:
    tf = robot_tree()
    with pytest.raises(TfError, match=r"tolerance 0\.01 s"):
        tf.lookup("odom", "base_link", 12.05, tolerance=0.01)
    last = tf.lookup("odom", "base_link", 12.05, tolerance=0.1)
    np.testing.assert_allclose(last[:3, 3], [3.0, 0, 0])
    lenient = TfBuffer(tolerance=0.5)
    lenient.add_transform("odom", "base_link", 1.0, (1, 2, 3), yaw_quaternion(0), static=False)
    np.testing.assert_allclose(lenient.lookup("odom", "base_link", 0.6)[:3, 3], [1, 2, 3])
    with pytest.raises(TfError, match="past"):
        lenient.lookup("odom", "base_link", 0.4)
    np.testing.assert_allclose(
        lenient.lookup("odom", "base_link", -1e9, tolerance=math.inf)[0, 3], 1
    )


def test_no_path_lists_known_frames() -> None:
    tf = robot_tree()
    tf.add_transform("world", "marker", 0.0, (0, 0, 0), yaw_quaternion(0), static=True)
    with pytest.raises(TfError) as err:
        tf.lookup("map", "marker", 11.0)
    text = str(err.value)
    assert "no tf path from 'marker' to 'map'" in text
    assert "'marker' connects to [marker, world]" in text
    assert "known frames: base_link, camera_link, camera_optical, laser, map, marker" in text
    with pytest.raises(TfError, match="'ghost' is not in tf"):
        tf.lookup("ghost", "map", 11.0)
    assert not tf.has_path("map", "world")


def test_samples_added_out_of_order_and_repeated_stamps() -> None:
    tf = TfBuffer()
    for stamp, x in ((3.0, 30.0), (1.0, 10.0), (2.0, 99.0), (2.0, 20.0)):
        tf.add_transform("a", "b", stamp, (x, 0, 0), yaw_quaternion(0), static=False)
    assert tf.lookup("a", "b", 2.0)[0, 3] == 20.0
    assert tf.lookup("a", "b", 1.5)[0, 3] == pytest.approx(15.0)
    tf.add_transform("a", "b", 4.0, (40, 0, 0), yaw_quaternion(0), static=False)
    assert tf.lookup("a", "b", 3.5)[0, 3] == pytest.approx(35.0)


def test_static_edges_ignore_time_and_keep_the_newest() -> None:
    tf = TfBuffer()
    tf.add_transform("base", "cam", 5.0, (1, 0, 0), yaw_quaternion(0), static=True)
    tf.add_transform("base", "cam", 6.0, (2, 0, 0), yaw_quaternion(0), static=True)
    assert tf.lookup("base", "cam", -100.0)[0, 3] == 2.0
    assert tf.lookup("cam", "base", 1e9)[0, 3] == -2.0


def test_invalid_transforms_are_rejected() -> None:
    tf = TfBuffer()
    with pytest.raises(TfError, match="zero quaternion"):
        tf.add_transform("a", "b", 1.0, (0, 0, 0), (0, 0, 0, 0), static=False)
    with pytest.raises(TfError, match="frames must differ"):
        tf.add_transform("/a", "a", 1.0, (0, 0, 0), (0, 0, 0, 1), static=True)
    assert not tf


def test_many_lookups_are_fast() -> None:
    tf = robot_tree()
    for i in range(10_000):
        tf.add_transform(
            "odom", "base_link", 12.0 + i * 0.01, (i, 0, 0), (0, 0, 0, 1), static=False
        )
    stamps = np.random.default_rng(0).uniform(10.0, 12.0, 20_000)
    start = time.perf_counter()
    for stamp in stamps:
        tf.lookup("map", "camera_optical", stamp)
    assert time.perf_counter() - start < 10.0  # ~25 us each; a linear scan would take minutes


def test_lookups_at_many_stamps_are_the_lookups_one_by_one() -> None:
    """Samples, between them, both ends within and beyond the tolerance, both directions."""
    tf = robot_tree()
    stamps = np.array([9.0, 9.96, 10.0, 10.3, 11.0, 11.5, 11.999, 12.0, 12.04, 12.5])
    for target, source in (("map", "base_link"), ("camera_optical", "map"), ("laser", "odom")):
        many, found = tf.lookup_many(target, source, stamps, tolerance=0.05)
        for stamp, matrix, ok in zip(stamps, many, found, strict=True):
            try:
                one = tf.lookup(target, source, float(stamp), tolerance=0.05)
            except TfError:
                assert not ok, stamp
                continue
            assert ok, stamp
            np.testing.assert_allclose(matrix, one, rtol=0, atol=1e-14)
    assert tf.lookup_many("map", "map", stamps)[1].all()
    with pytest.raises(TfError, match="nowhere"):
        tf.lookup_many("map", "nowhere", stamps)
