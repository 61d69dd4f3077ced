"""The wall map's compiled association, update and see-through, against the numpy they replace."""

from __future__ import annotations

import numpy as np

from wallmap.common import ekf, map_kernels, pose_kernels

Array = np.ndarray


def _walls(rng: np.random.Generator, n: int) -> tuple[Array, Array, Array]:
    s, anchor = rng.uniform(-4, 4, (n, 2)), rng.uniform(-2, 2, (n, 2))
    a = rng.normal(0, 0.05, (n, 2, 2))
    return s, a @ a.transpose(0, 2, 1) + 1e-6 * np.eye(2), anchor


def _numpy_choice(
    s: Array, p: Array, anchor: Array, z: Array, r: Array, pose: Array, pose_cov: Array, gate: float
) -> int:
    """``WallMap.match`` as it was in numpy: the first wall of highest likelihood in the gate."""
    best, score = -1, -np.inf
    for k in range(len(s)):
        innov = ekf.innovation(s[k], p[k], anchor[k], z, r, pose, pose_cov)
        if innov.mahalanobis2 <= gate and innov.log_likelihood > score:
            best, score = k, innov.log_likelihood
    return best


def _compiled_choice(
    s: Array, p: Array, anchor: Array, z: Array, r: Array, pose: Array, pose_cov: Array, gate: float
) -> int:
    """``WallMap.match``'s choice now: one observation's pairs, the judge's ``best_pairs``."""
    n = len(s)
    one = np.zeros(n, dtype=np.int64)
    z, r = np.tile(z, (n, 1)), np.tile(r, (n, 1, 1))
    best = pose_kernels.best_pairs(s, p, anchor, z, r, pose, pose_cov, one, gate)
    return int(best[0]) if len(best) else -1


def test_the_most_likely_wall_is_the_numpy_ekf_s_choice() -> None:
    """Near walls whose scores differ by little, some outside the gate: the same pick always."""
    rng = np.random.default_rng(3)
    picked = set()
    for _ in range(300):
        n = int(rng.integers(1, 6))
        s, p, anchor = _walls(rng, n)
        pose, pose_cov = rng.normal(0, 1, 3), np.diag([1e-3, 2e-3, 1e-4])
        r = np.diag(rng.uniform(1e-4, 5e-3, 2))
        # An observation near one wall's prediction, so that the gate takes some and not others.
        z = ekf.innovation(s[0], p[0], anchor[0], np.zeros(2), r, pose, pose_cov).residual * -1
        z = z + rng.normal(0, 0.05, 2)
        gate = ekf.CHI2_2DOF_999
        want = _numpy_choice(s, p, anchor, z, r, pose, pose_cov, gate)
        assert _compiled_choice(s, p, anchor, z, r, pose, pose_cov, gate) == want
        picked.add(want)
    assert {-1, 0} <= picked  # both outcomes were tried: in the gate and out of it


def test_ties_go_to_the_first_wall() -> None:
    s, p, anchor = np.array([[2.0, 0.0]] * 3), np.array([np.eye(2) * 1e-3] * 3), np.zeros((3, 2))
    z, r = np.array([2.0, 0.0]), np.eye(2) * 1e-3
    pose, pose_cov = np.zeros(3), np.eye(3) * 1e-4
    assert _compiled_choice(s, p, anchor, z, r, pose, pose_cov, 13.8) == 0


def test_the_update_is_the_numpy_ekf_update() -> None:
    rng = np.random.default_rng(11)
    for _ in range(200):
        (s,), (p,), (anchor,) = _walls(rng, 1)
        pose, pose_cov = rng.normal(0, 1, 3), np.diag(rng.uniform(1e-5, 1e-2, 3))
        z, r = rng.uniform(-4, 4, 2), np.diag(rng.uniform(1e-4, 5e-3, 2))
        want_s, want_p = ekf.update(s, p, ekf.innovation(s, p, anchor, z, r, pose, pose_cov))
        got_s, got_p = map_kernels.update(s, p, anchor, z, r, pose, pose_cov)
        np.testing.assert_allclose(got_s, want_s, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(got_p, want_p, rtol=1e-7, atol=1e-15)
        assert np.array_equal(got_p, got_p.T)
        assert np.all(np.linalg.eigvalsh(got_p) > 0)


def _numpy_see_through(
    origin: Array, ends: Array, pose: Array, normals: Array, feet: Array
) -> list[tuple[int, Array]]:
    """``WallMap._see_through`` as it was in numpy: per wall, the points rays crossed it at."""
    c, q = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, -q], [q, c]])
    start = pose[:2] + rot @ origin
    rays = pose[:2] + ends @ rot.T - start
    length = np.linalg.norm(rays, axis=1)
    margin = 0.1 + 3e-3 * length**2
    found = []
    for k, (normal, foot) in enumerate(zip(normals, feet, strict=True)):
        with np.errstate(divide="ignore", invalid="ignore"):
            share = (normal @ (foot - start)) / (rays @ normal)
        distance = share * length
        crossed = (distance > 0.3) & (distance < length - margin)
        if crossed.any():
            found.append((k, start + share[crossed, None] * rays[crossed]))
    return found


def test_the_rays_cross_the_walls_numpy_said() -> None:
    """Rays fanned out at random walls, some through, some short of them, one along one."""
    rng = np.random.default_rng(8)
    crossed = 0
    for _ in range(100):
        origin, pose = rng.normal(0, 0.2, 2), rng.normal(0, 2, 3)
        angles, ranges = rng.uniform(-0.8, 0.8, 64), rng.uniform(0.2, 8.0, 64)
        ends = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])
        turn = rng.uniform(0, 2 * np.pi, 4)
        normals = np.column_stack([np.cos(turn), np.sin(turn)])
        feet = pose[:2] + rng.uniform(-5, 5, (4, 2))
        start, rays, length, limit, box = map_kernels.rays_in_map(origin, ends, pose, 0.1, 3e-3)
        stops = start + rays
        low, high = np.minimum(stops.min(axis=0), start), np.maximum(stops.max(axis=0), start)
        np.testing.assert_allclose(box, [low, high], atol=1e-12)
        which, points = map_kernels.crossings(start, rays, length, limit, normals, feet, 0.3)
        want = _numpy_see_through(origin, ends, pose, normals, feet)
        assert sorted(set(which.tolist())) == [k for k, _ in want]
        for k, at in want:
            np.testing.assert_allclose(points[which == k], at, atol=1e-9)
            crossed += len(at)
    assert crossed > 500  # the rays did cross walls


def test_a_ray_along_a_wall_never_crosses_it() -> None:
    start, rays = np.zeros(2), np.array([[4.0, 0.0]])
    normals, feet = np.array([[0.0, 1.0]]), np.array([[0.0, 0.0]])
    which, _ = map_kernels.crossings(
        start, rays, np.array([4.0]), np.array([3.8]), normals, feet, 0.3
    )
    assert len(which) == 0
