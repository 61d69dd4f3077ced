"""What the player hands to its publisher for each sensor message."""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class SensorFrame:
    """One decoded sensor message: an organized grid of 3-D points and its mounting.

    Attributes:
        stamp: Header stamp in float seconds (bag receive time when the header stamp is zero).
        frame_id: Sensor frame the points are expressed in.
        points: float32 (rows, w, 3) points in the sensor frame (every row, or those the player
            asked for); NaN marks pixels without a return.
        T_base_sensor: float64 4x4 transform mapping sensor-frame points into the base frame.
        bag_time: When the bag received it, seconds from the bag's start (for playback).
        band: When ``points`` is the band's stack (``pick_points``), that band (m above the
            floor); None for whole clouds and single rows.
    """

    stamp: float
    frame_id: str
    points: np.ndarray
    T_base_sensor: np.ndarray
    bag_time: float = 0.0
    band: tuple[float, float] | None = None
