"""Values the player hands to its publisher: sensor frames and planar robot poses."""

from dataclasses import dataclass
from typing import Any

import numpy as np


# eq=False: the array fields make generated equality ambiguous and hashing impossible.
@dataclass(frozen=True, eq=False)
class Pose2D:
    """Planar pose of ``child`` in ``frame`` at ``stamp``, as the mapper consumes it.

    Attributes:
        stamp: Time in float seconds (the sensor frame's header stamp it was interpolated at).
        x: Position along the frame's x axis, metres.
        y: Position along the frame's y axis, metres.
        yaw: Heading about z, radians in [-pi, pi].
        cov: 3x3 covariance of (x, y, yaw), or None when the source gives none.
        frame: Fixed frame the pose is expressed in.
        child: Robot frame whose pose this is.
    """

    stamp: float
    x: float
    y: float
    yaw: float
    cov: np.ndarray | None
    frame: str = "map"
    child: str = "base_link"


@dataclass(frozen=True, eq=False)
class SensorFrame:
    """One decoded sensor message: an organized grid of 3-D points and its mounting.

    Attributes:
        stamp: Header stamp in float seconds (bag receive time when the header stamp is zero).
        frame_id: Sensor frame the points are expressed in.
        points: float32 (h, w, 3) points in the sensor frame; NaN marks pixels without a return.
        T_base_sensor: float64 4x4 transform mapping sensor-frame points into the base frame.
    """

    stamp: float
    frame_id: str
    points: np.ndarray
    T_base_sensor: np.ndarray


def header_stamp(header: Any, receive_time_ns: int) -> float:
    """Return a message's header stamp in float seconds, or its bag receive time if unset.

    Some drivers leave the header stamp at zero; the receive time is then the best estimate.
    """
    stamp = header.stamp
    if stamp.sec == 0 and stamp.nanosec == 0:
        return receive_time_ns * 1e-9
    return stamp.sec + stamp.nanosec * 1e-9
