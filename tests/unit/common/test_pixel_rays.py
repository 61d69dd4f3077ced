"""A camera's pixel rays, fitted from its own points, and the rows that never see the band.

The rows dropped must change nothing: the band's stack of the rows kept is the stack of every
searched row, to the bit, whatever the camera's intrinsics, frame convention and tilt. And they
must be dropped where they can be, or the player reads half its rows for nothing.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wallmap.common.pixel_rays import PixelRays, fit_pixel_rays
from wallmap.common.pose3d import rpy_matrix
from wallmap.common.scan_row import RowSelection, band_stack, rows_to_search

W, H = 160, 120
OPTICAL_TO_BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _camera(rng: np.random.Generator) -> np.ndarray:
    """K^-1 of a random pinhole camera of W x H pixels (45-100 degrees across)."""
    f = rng.uniform(0.5, 1.2) * W
    cx, cy = (W - 1) / 2 + rng.uniform(-8, 8), (H - 1) / 2 + rng.uniform(-8, 8)
    return np.linalg.inv(np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]]))


def _frame(
    rng: np.random.Generator, k_inv: np.ndarray, body: bool, missing: float = 0.2
) -> np.ndarray:
    """One frame's (H, W, 3) points at random ranges, NaN where there is no return."""
    c, r = np.meshgrid(np.arange(W), np.arange(H))
    rays = np.stack([c, r, np.ones_like(c)], axis=-1) @ k_inv.T  # optical frame, z ahead
    points = rays * rng.uniform(0.3, 10.0, (H, W, 1))
    if body:  # the cloud given in the camera's body frame (x ahead, z up)
        points = points @ OPTICAL_TO_BODY.T
    points[rng.random((H, W)) < missing] = np.nan
    return points.astype(np.float32)


def _mount(height: float, pitch: float, roll: float, body: bool) -> np.ndarray:
    """T_base_sensor of a camera ``height`` up, pitched (nose down > 0) and rolled."""
    mount = np.eye(4)
    turn = rpy_matrix(roll, pitch, 0.0)
    mount[:3, :3] = turn if body else turn @ OPTICAL_TO_BODY
    mount[2, 3] = height
    return mount


@pytest.mark.parametrize("body", [False, True])
def test_the_rays_of_a_pinhole_are_found_from_its_points(body: bool) -> None:
    rng = np.random.default_rng(1)
    k_inv = _camera(rng)
    rays = fit_pixel_rays([(_frame(rng, k_inv, body), slice(None)) for _ in range(3)])
    assert rays is not None
    assert rays.width == W
    expected = OPTICAL_TO_BODY @ k_inv if body else k_inv
    scale = np.sum(rays.matrix * expected) / np.sum(expected * expected)
    assert scale > 0, "the rays point to the points, not away from them"
    np.testing.assert_allclose(rays.matrix / scale, expected, atol=1e-7)


def test_every_kth_row_gives_the_same_rays_as_the_whole_frame() -> None:
    """A live survey reads every k-th row: the fit places them where they are in the image."""
    rng = np.random.default_rng(2)
    k_inv = _camera(rng)
    frames = [_frame(rng, k_inv, False) for _ in range(3)]
    whole = fit_pixel_rays([(f, slice(None)) for f in frames])
    strided = fit_pixel_rays([(f[3::7], slice(3, None, 7)) for f in frames])
    assert whole is not None
    assert strided is not None
    np.testing.assert_allclose(
        strided.matrix / np.linalg.norm(strided.matrix),
        whole.matrix / np.linalg.norm(whole.matrix),
        atol=1e-6,
    )


def test_what_is_no_pinhole_is_refused() -> None:
    rng = np.random.default_rng(3)
    k_inv = _camera(rng)
    frame = _frame(rng, k_inv, False, missing=0.0)
    # A lens left distorted: the points bend away from the pinhole's rays towards the edges.
    x, y = frame[..., 0] / frame[..., 2], frame[..., 1] / frame[..., 2]
    bend = 1 + 0.08 * (x * x + y * y)
    distorted = np.stack([x * bend, y * bend, np.ones_like(x)], -1) * frame[..., 2:]
    assert fit_pixel_rays([(distorted, slice(None))]) is None
    # A spinning lidar's organized cloud: rows are beams at fixed elevations, columns azimuths.
    azimuth, elevation = np.meshgrid(
        np.linspace(-math.pi, math.pi, W), np.radians(np.linspace(15, -15, H))
    )
    lidar = np.stack(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ],
        -1,
    ) * rng.uniform(1, 20, (H, W, 1))
    assert fit_pixel_rays([(lidar, slice(None))]) is None
    # Too little to tell: one row, a handful of points, frames of two widths.
    assert fit_pixel_rays([(frame[:1], slice(None))]) is None
    sparse = np.full_like(frame, np.nan)
    sparse[::30, ::30] = frame[::30, ::30]
    assert fit_pixel_rays([(sparse, slice(None))]) is None
    assert fit_pixel_rays([(frame, slice(None)), (frame[:, :100], slice(None))]) is None
    assert fit_pixel_rays([(frame, slice(None))]) is not None


def test_dropping_the_rows_that_never_see_the_band_changes_no_point_of_its_stack() -> None:
    """Random cameras, frames, tilts and bands: the same stack from fewer rows."""
    rng = np.random.default_rng(4)
    searched = rows_to_search(RowSelection(), H)
    kept_shares = []
    for case in range(60):
        body = bool(case % 2)
        k_inv = _camera(rng)
        rays = fit_pixel_rays([(_frame(rng, k_inv, body), slice(None))])
        assert rays is not None
        low = rng.uniform(0.5, 1.5)
        band = (low, low + rng.uniform(0.3, 1.0))
        for _ in range(5):
            height = rng.choice([rng.uniform(0.1, band[0]), rng.uniform(band[1], 3.0)])
            pitch, roll = np.radians(rng.uniform(-35, 35)), np.radians(rng.uniform(-20, 20))
            mount = _mount(height, pitch, roll, body)
            frame = _frame(rng, k_inv, body, missing=0.1)
            kept = rays.reaching(searched, H, mount, band)
            np.testing.assert_array_equal(
                band_stack(frame[kept], mount, band), band_stack(frame[searched], mount, band)
            )
            kept_shares.append(len(range(H)[kept]) / len(range(H)[searched]))
    assert np.median(kept_shares) < 0.8, "rows are dropped where they can be"


def test_a_level_camera_below_the_band_reads_its_upper_half() -> None:
    rng = np.random.default_rng(5)
    k_inv = np.linalg.inv(np.array([[W, 0, (W - 1) / 2], [0, W, (H - 1) / 2], [0, 0, 1.0]]))
    rays = fit_pixel_rays([(_frame(rng, k_inv, False), slice(None))])
    assert rays is not None
    horizon = (H - 1) / 2  # rows below it look down; one degree below is W/57 rows on
    kept = rays.reaching(slice(0, H, 1), H, _mount(0.6, 0.0, 0.0, False), (1.3, 2.1))
    assert kept.start == 0
    assert horizon + 1 < kept.stop - 1 <= horizon + W * math.tan(math.radians(1.0)) + 1
    # In the band, or looking at the ceiling from below it, every row can see it.
    for mount in (_mount(1.5, 0.0, 0.0, False), _mount(0.6, -math.radians(60), 0.0, False)):
        assert rays.reaching(slice(0, H, 1), H, mount, (1.3, 2.1)) == slice(0, H, 1)
    # Above the band, the rows looking up are the ones dropped.
    above = rays.reaching(slice(0, H, 1), H, _mount(2.6, 0.0, 0.0, False), (1.3, 2.1))
    assert above.stop == H
    assert horizon - W * math.tan(math.radians(1.0)) - 1 <= above.start < horizon


def test_at_least_two_rows_stay_and_a_gap_in_the_middle_keeps_them_all() -> None:
    below = np.eye(4)  # a sensor under the band, its third axis up
    below[2, 3] = 0.5
    below[:3, :3] = np.diag([1.0, -1.0, -1.0])  # ...turned over: rays (c, r, 1) all fall
    falling = PixelRays(np.diag([1e-3, 1e-3, 1.0]), W)
    assert falling.reaching(slice(0, H, 4), H, below, (1.3, 2.1)) == slice(0, 5, 4), (
        "two rows, though neither sees the band"
    )
    # Rays steep near the middle row and ever flatter away from it: the ends may see the band.
    bowl = PixelRays(np.array([[1e-3, 0, 0], [0, 2.0, -120.0], [0, 0, 1.0]]), W)
    rows = slice(0, H, 1)
    assert bowl.reaching(rows, H, below, (1.3, 2.1)) == rows
