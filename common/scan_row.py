"""From an organized cloud to one scan row of 2-D points in the robot's base frame.

The paper takes one fixed upper row of the image, to look over furniture. Two things go wrong
with a fixed row: far away it climbs onto the ceiling, and a ceiling (or floor) seen by one image
row is itself a straight line in 2-D, so it comes out as a phantom wall; and its height depends on
the camera's tilt. The default here is a *height band* in the base frame instead: per image
column, the point whose height is nearest the middle of the band, which keeps above furniture and
below the ceiling at every range and any tilt. Walls are vertical, so every point on a wall, at
any height, projects onto the wall's 2-D line. ``docs/detector.md`` compares the two on generated
scenes.

A frame with a single row is a 2-D scanner's scan and is used as it is.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from wallmap.common.codec import MessageError

Array = NDArray[np.float64]
SEARCHED_ROWS = 64  # the band is looked for on about this many image rows (up to twice)


@dataclass(frozen=True)
class RowSelection:
    """How the scan row is chosen.

    Attributes:
        mode: ``band`` (a height band in the base frame) or ``row`` (one fixed image row).
        band: lowest and highest height of the band (m, base frame).
        row_fraction: for ``row`` mode, the row as a fraction of the image height from the top.
    """

    mode: Literal["band", "row"] = "band"
    band: tuple[float, float] = (1.3, 2.1)
    row_fraction: float = 0.25

    def to_map(self) -> dict[str, Any]:
        """What the detector tells players, so they send this row only."""
        return {"mode": self.mode, "band": list(self.band), "row_fraction": self.row_fraction}

    @classmethod
    def from_map(cls, m: dict[str, Any]) -> RowSelection:
        """Read what a detector said; MessageError when it makes no sense."""
        try:
            mode, (low, high), fraction = m["mode"], m["band"], float(m["row_fraction"])
            band = (float(low), float(high))
        except (KeyError, TypeError, ValueError) as err:
            msg = f"malformed row selection: {err}"
            raise MessageError(msg) from err
        if (
            not isinstance(mode, str)
            or mode not in ("band", "row")
            or not low < high
            or not 0.0 <= fraction <= 1.0
        ):
            msg = f"row selection out of range: {m!r}"
            raise MessageError(msg)
        return cls(mode, band, fraction)


def _to_base_xy(points: NDArray[np.float32], base_from_sensor: Array) -> Array:
    xy = points.astype(np.float64) @ base_from_sensor[:2, :3].T + base_from_sensor[:2, 3]
    xy[~np.isfinite(xy).all(axis=-1)] = np.nan
    return xy


def band_points(
    points: NDArray[np.float32], base_from_sensor: Array, band: tuple[float, float]
) -> NDArray[np.float32]:
    """Per column, the point nearest the middle of the height band (sensor frame); NaN if none."""
    low, high = band
    a, b, c, d = base_from_sensor[2].astype(np.float32)
    # Per axis rather than a matrix product: the player hands a strided view over the message.
    height = points[..., 0] * a
    height += points[..., 1] * b
    height += points[..., 2] * c
    height += d
    inside = (height >= low) & (height <= high)  # NaN compares False
    cost = np.where(inside, np.abs(height - 0.5 * (low + high)), np.inf)
    best = np.argmin(cost, axis=0)
    columns = np.arange(points.shape[1])
    chosen = points[best, columns]
    chosen[~inside[best, columns]] = np.nan
    return chosen


def rows_to_search(how: RowSelection, height: int) -> slice:
    """The image rows a selection looks at, so a player decodes only those.

    The band is searched on every k-th row, k = height // SEARCHED_ROWS: on a 480-row camera with
    a 45 degree vertical field of view the searched rows are 0.7 degree apart, and an 0.8 m band
    spans that out to 65 m, beyond any depth camera's range.
    """
    if height <= 1:
        return slice(0, height)
    if how.mode == "row":
        row = round(how.row_fraction * (height - 1))
        return slice(row, row + 1)
    return slice(0, height, max(1, height // SEARCHED_ROWS))


def pick_points(
    searched: NDArray[np.float32], base_from_sensor: Array, how: RowSelection
) -> NDArray[np.float32]:
    """The scan row (columns x 3) from the rows ``rows_to_search`` chose, and only those."""
    if searched.shape[0] == 1:
        return searched[0]
    return band_points(searched, base_from_sensor, how.band)


def select_points(
    points: NDArray[np.float32], base_from_sensor: Array, how: RowSelection
) -> NDArray[np.float32]:
    """The scan row (columns x 3, sensor frame, NaN for no point) chosen from an organized cloud.

    The player applies it too, so that only this row travels (see RowSelection.to_map).
    """
    searched = points[rows_to_search(how, points.shape[0])]
    return pick_points(searched, base_from_sensor, how)


def select_scan(points: NDArray[np.float32], base_from_sensor: Array, how: RowSelection) -> Array:
    """The scan row as 2-D points in the base frame (columns x 2, NaN for no point)."""
    return _to_base_xy(select_points(points, base_from_sensor, how), base_from_sensor)
