"""The codec and message validation: round trips, zero copies, and every refusal has a reason."""

import contextlib
import math
from dataclasses import replace

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wallmap.common import codec
from wallmap.common.codec import MessageError
from wallmap.common.fields import array, refusal
from wallmap.common.line_fit import fit_line
from wallmap.common.map_records import WallRecord
from wallmap.common.messages import (
    Frame,
    Observations,
    Pose,
    WallObservation,
    _wall_covariance,
    pack,
    unpack_frame,
    unpack_observations,
    unpack_pose,
)


def make_frame(points=None):
    if points is None:
        points = np.arange(2 * 4 * 3, dtype=np.float32).reshape(2, 4, 3)
    return Frame("run1", 7, 12.5, "camera", points, np.eye(4))


def test_frame_round_trip_is_exact_and_does_not_copy_the_points():
    frame = make_frame()
    back = unpack_frame(pack(frame))
    np.testing.assert_array_equal(back.points, frame.points)
    assert not back.points.flags.owndata  # a view over the received bytes
    assert (back.run, back.seq, back.stamp, back.frame_id) == ("run1", 7, 12.5, "camera")


def test_big_endian_and_strided_arrays_are_sent_correctly():
    big = np.arange(24, dtype=">f4").reshape(2, 4, 3)
    back = unpack_frame(pack(make_frame(big.astype(np.float32))))
    np.testing.assert_array_equal(back.points, big)
    strided = np.arange(48, dtype=np.float32).reshape(2, 8, 3)[:, ::2]
    np.testing.assert_array_equal(unpack_frame(pack(make_frame(strided))).points, strided)


def test_pose_and_observations_round_trip():
    pose = Pose(3.0, 1.0, -2.0, 0.5, np.diag([0.1, 0.2, 0.3]))
    assert unpack_pose(pack(pose)).to_map() == pose.to_map()
    wall = WallObservation(
        np.array([1.0, 2.0]), np.eye(2) * 1e-4, np.zeros(2), np.ones(2), 30, 0.01
    )
    obs = Observations("r", 1, 2.0, "base_link", [wall])
    assert unpack_observations(pack(obs)).to_map() == obs.to_map()


def test_walls_beyond_any_building_are_refused_without_overflowing() -> None:
    wall = WallObservation(np.array([1e200, 1e200]), np.eye(2), np.zeros(2), np.ones(2), 30, 0.01)
    far_end = replace(wall, closest=np.array([1.0, 2.0]), p1=np.array([0.0, -2e6]))
    record = WallRecord(
        0,
        1.0,
        2.0,
        ((1e-4, 0.0), (0.0, 1e-4)),
        (0.0, 0.0),
        (1e300, 0.0),
        (((0.0, 0.0), (1e300, 0.0)),),
        10,
    )
    with np.errstate(all="raise"):
        for bad in (wall, far_end):
            obs = Observations("r", 1, 2.0, "base_link", [bad])
            with pytest.raises(MessageError, match="beyond 1e\\+06 m"):
                unpack_observations(pack(obs))
        with pytest.raises(MessageError, match="a wall lies beyond"):
            WallRecord.from_map(record.to_map())


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"\xc1garbage", "not a msgpack payload"),
        (msgpack.packb([1, 2]), "not a map"),
        (msgpack.packb({"stamp": 1.0}), "schema version None"),
        (msgpack.packb({"v": 2, "stamp": 1.0}), "schema version 2"),
        (codec.encode({"stamp": 1.0, "x": 0.0, "y": 0.0}), "field 'yaw' is missing"),
        (
            codec.encode({"stamp": 1.0, "x": math.nan, "y": 0.0, "yaw": 0.0}),
            "field 'x' must be a finite number, got nan",
        ),
        (
            codec.encode({"stamp": 1.0, "x": math.inf, "y": 0.0, "yaw": 0.0}),
            "field 'x' must be a finite number, got inf",
        ),
        (
            codec.encode({"stamp": "now", "x": 0.0, "y": 0.0, "yaw": 0.0}),
            "field 'stamp' must be a finite number, got 'now'",
        ),
        (
            codec.encode({"stamp": 1.0, "x": 0.0, "y": 0.0, "yaw": 0.0, "cov": [[1, 0], [0, 1]]}),
            "shape",
        ),
        (
            codec.encode(
                {"stamp": 1.0, "x": 0.0, "y": 0.0, "yaw": 0.0, "cov": (-np.eye(3)).tolist()}
            ),
            "positive semi-definite",
        ),
    ],
)
def test_bad_poses_are_refused_with_their_reason(payload, reason):
    with pytest.raises(MessageError, match=reason):
        unpack_pose(payload)


@pytest.mark.parametrize(
    ("cov", "reason"),
    [
        ([[1e-4, 2e-6], [1e-6, 1e-4]], "must be symmetric"),
        ([[1e-4, 2e-4], [2e-4, 1e-4]], "positive semi-definite"),
        ([[1e-4, 1e-4], [1e-4, 1e-4]], "must be non-singular"),
        ([[0.0, 0.0], [0.0, 0.0]], "must be non-singular"),
        ([[1e-4, 1e-6], [1e-6 * (1 + 1e-7), 2e-4]], None),  # symmetric to rounding
    ],
)
def test_a_wall_s_covariance_is_a_covariance(cov: list[list[float]], reason: str | None) -> None:
    m = WallObservation(np.array([1.0, 2.0]), np.eye(2), np.zeros(2), np.ones(2), 30, 0.01)
    m = {**m.to_map(), "cov": cov}
    if reason is None:
        np.testing.assert_array_equal(WallObservation.from_map(m).cov, cov)
    else:
        with pytest.raises(MessageError, match=reason):
            WallObservation.from_map(m)


def _numpy_wall_covariance(value: object) -> np.ndarray:
    """The checks a wall's covariance had before its plain-float ones: numpy's parse and tests,
    then ``WallObservation.from_map``'s own test of the determinant."""
    cov = array(value, (2, 2), "cov")
    size = np.abs(cov)
    if not (np.abs(cov - cov.T) <= 1e-12 + 1e-9 * size.max() + 1e-5 * size).all():
        raise refusal("cov", "symmetric", value)
    (a, _), (c, d) = cov.tolist()
    if 0.5 * (a + d) - math.hypot(0.5 * (a - d), c) < -1e-12:
        raise refusal("cov", "positive semi-definite", value)
    (a, b), (c, d) = cov.tolist()
    if a * d - b * c <= 0.0:
        raise refusal("cov", "non-singular", value)
    return cov


_ENTRY = st.one_of(
    st.floats(-1e-3, 1e-3),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-3, 3),
    st.booleans(),
    st.just("1e-4"),  # numpy's parse reads strings of numbers: still taken, as before
    st.just(np.float32(1e-4)),
)


@st.composite
def _wall_covariances(draw: st.DrawFn) -> object:
    """Near-symmetric matrices at the tolerance's edge, and every kind of entry a sender sends."""
    a, b, d = (draw(st.floats(-1e-3, 1e-3)) for _ in range(3))
    c = b * (1 + draw(st.sampled_from([0.0, 1e-7, 1e-5, 2e-5, -1e-5, 1e-3])))
    rows = [[a, b], [c, d]]
    for i, j in draw(st.lists(st.tuples(st.integers(0, 1), st.integers(0, 1)), max_size=2)):
        rows[i][j] = draw(_ENTRY)
    shape = draw(st.sampled_from(["lists", "tuples", "array", "ragged"]))
    if shape == "tuples":
        return tuple(tuple(row) for row in rows)
    if shape == "array":
        with contextlib.suppress(ValueError, TypeError):
            return np.array(rows, dtype=np.float64)
    if shape == "ragged":
        return [rows[0], rows[1][:1]]
    return rows


@settings(max_examples=600, deadline=None)
@given(_wall_covariances())
def test_a_wall_s_covariance_takes_and_refuses_what_numpy_s_check_did(value: object) -> None:
    """The plain-float check of a wall's covariance, against the numpy one it replaced: the same
    matrices taken, with the same values, and the same refused, for the same reason."""
    try:
        expected: np.ndarray | str = _numpy_wall_covariance(value)
    except MessageError as err:
        expected = str(err)
    try:
        got: np.ndarray | str = _wall_covariance(value, "cov")
    except MessageError as err:
        got = str(err)
    if isinstance(expected, str):
        assert got == expected
    else:
        assert isinstance(got, np.ndarray)
        assert got.dtype == expected.dtype
        np.testing.assert_array_equal(got, expected)


def test_bad_frames_are_refused_with_their_reason():
    good = make_frame().to_map()
    cases = {
        "float32 array": {**good, "points": np.zeros((2, 2, 3), np.float64)},
        "shape": {**good, "points": np.zeros((2, 2, 2), np.float32)},
        "base_from_sensor": {**good, "base_from_sensor": np.eye(3)},
        "'seq' must be a non-negative integer, got 1.5": {**good, "seq": 1.5},
        "'seq' must be a non-negative integer, got -1": {**good, "seq": -1},
    }
    for reason, m in cases.items():
        with pytest.raises(MessageError, match=reason):
            unpack_frame(codec.encode(m))
    lying = codec.encode(good).replace(b"<f4", b"<f8")  # dtype that does not fit the bytes
    with pytest.raises(MessageError, match="does not match"):
        unpack_frame(lying)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=256))
def test_random_bytes_never_crash_a_decoder(data):
    for unpack in (unpack_pose, unpack_frame, unpack_observations):
        with contextlib.suppress(MessageError):
            unpack(data)


json_like = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=5)
    | st.binary(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=5)
    ),
    max_leaves=20,
)


@settings(max_examples=300, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(
            ["stamp", "x", "y", "yaw", "cov", "points", "walls", "run", "seq", "__nd__"]
        ),
        json_like,
    )
)
def test_wrong_types_never_crash_a_decoder(fields):
    data = msgpack.packb({"v": 1, **fields}, use_bin_type=True)
    for unpack in (unpack_pose, unpack_frame, unpack_observations):
        with contextlib.suppress(MessageError):
            unpack(data)


def test_a_fleet_walls_sources_go_and_come_back_and_bad_ones_are_refused() -> None:
    wall = WallRecord.from_segment(4, (1.0, 2.0), (4.0, 2.0), n_obs=3)
    assert (wall.u, wall.v) == pytest.approx((0.0, 2.0))
    assert "sources" not in wall.to_map(), "a robot's own wall has none"
    fused = replace(wall, sources=(("robot_a", 4), ("robot_b", 9)))
    body = fused.to_map()
    assert body["sources"] == [{"robot": "robot_a", "id": 4}, {"robot": "robot_b", "id": 9}]
    assert WallRecord.from_map(msgpack.unpackb(msgpack.packb(body))) == fused
    for bad in ([{"robot": "", "id": 1}], [{"robot": "a", "id": "x"}], ["a"], {"robot": "a"}):
        with pytest.raises(MessageError):
            WallRecord.from_map({**body, "sources": bad})


def test_a_line_fit_becomes_the_wall_the_detector_reports() -> None:
    """``from_fit`` carries the fit's line, covariance, extent and support, nothing else."""
    xs = np.linspace(-1.0, 1.0, 40)
    fit = fit_line(np.stack([xs, 2.0 + 0.01 * np.sin(7 * xs)], axis=1))
    wall = WallObservation.from_fit(fit)
    by_hand = WallObservation(fit.closest, fit.cov, fit.p0, fit.p1, fit.n_points, fit.rms)
    assert pack(Observations("r", 1, 2.0, "base_link", [wall])) == pack(
        Observations("r", 1, 2.0, "base_link", [by_hand])
    )
    back = unpack_observations(pack(Observations("r", 1, 2.0, "base_link", [wall]))).walls[0]
    np.testing.assert_array_equal(back.closest, fit.closest)
    assert (back.n_points, back.rms) == (fit.n_points, fit.rms)
