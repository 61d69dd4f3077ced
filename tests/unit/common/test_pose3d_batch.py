"""The batched rigid transforms against their scalar twins in ``pose3d``, on random poses."""

import math

import numpy as np
import pytest

from wallmap.common import pose3d, pose3d_batch


def _quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_rotations_and_transforms_are_the_scalar_ones() -> None:
    rng = np.random.default_rng(1)
    q, t = _quaternions(rng, 50), rng.normal(size=(50, 3))
    many = pose3d_batch.transform_matrices(t, q)
    for i in range(50):
        one = pose3d.transform_matrix(tuple(t[i]), tuple(q[i]))
        np.testing.assert_array_equal(many[i], one)


def test_slerp_is_the_scalar_one_on_both_arcs_and_near_parallel() -> None:
    rng = np.random.default_rng(2)
    q0 = _quaternions(rng, 60)
    q1 = _quaternions(rng, 60)
    q1[:20] = -q1[:20]  # long way round: the shorter arc is taken
    q1[40:] = q0[40:] + 1e-4 * rng.normal(size=(20, 4))  # nearly parallel: the normalised lerp
    q1[40:] /= np.linalg.norm(q1[40:], axis=1, keepdims=True)
    weights = rng.uniform(0.0, 1.0, 60)
    many = pose3d_batch.slerp_many(q0, q1, weights)
    for i in range(60):
        one = pose3d.slerp(tuple(q0[i]), tuple(q1[i]), float(weights[i]))
        np.testing.assert_allclose(many[i], one, rtol=0, atol=1e-15)


def test_inverses_undo_the_transforms() -> None:
    rng = np.random.default_rng(3)
    m = pose3d_batch.transform_matrices(rng.normal(size=(30, 3)), _quaternions(rng, 30))
    inverse = pose3d_batch.invert_many(m)
    for i in range(30):
        np.testing.assert_allclose(inverse[i], pose3d.invert(m[i]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(inverse @ m, np.broadcast_to(np.eye(4), m.shape), atol=1e-12)


@pytest.mark.parametrize("forward", [pose3d.FORWARD_X, pose3d.FORWARD_Z])
def test_headings_are_the_scalar_ones_also_looking_up_or_down(forward: int) -> None:
    rng = np.random.default_rng(4)
    rotations = pose3d_batch.rotation_matrices(_quaternions(rng, 200))
    # Some look straight up or down: the sideways axis then gives the heading.
    pitch_up = pose3d.rpy_matrix(0.0, -math.pi / 2 + 0.01, 0.7)
    optical_down = pose3d.rpy_matrix(math.pi, 0.0, -0.4)
    rotations[:2] = pitch_up, optical_down
    many = pose3d_batch.headings(rotations, forward)
    for i in range(200):
        assert many[i] == pose3d.heading(rotations[i], forward)
