"""What the player hands to its publisher for each sensor message, and how it picks it."""

from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Self

import numpy as np

from wallmap.common.messages import Frame
from wallmap.common.scan_row import DEFAULT_BAND, RowSelection, pick_points, rows_to_search
from wallmap.services.player.placement import Placement
from wallmap.services.player.pointcloud import invalid_to_nan


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
        sweep: Seconds the frame's capture spans and was not deskewed over: a scanner's sweep
            without beam times, or without poses to deskew it with (0: an instant).
    """

    stamp: float
    frame_id: str
    points: np.ndarray
    T_base_sensor: np.ndarray
    bag_time: float = 0.0
    band: tuple[float, float] | None = None
    sweep: float = 0.0

    def to_frame(self, *, run: str, seq: int, sensor: str, lossless: bool = False) -> Frame:
        """The wire ``Frame`` a player sends of this one, as frame ``seq`` of ``run``.

        One place for it, so the player, the ROS 2 source and the offline runner send alike.
        ``sensor`` is ``depth`` or ``scan`` (whose noise the points carry); ``lossless``: the
        player waits for the pipeline (``--fast``).
        """
        return Frame(
            run=run,
            seq=seq,
            stamp=self.stamp,
            frame_id=self.frame_id,
            points=self.points,
            T_base_sensor=self.T_base_sensor,
            sensor=sensor,
            lossless=lossless,
            band=self.band,
            sweep=self.sweep,
        )


def hand_out(
    read: Callable[[slice], np.ndarray],
    height: int,
    rows: RowSelection | None,
    mount: np.ndarray,
    placement: Placement,
) -> tuple[np.ndarray, tuple[float, float] | None]:
    """One frame's points as the player sends them, and the band they stack (or None).

    ``read(rows)`` decodes those image rows of a frame ``height`` rows high. With ``rows`` None:
    every row. Else only the rows the selection searches are read (decoding whole clouds is most
    of a player's time) and the band's stack, or one row, is picked (``pick_points``); the band
    is the selection's, or the one the sensor sees (``placement.band``), or the default. Of a
    band's rows, those whose rays never come near it are not read (``placement.rays``: the
    stack is the same without them).

    The points are float32 and the caller's own (not a view over the message), and a point
    without all three coordinates is all NaN, so consumers test one value for "no return". A
    band's stack is so already (``band_stack``: such a point has no height); rows are made so.
    """
    if rows is None:
        return _whole_points(read(slice(None))), None
    band = rows.band or placement.band or DEFAULT_BAND
    searched = rows_to_search(rows, height)
    rays = placement.rays
    points = read(searched if rays is None else rays.reaching(searched, height, mount, band))
    if rays is not None and points.shape[1] != rays.width:
        points = read(searched)  # not the camera surveyed: every searched row
    points = pick_points(points, mount, band)
    if points.shape[0] > 1:
        return points, band
    return _whole_points(points), None


def _whole_points(points: np.ndarray) -> np.ndarray:
    """``points`` as float32 of the caller's own, NaN wherever a coordinate is not finite."""
    if points.base is not None or points.dtype != np.float32:  # a view, not ours to change
        points = np.array(points, dtype=np.float32)
    return invalid_to_nan(points)


class ClosingSource:
    """A frame source used as ``with Source(path) as source:``, closed on the way out."""

    def close(self) -> None:
        """Release what the source holds; safe to call twice."""

    def __enter__(self) -> Self:
        """The source itself."""
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        """Close the source."""
        self.close()
