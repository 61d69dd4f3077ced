"""Decode sensor_msgs/PointCloud2 messages into organized xyz grids.

Clouds from real drivers carry extra fields (intensity, rgb, ring), padding and per-row gaps, in
either byte order. Reading them through a structured dtype laid over the message buffer keeps the
decoding a zero-copy view plus one copy into the float32 xyz array the detector wants.
"""

from typing import Any

import numpy as np

from wallmap.services.player.errors import PlayerError

# sensor_msgs/PointField datatype constants, named for error messages.
POINTFIELD_TYPES: dict[int, str] = {
    1: "INT8",
    2: "UINT8",
    3: "INT16",
    4: "UINT16",
    5: "INT32",
    6: "UINT32",
    7: "FLOAT32",
    8: "FLOAT64",
}
FLOAT32 = 7
_XYZ = ("x", "y", "z")


def _xyz_offsets(msg: Any) -> tuple[int, int, int]:
    """Return the byte offsets of x, y and z, checking each is a FLOAT32 field."""
    fields = {f.name: f for f in msg.fields}
    offsets = []
    for name in _XYZ:
        field = fields.get(name)
        if field is None:
            have = ", ".join(fields) or "none"
            raise PlayerError(f"PointCloud2 has no field {name!r} (fields: {have})")
        if field.datatype != FLOAT32:
            kind = POINTFIELD_TYPES.get(field.datatype, f"unknown type {field.datatype}")
            raise PlayerError(
                f"PointCloud2 field {name!r} is {kind}; only FLOAT32 x/y/z are supported"
            )
        offsets.append(int(field.offset))
    return offsets[0], offsets[1], offsets[2]


def _check_layout(msg: Any, offsets: tuple[int, int, int], size: int) -> None:
    """Check that a cloud's steps hold its x/y/z fields and its buffer its rows.

    Raises:
        PlayerError: Saying which of them does not fit.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    if max(offsets) + 4 > point_step:
        raise PlayerError(
            f"PointCloud2 point_step {point_step} is smaller than its x/y/z fields "
            f"(offsets {', '.join(map(str, offsets))})"
        )
    if row_step < width * point_step and height > 1:
        raise PlayerError(
            f"PointCloud2 row_step {row_step} is smaller than width {width} x point_step "
            f"{point_step}"
        )
    needed = (height - 1) * row_step + width * point_step
    if size < needed:
        raise PlayerError(
            f"PointCloud2 data has {size} bytes but its {height}x{width} layout needs {needed}"
        )


def pointcloud2_xyz(msg: Any, rows: slice = slice(None)) -> np.ndarray:
    """The x, y, z of a PointCloud2's rows as (rows, width, 3) float32, without copying if it can.

    Any field layout, ``point_step``, ``row_step`` and byte order is accepted as long as x, y and
    z are FLOAT32. Contiguous x, y, z (the common case) come back as a strided view over the
    message buffer, so picking a scan row reads only the points it looks at; other layouts are
    copied. Non-finite coordinates are left as they are (see ``invalid_to_nan``). Unorganized
    clouds come back as a single row (1, n, 3).

    Args:
        msg: A deserialized sensor_msgs/msg/PointCloud2 (ROS 1 or ROS 2).
        rows: The rows wanted (all by default); the others are never read.

    Raises:
        PlayerError: x/y/z missing or not FLOAT32, or the buffer is too small for the layout.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    ox, oy, oz = _xyz_offsets(msg)
    if height == 0 or width == 0:
        return np.empty((len(range(height)[rows]), width, 3), dtype=np.float32)
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    _check_layout(msg, (ox, oy, oz), data.size)
    order = ">" if msg.is_bigendian else "<"
    if (oy, oz) == (ox + 4, ox + 8):
        view = np.ndarray(
            shape=(height, width, 3),
            dtype=f"{order}f4",
            buffer=data,
            offset=ox,
            strides=(row_step, point_step, 4),
        )
        return view[rows]
    dtype = np.dtype(
        {
            "names": _XYZ,
            "formats": [f"{order}f4"] * 3,
            "offsets": [ox, oy, oz],
            "itemsize": point_step,
        }
    )
    grid = np.ndarray(
        shape=(height, width), dtype=dtype, buffer=data, strides=(row_step, point_step)
    )[rows]
    out = np.empty((*grid.shape, 3), dtype=np.float32)
    for i, name in enumerate(_XYZ):
        out[..., i] = grid[name]
    return out


def invalid_to_nan(points: np.ndarray) -> np.ndarray:
    """Make every point with a non-finite coordinate all-NaN, in place, and return it.

    Consumers then test one value for "no return".
    """
    finite = np.isfinite(points)
    if not finite.all():
        # Explicit ands and adding NaN (0 elsewhere) per axis: reducing over the length-3 axis
        # and boolean-mask assignment are each several times slower on 640x480 clouds.
        valid = finite[..., 0] & finite[..., 1] & finite[..., 2]
        penalty = np.where(valid, np.float32(0.0), np.float32(np.nan))
        for axis in range(3):
            points[..., axis] += penalty
    return points
