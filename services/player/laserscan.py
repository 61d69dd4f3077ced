"""Convert sensor_msgs/LaserScan messages into a one-row xyz grid.

A planar scan is treated as an organized cloud with a single row so it flows through the same
SensorFrame path as depth cameras. Beam directions depend only on the scan geometry, which a
scanner keeps constant, so they are cached.
"""

from functools import lru_cache
from typing import Any

import numpy as np


@lru_cache(maxsize=8)
def _directions(angle_min: float, angle_increment: float, count: int) -> np.ndarray:
    """Unit beam directions (count, 3) in the scanner frame, z = 0, read-only."""
    angles = angle_min + angle_increment * np.arange(count, dtype=np.float64)
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros(count)], axis=1)
    directions = directions.astype(np.float32)
    directions.flags.writeable = False
    return directions


def laserscan_to_xyz(msg: Any) -> np.ndarray:
    """Convert a LaserScan to float32 (1, n, 3) points in the scanner frame.

    Ranges outside [range_min, range_max] or non-finite become NaN in all three coordinates,
    matching the "NaN = no return" convention of the other decoders.

    Args:
        msg: A deserialized sensor_msgs/msg/LaserScan (ROS 1 or ROS 2).

    Returns:
        Freshly allocated float32 array of shape (1, len(ranges), 3).
    """
    ranges = np.asarray(msg.ranges, dtype=np.float32)
    valid = np.isfinite(ranges) & (ranges >= msg.range_min) & (ranges <= msg.range_max)
    ranges = np.where(valid, ranges, np.float32(np.nan))
    directions = _directions(float(msg.angle_min), float(msg.angle_increment), ranges.size)
    return (directions * ranges[:, np.newaxis])[np.newaxis]
