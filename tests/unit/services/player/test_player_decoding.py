"""Decoding of PointCloud2, depth images and laser scans into organized xyz grids."""

import math

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from wallmap.services.player.depth import _rays, depth_image_to_xyz
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.laserscan import laserscan_to_xyz
from wallmap.services.player.pointcloud import invalid_to_nan, pointcloud2_xyz

ROS2 = get_typestore(Stores.ROS2_HUMBLE).types
ROS1 = get_typestore(Stores.ROS1_NOETIC).types
FLOAT32, FLOAT64, UINT8 = 7, 8, 2


def header(frame: str = "camera") -> object:
    return ROS2["std_msgs/msg/Header"](
        stamp=ROS2["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id=frame
    )


def field(name: str, offset: int, datatype: int = FLOAT32) -> object:
    return ROS2["sensor_msgs/msg/PointField"](name=name, offset=offset, datatype=datatype, count=1)


def make_cloud(
    xyz: np.ndarray,
    *,
    point_step: int = 32,
    offsets: tuple[int, int, int] = (0, 4, 8),
    row_pad: int = 0,
    bigendian: bool = False,
) -> object:
    """A PointCloud2 with intensity and ring fields, padding, and optional row padding."""
    height, width, _ = xyz.shape
    row_step = width * point_step + row_pad
    buf = np.full(height * row_step, 0xAB, dtype=np.uint8)  # garbage in padding bytes
    order = ">" if bigendian else "<"

    def column(offset: int, dtype: str) -> np.ndarray:
        return np.ndarray(
            (height, width), dtype=dtype, buffer=buf, offset=offset, strides=(row_step, point_step)
        )

    for axis, offset in enumerate(offsets):
        column(offset, f"{order}f4")[...] = xyz[..., axis]
    column(16, f"{order}f4")[...] = 123.0
    column(20, "u1")[...] = 7
    fields = [field(n, o) for n, o in zip("xyz", offsets, strict=True)]
    fields += [field("intensity", 16), field("ring", 20, UINT8)]
    return ROS2["sensor_msgs/msg/PointCloud2"](
        header=header(),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=bigendian,
        point_step=point_step,
        row_step=row_step,
        data=buf,
        is_dense=False,
    )


def pointcloud2_to_xyz(msg: object, rows: slice = slice(None)) -> np.ndarray:
    """A cloud's rows as the player hands them out: a fresh float32 copy, NaN for no return."""
    return invalid_to_nan(np.array(pointcloud2_xyz(msg, rows), dtype=np.float32))


def random_xyz(height: int = 4, width: int = 5) -> np.ndarray:
    return np.random.default_rng(1).normal(size=(height, width, 3)).astype(np.float32)


# --- PointCloud2 --------------------------------------------------------------------------------


@pytest.mark.parametrize("bigendian", [False, True])
def test_pointcloud_with_padding_and_extra_fields_round_trips(bigendian: bool) -> None:
    xyz = random_xyz()
    out = pointcloud2_to_xyz(make_cloud(xyz, row_pad=12, bigendian=bigendian))
    assert out.dtype == np.float32
    assert out.shape == (4, 5, 3)
    np.testing.assert_array_equal(out, xyz)
    assert out.dtype.byteorder in "=<"


def test_pointcloud_with_scattered_fields_round_trips() -> None:
    xyz = random_xyz(3, 2)
    out = pointcloud2_to_xyz(make_cloud(xyz, offsets=(8, 0, 24), bigendian=True))
    np.testing.assert_array_equal(out, xyz)


def test_pointcloud_non_finite_points_become_nan() -> None:
    xyz = random_xyz()
    xyz[1, 2, 0] = np.inf
    xyz[3, 4] = np.nan
    out = pointcloud2_to_xyz(make_cloud(xyz))
    assert np.isnan(out[1, 2]).all()
    assert np.isnan(out[3, 4]).all()
    assert np.isfinite(out).all(axis=2).sum() == 20 - 2


@pytest.mark.parametrize(
    ("offsets", "bigendian"), [((0, 4, 8), False), ((0, 4, 8), True), ((8, 0, 24), False)]
)
def test_pointcloud_some_rows_are_those_rows_of_the_whole(
    offsets: tuple[int, int, int], bigendian: bool
) -> None:
    xyz = random_xyz(9, 4)
    xyz[4, 1, 2] = np.inf
    msg = make_cloud(xyz, offsets=offsets, row_pad=8, bigendian=bigendian)
    whole = pointcloud2_to_xyz(msg)
    for rows in (slice(0, 9, 4), slice(4, 5), slice(None)):
        np.testing.assert_array_equal(pointcloud2_to_xyz(msg, rows), whole[rows])
    assert np.isnan(pointcloud2_to_xyz(msg, slice(4, 5))[0, 1]).all()
    view = pointcloud2_xyz(msg, slice(0, 9, 4))  # no copy, non-finite left as it is
    np.testing.assert_array_equal(view, xyz[0:9:4])
    if offsets == (0, 4, 8):
        assert not view.flags.owndata


def test_depth_some_rows_are_those_rows_of_the_whole() -> None:
    depth_mm = np.random.default_rng(2).integers(0, 4000, size=(HEIGHT, WIDTH)).astype(np.uint16)
    image = make_depth(depth_mm, "16UC1")
    whole = depth_image_to_xyz(image, camera_info())
    np.testing.assert_array_equal(
        depth_image_to_xyz(image, camera_info(), slice(1, HEIGHT, 3)), whole[1:HEIGHT:3]
    )


def test_pointcloud_unorganized_is_one_row() -> None:
    xyz = random_xyz(1, 7)
    np.testing.assert_array_equal(pointcloud2_to_xyz(make_cloud(xyz)), xyz)


def test_pointcloud_rejects_non_float32_xyz() -> None:
    msg = make_cloud(random_xyz())
    msg.fields[1] = field("y", 4, FLOAT64)
    with pytest.raises(PlayerError, match=r"'y' is FLOAT64; only FLOAT32"):
        pointcloud2_to_xyz(msg)


def test_pointcloud_rejects_missing_field_and_short_buffer() -> None:
    msg = make_cloud(random_xyz())
    del msg.fields[2]
    with pytest.raises(PlayerError, match=r"no field 'z' \(fields: x, y, intensity, ring\)"):
        pointcloud2_to_xyz(msg)
    msg = make_cloud(random_xyz())
    msg.data = msg.data[:-1]
    with pytest.raises(PlayerError, match="needs"):
        pointcloud2_to_xyz(msg)


# --- depth images -------------------------------------------------------------------------------

FX, FY, CX, CY = 500.0, 400.0, 3.5, 2.5
WIDTH, HEIGHT = 8, 6


def camera_info(*, ros1: bool = False, width: int = WIDTH, height: int = HEIGHT) -> object:
    k = np.array([FX, 0, CX, 0, FY, CY, 0, 0, 1], dtype=np.float64)
    if ros1:
        info = ROS1["sensor_msgs/msg/CameraInfo"]
        roi = ROS1["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
        hdr = ROS1["std_msgs/msg/Header"](0, ROS1["builtin_interfaces/msg/Time"](0, 0), "cam")
    else:
        info = ROS2["sensor_msgs/msg/CameraInfo"]
        roi = ROS2["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
        hdr = header()
    return info(
        hdr, height, width, "plumb_bob", np.zeros(5), k, np.eye(3).ravel(), np.zeros(12), 0, 0, roi
    )


def make_depth(
    depth: np.ndarray, encoding: str, *, pad: int = 6, bigendian: bool = False
) -> object:
    """An Image whose rows carry ``pad`` garbage bytes after the pixels."""
    order = ">" if bigendian else "<"
    kind = f"{order}u2" if encoding == "16UC1" else f"{order}f4"
    pixels = depth.astype(kind)
    rows = np.full((depth.shape[0], pixels.itemsize * depth.shape[1] + pad), 0xCD, np.uint8)
    rows[:, : -pad or None] = pixels.view(np.uint8).reshape(depth.shape[0], -1)
    return ROS2["sensor_msgs/msg/Image"](
        header=header("camera_optical"),
        height=depth.shape[0],
        width=depth.shape[1],
        encoding=encoding,
        is_bigendian=bigendian,
        step=rows.shape[1],
        data=rows.ravel(),
    )


def expected_point(u: int, v: int, z: float) -> np.ndarray:
    return np.array([(u - CX) / FX * z, (v - CY) / FY * z, z], dtype=np.float32)


@pytest.mark.parametrize("bigendian", [False, True])
def test_depth_16uc1_with_row_padding(bigendian: bool) -> None:
    depth_mm = np.full((HEIGHT, WIDTH), 1500, dtype=np.uint16)
    depth_mm[4, 1] = 2000
    depth_mm[0, 7] = 0
    out = depth_image_to_xyz(make_depth(depth_mm, "16UC1", bigendian=bigendian), camera_info())
    assert out.shape == (HEIGHT, WIDTH, 3)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out[4, 1], expected_point(1, 4, 2.0), rtol=1e-6)
    np.testing.assert_allclose(out[2, 3], expected_point(3, 2, 1.5), rtol=1e-6)
    assert np.isnan(out[0, 7]).all()
    assert np.isfinite(out).all(axis=2).sum() == HEIGHT * WIDTH - 1


@pytest.mark.parametrize("bigendian", [False, True])
def test_depth_32fc1_with_row_padding(bigendian: bool) -> None:
    depth = np.full((HEIGHT, WIDTH), 3.25, dtype=np.float32)
    depth[5, 0] = 0.75
    depth[1, 1], depth[1, 2], depth[1, 3], depth[1, 4] = np.nan, 0.0, np.inf, -1.0
    image = make_depth(depth, "32FC1", pad=4, bigendian=bigendian)
    out = depth_image_to_xyz(image, camera_info(ros1=True))
    np.testing.assert_allclose(out[5, 0], expected_point(0, 5, 0.75), rtol=1e-6)
    np.testing.assert_allclose(out[0, 6], expected_point(6, 0, 3.25), rtol=1e-6)
    assert np.isnan(out[1, 1:5]).all()
    assert np.isfinite(out).all(axis=2).sum() == HEIGHT * WIDTH - 4


def test_depth_rays_are_cached_per_calibration() -> None:
    image = make_depth(np.ones((HEIGHT, WIDTH)), "16UC1")
    depth_image_to_xyz(image, camera_info())
    hits = _rays.cache_info().hits
    depth_image_to_xyz(image, camera_info())
    assert _rays.cache_info().hits == hits + 1


def test_depth_rejects_other_encodings_and_mismatched_calibration() -> None:
    image = make_depth(np.ones((HEIGHT, WIDTH)), "16UC1")
    image.encoding = "rgb8"
    with pytest.raises(PlayerError, match=r"encoding 'rgb8' is not supported \(supported: 16UC1"):
        depth_image_to_xyz(image, camera_info())
    image = make_depth(np.ones((HEIGHT, WIDTH)), "16UC1")
    with pytest.raises(PlayerError, match=r"8x6 but its CameraInfo is calibrated for 16x12"):
        depth_image_to_xyz(image, camera_info(width=16, height=12))
    info = camera_info()
    info.k[:] = 0
    with pytest.raises(PlayerError, match="no usable calibration"):
        depth_image_to_xyz(image, info)


# --- LaserScan ----------------------------------------------------------------------------------


def test_laserscan_points_and_invalid_ranges() -> None:
    ranges = np.array([1.0, 2.0, 0.05, np.inf, 9.0, np.nan, 3.0], dtype=np.float32)
    scan = ROS2["sensor_msgs/msg/LaserScan"](
        header=header("laser"),
        angle_min=-math.pi / 2,
        angle_max=math.pi / 2,
        angle_increment=math.pi / 6,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=8.0,
        ranges=ranges,
        intensities=np.zeros(0, np.float32),
    )
    out = laserscan_to_xyz(scan)
    assert out.shape == (1, 7, 3)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out[0, 0], [0.0, -1.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(out[0, 1], [2 * math.cos(-math.pi / 3), -math.sqrt(3), 0], atol=1e-6)
    np.testing.assert_allclose(out[0, 6], [0.0, 3.0, 0.0], atol=1e-6)
    assert np.isnan(out[0, [2, 3, 4, 5]]).all()
