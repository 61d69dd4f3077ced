"""Back-project depth images (sensor_msgs/Image + CameraInfo) into organized xyz grids.

A depth camera's intrinsics do not change during a recording, so the per-pixel ray directions
are computed once per calibration and each frame is a single multiply of rays by depth.
"""

from functools import lru_cache
from typing import Any

import numpy as np

from wallmap.services.player.errors import PlayerError

SUPPORTED_ENCODINGS = ("16UC1", "32FC1")
_MM_TO_M = np.float32(0.001)


@lru_cache(maxsize=8)
def _rays(
    height: int, width: int, intrinsics: tuple[float, float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """A pinhole camera's rays with z = 1: x per image column (w,), y per row (h,); read-only.

    Two vectors, not an (h, w, 3) cube: multiplying the depths axis by axis is several times
    faster than broadcasting them over the cube's last axis of 3.
    """
    fx, fy, cx, cy = intrinsics
    x = ((np.arange(width, dtype=np.float64) - cx) / fx).astype(np.float32)
    y = ((np.arange(height, dtype=np.float64) - cy) / fy).astype(np.float32)
    x.flags.writeable = False
    y.flags.writeable = False
    return x, y


def _intrinsics(camera_info: Any) -> tuple[float, float, float, float]:
    """Return (fx, fy, cx, cy) from K, which ROS 1 names ``K`` and ROS 2 ``k``."""
    k = getattr(camera_info, "k", None)
    if k is None:
        k = camera_info.K
    fx, cx, fy, cy = float(k[0]), float(k[2]), float(k[4]), float(k[5])
    if fx <= 0 or fy <= 0:
        raise PlayerError(f"CameraInfo has no usable calibration (fx={fx}, fy={fy} in K)")
    return fx, fy, cx, cy


def _pixels(image: Any, itemsize: int, kind: str) -> np.ndarray:
    """View the image buffer as (h, w) pixels, skipping row padding and honouring byte order."""
    height, width, step = int(image.height), int(image.width), int(image.step)
    data = np.asarray(image.data, dtype=np.uint8).reshape(-1)
    if step < width * itemsize:
        raise PlayerError(
            f"depth image step {step} is smaller than width {width} x {itemsize} bytes"
        )
    needed = (height - 1) * step + width * itemsize if height else 0
    if data.size < needed:
        raise PlayerError(
            f"depth image data has {data.size} bytes but {height}x{width} with step {step} "
            f"needs {needed}"
        )
    dtype = np.dtype(f"{'>' if image.is_bigendian else '<'}{kind}{itemsize}")
    return np.ndarray(shape=(height, width), dtype=dtype, buffer=data, strides=(step, itemsize))


def depth_image_to_xyz(image: Any, camera_info: Any, rows: slice = slice(None)) -> np.ndarray:
    """Back-project a depth image (or some of its rows) into float32 (rows, w, 3) points.

    The optical frame has z forward, x right and y down. ``16UC1`` is millimetres with 0 meaning
    no return; ``32FC1`` is metres with NaN, inf and non-positive values meaning no return. Pixels
    without a return are NaN in all three coordinates. Points are in the optical frame.

    Args:
        image: A deserialized sensor_msgs/msg/Image with a supported depth encoding.
        camera_info: The camera's sensor_msgs/msg/CameraInfo; only K (pinhole) is used.
        rows: The rows to back-project (all by default).

    Returns:
        Freshly allocated float32 array of shape (rows, width, 3).

    Raises:
        PlayerError: Unsupported encoding, image size differing from the calibration, missing
            calibration, or a buffer too small for the declared layout.
    """
    encoding = str(image.encoding)
    height, width = int(image.height), int(image.width)
    info_size = (int(camera_info.height), int(camera_info.width))
    if info_size not in {(0, 0), (height, width)}:
        raise PlayerError(
            f"depth image is {width}x{height} but its CameraInfo is calibrated for "
            f"{info_size[1]}x{info_size[0]}"
        )
    if encoding == "16UC1":
        raw = _pixels(image, 2, "u")[rows]
        depth = raw.astype(np.float32) * _MM_TO_M
        depth[raw == 0] = np.nan
    elif encoding == "32FC1":
        depth = _pixels(image, 4, "f")[rows].astype(np.float32)
        depth[~(np.isfinite(depth) & (depth > 0))] = np.nan
    else:
        raise PlayerError(
            f"depth image encoding {encoding!r} is not supported "
            f"(supported: {', '.join(SUPPORTED_ENCODINGS)})"
        )
    return back_project(depth, (height, width), _intrinsics(camera_info), rows)


def back_project(
    depth: np.ndarray,
    size: tuple[int, int],
    intrinsics: tuple[float, float, float, float],
    rows: slice = slice(None),
) -> np.ndarray:
    """Points (rows, w, 3) in the optical frame from depths (m, NaN for none) of those rows.

    Args:
        depth: float32 depths of the rows ``rows`` of an image of ``size`` (height, width).
        size: The whole image's (height, width).
        intrinsics: (fx, fy, cx, cy) in pixels.
        rows: Which rows ``depth`` holds.
    """
    x, y = _rays(*size, intrinsics)
    points = np.empty((*depth.shape, 3), dtype=np.float32)
    np.multiply(depth, x, out=points[..., 0])
    np.multiply(depth, y[rows, np.newaxis], out=points[..., 1])
    points[..., 2] = depth
    return points
