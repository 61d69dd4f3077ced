"""6-DoF poses: transforms, the split into a planar pose and a tilt, and the contract's fields."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallmap.common.codec import MessageError, encode
from wallmap.common.messages import Pose, pack, unpack_pose
from wallmap.common.pose3d import (
    FORWARD_X,
    FORWARD_Z,
    forward_axis,
    planar_matrix,
    pose_matrix,
    quaternion_from_matrix,
    rotation_matrix,
    rpy_from_matrix,
    rpy_matrix,
    split_planar,
)


def random_poses(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield pose_matrix(*rng.uniform(-3, 3, 3), *rng.uniform(-0.6, 0.6, 2), rng.uniform(-3, 3))


def test_quaternions_and_roll_pitch_yaw_round_trip() -> None:
    rng = np.random.default_rng(1)
    for _ in range(500):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        rotation = rotation_matrix(tuple(q))
        np.testing.assert_allclose(
            rotation_matrix(quaternion_from_matrix(rotation)), rotation, atol=1e-12
        )
        np.testing.assert_allclose(rpy_matrix(*rpy_from_matrix(rotation)), rotation, atol=1e-12)


@pytest.mark.parametrize("forward", [FORWARD_X, FORWARD_Z])
def test_a_pose_splits_exactly_into_a_floor_pose_and_a_tilt(forward: int) -> None:
    for pose in random_poses(200):
        x, y, yaw, tilt = split_planar(pose, forward)
        np.testing.assert_allclose(planar_matrix(x, y, yaw) @ tilt, pose, atol=1e-12)
        np.testing.assert_allclose(tilt[:2, 3], 0.0, atol=1e-12)  # no offset on the floor
        assert tilt[2, 3] == pytest.approx(pose[2, 3])  # the height stays with the frame
        # The forward axis has no heading left in the tilt: it points along +x of the floor
        # (unless it points nearly straight up or down, and the sideways axis stands in).
        ahead = tilt[:3, forward]
        if math.hypot(ahead[0], ahead[1]) > 0.2:
            assert abs(ahead[1]) < 1e-9
            assert ahead[0] > 0


def test_a_planar_pose_has_no_tilt() -> None:
    x, y, yaw, tilt = split_planar(planar_matrix(1.0, -2.0, 0.7))
    assert (x, y, yaw) == pytest.approx((1.0, -2.0, 0.7))
    np.testing.assert_allclose(tilt, np.eye(4), atol=1e-12)


def test_an_optical_frame_heads_where_its_camera_looks() -> None:
    optical_in_link = rotation_matrix((-0.5, 0.5, -0.5, 0.5))  # REP-103: z forward, y down
    pose = np.eye(4)
    pose[:3, :3] = rpy_matrix(0.0, 0.4, 1.1) @ optical_in_link  # pitched down, heading 1.1
    assert forward_axis("camera_depth_optical_frame") == FORWARD_Z
    assert forward_axis("camera_link") == FORWARD_X
    assert split_planar(pose, FORWARD_Z)[2] == pytest.approx(1.1)


def test_a_camera_looking_straight_down_keeps_a_heading() -> None:
    pose = pose_matrix(0, 0, 1.5, 0.0, math.pi / 2, 0.8)  # x axis points at the floor
    x, y, yaw, tilt = split_planar(pose)
    np.testing.assert_allclose(planar_matrix(x, y, yaw) @ tilt, pose, atol=1e-12)
    assert yaw == pytest.approx(0.8)


def test_the_contract_pose_carries_6dof_fields_or_a_quaternion() -> None:
    pose = Pose(1.0, 2.0, 3.0, 0.5, None, "map", "camera_link", z=1.4, roll=0.1, pitch=-0.3)
    back = unpack_pose(pack(pose))
    assert (back.z, back.roll, back.pitch, back.yaw) == pytest.approx((1.4, 0.1, -0.3, 0.5))
    np.testing.assert_allclose(back.matrix, pose.matrix)
    planar = Pose(1.0, 2.0, 3.0, 0.5)
    assert "z" not in planar.to_map()  # planar poses stay as the contract always had them
    q = quaternion_from_matrix(rpy_matrix(0.2, -0.1, 2.0))
    message = {"v": 1, "stamp": 1.0, "x": 0.0, "y": 0.0, "q": list(q), "z": 0.5}
    got = unpack_pose(encode(message))
    assert (got.roll, got.pitch, got.yaw, got.z) == pytest.approx((0.2, -0.1, 2.0, 0.5))
    with pytest.raises(MessageError, match="unit quaternion"):
        unpack_pose(encode({**message, "q": [0.0, 0.0, 0.0, 3.0]}))
    with pytest.raises(MessageError, match="field 'roll' must be a finite number, got nan"):
        unpack_pose(encode({"v": 1, "stamp": 1.0, "x": 0, "y": 0, "yaw": 0, "roll": math.nan}))
