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


def beam_times(msg: Any, period: float) -> tuple[bool, float]:
    """Whether a scan's beams are timed, and how long its sweep took (s) from its stamp.

    ROS stamps a scan at its first beam, the next one ``time_increment`` later; a scanner that
    leaves ``time_increment`` at 0 says nothing of its beams' times, and its sweep is taken to
    last ``scan_time`` or, without that either, ``period`` (the time between scans).
    """
    count = len(msg.ranges)
    timed = float(msg.time_increment) > 0.0 and count > 1
    if timed:
        return True, float(msg.time_increment) * (count - 1)
    return False, float(msg.scan_time) if float(msg.scan_time) > 0.0 else period


def deskew(points: np.ndarray, mount: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """A timed scan's points as if all were seen at its first beam.

    Args:
        points: (1, n, 3) float32 points in the scanner frame, beams in time order.
        mount: T_base_sensor (4x4).
        motion: The base frame's planar motion (x, y, yaw) from the first beam to the last,
            in the first beam's base frame; taken as steady over the sweep.

    Returns:
        (1, n, 3) float32 points in the scanner frame.
    """
    n = points.shape[1]
    share = np.linspace(0.0, 1.0, n)[:, None]
    step = share * motion  # (n, 3): the base's pose at each beam, from the first
    base = points[0].astype(np.float64) @ mount[:3, :3].T + mount[:3, 3]
    c, s = np.cos(step[:, 2]), np.sin(step[:, 2])
    x = c * base[:, 0] - s * base[:, 1] + step[:, 0]
    y = s * base[:, 0] + c * base[:, 1] + step[:, 1]
    moved = np.column_stack([x, y, base[:, 2]])
    rotation, offset = mount[:3, :3], mount[:3, 3]
    return ((moved - offset) @ rotation).astype(np.float32)[np.newaxis]
