"""From an organized cloud to one scan row of 2-D points in the robot's base frame.

The paper takes one fixed upper row of the image, to look over furniture. Two things go wrong
with a fixed row: far away it climbs onto the ceiling, and a ceiling (or floor) seen by one image
row is itself a straight line in 2-D, so it comes out as a phantom wall; and its height depends on
the camera's tilt. The default here is a *height band* in the base frame instead, and more than
one row of it: per image column, the points nearest ``STACK`` heights spread over the band. Walls
are vertical planes, so a wall's points at every height fall onto one spot of the floor plan;
a kettle, a box or a cabinet front does not rise through the band, and a counter top or a chair
seat is level. ``upright_points`` keeps, per column, a point only where what it lies on rises
through the band, which the paper's single row cannot see. ``docs/detector.md`` compares the
choices on generated scenes.

The band adapts to the sensor (``auto_band``): a handheld camera 1.4 m up looking down sees
nothing at 1.3 to 2.1 m, the band that suits a robot's level camera.

A frame with a single row is a 2-D scanner's scan and is used as it is.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from wallmap.common.codec import MessageError
from wallmap.common.compiled import band_kernels, loaded_band_kernels, plain

Array = NDArray[np.float64]
SEARCHED_ROWS = 64  # the band is looked for on about this many image rows (up to twice)


DEFAULT_BAND = (1.3, 2.1)  # m above the floor: over furniture, under the ceiling
STACK = 6  # heights per column within the band
FURNITURE = 0.9  # m: tables, counters and desks stay below this
MIN_BAND = 0.3  # m: a band narrower than this holds too few heights to tell walls from clutter
UPRIGHT_SHARE = 0.6  # of the band (or of what a column sees of it) a surface must rise through
UPRIGHT_TOP = 0.1  # m: a wall reaches to within this of the top of what its column sees
UPRIGHT_CELL = 0.04  # m: points this close on the floor plan stand on one spot


@dataclass(frozen=True)
class RowSelection:
    """How the scan row is chosen.

    Attributes:
        mode: ``band`` (a height band in the base frame) or ``row`` (one fixed image row).
        band: lowest and highest height of the band (m, base frame).
        row_fraction: for ``row`` mode, the row as a fraction of the image height from the top.
    """

    mode: Literal["band", "row"] = "band"
    band: tuple[float, float] | None = None
    row_fraction: float = 0.25

    def __post_init__(self) -> None:
        if self.band is not None:
            parse_band(self.band)  # two finite heights, low below high: ValueError otherwise
        if not 0.0 <= self.row_fraction <= 1.0:
            msg = f"row_fraction must lie in [0, 1], got {self.row_fraction}"
            raise ValueError(msg)

    def to_map(self) -> dict[str, Any]:
        """What the detector tells players, so they send this row only."""
        band = "auto" if self.band is None else list(self.band)
        return {"mode": self.mode, "band": band, "row_fraction": self.row_fraction}

    @classmethod
    def from_map(cls, m: dict[str, Any]) -> RowSelection:
        """Read what a detector said; MessageError when it makes no sense."""
        try:
            mode, fraction = m["mode"], float(m["row_fraction"])
            band = None if m["band"] in ("auto", None) else parse_band(m["band"])
        except (KeyError, TypeError, ValueError) as err:
            msg = f"malformed row selection: {err}"
            raise MessageError(msg) from err
        if not isinstance(mode, str) or mode not in ("band", "row") or not 0.0 <= fraction <= 1.0:
            msg = f"row selection out of range: {m!r}"
            raise MessageError(msg)
        return cls(mode, band, fraction)


def parse_band(value: Any) -> tuple[float, float]:
    """A band (low, high) in metres from a two-element sequence; ValueError if it is not one."""
    low, high = (float(v) for v in value)
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        msg = f"band must be two finite heights, low below high, got {value!r}"
        raise ValueError(msg)
    return low, high


def auto_band(heights: Array, default: tuple[float, float] = DEFAULT_BAND) -> tuple[float, float]:
    """The height band a sensor can see, above furniture and below the ceiling.

    ``heights`` are of the points the sensor saw, above the floor. The band reaches up to just
    below the highest heights seen (at most the default's top, under the ceiling's clutter) and
    is as tall as the default, but never reaches down into furniture (0.9 m): a sensor that
    sees nothing above furniture height (a camera looking down at a cabinet) sees no wall. A
    sensor that sees the whole default band gets the default.
    """
    low_default, high_default = default
    seen = heights[np.isfinite(heights)]
    if seen.size < 100:
        return default
    high = min(high_default, float(np.percentile(seen, 97.0)) - 0.05)
    low = max(FURNITURE, min(low_default, high - (high_default - low_default)))
    high = max(high, low + MIN_BAND)  # never down into the furniture: rather a band unseen
    return round(low, 2), round(high, 2)


def to_base_xy(points: NDArray[np.float32], T_base_sensor: Array) -> Array:
    """Sensor-frame points (..., 3) as base-frame floor positions (..., 2), NaN where none."""
    xy = points.astype(np.float64) @ T_base_sensor[:2, :3].T + T_base_sensor[:2, 3]
    xy[~np.isfinite(xy).all(axis=-1)] = np.nan
    return xy


def _heights(points: NDArray[np.float32], T_base_sensor: Array) -> NDArray[np.float32]:
    a, b, c, d = T_base_sensor[2].astype(np.float32)
    # Per axis rather than a matrix product: the player hands a strided view over the message.
    with np.errstate(invalid="ignore"):  # an infinite coordinate times 0: NaN, no height
        height = points[..., 0] * a
        height += points[..., 1] * b
        height += points[..., 2] * c
    height += d
    return height


def band_stack(
    points: NDArray[np.float32], T_base_sensor: Array, band: tuple[float, float]
) -> NDArray[np.float32]:
    """Per column, the points nearest ``STACK`` heights spread over the band: (STACK, w, 3).

    A height gets the point nearest it within half the spacing of the heights, or NaN (the
    first row of equals). Its points are whole: a point with a coordinate that is not finite
    has no height, and is never picked, so the stack needs no ``invalid_to_nan``.

    A player's largest share of a frame: one compiled pass over the rows as they lie in the
    message (``band_kernels.band_stack``) where the process has loaded it (a ``--fast``
    player, a detector), else six numpy passes (numba's import and start cost a process 0.3 s,
    which a player in real time need not pay). The two pick the same points, to the bit.
    """
    kernels = loaded_band_kernels()
    if kernels is None:
        return _band_stack_numpy(points, T_base_sensor, band)
    if points.dtype != np.float32:
        points = points.astype(np.float32)  # a big-endian cloud's rows, say: made native
    low, high = band
    return kernels.band_stack(
        points, plain(T_base_sensor, np.float64), float(low), float(high), STACK
    )


def _band_stack_numpy(
    points: NDArray[np.float32], T_base_sensor: Array, band: tuple[float, float]
) -> NDArray[np.float32]:
    """``band_stack`` in numpy: the heights searched column by column, in reused buffers."""
    low, high = band
    spacing = (high - low) / STACK
    height = np.ascontiguousarray(_heights(points, T_base_sensor).T)  # (w, rows)
    columns = np.arange(points.shape[1])
    stack = np.full((STACK, points.shape[1], 3), np.nan, dtype=np.float32)
    cost = np.empty_like(height)
    inside = np.empty(height.shape, dtype=bool)
    for level in range(STACK):
        np.subtract(height, low + (level + 0.5) * spacing, out=cost)
        np.abs(cost, out=cost)
        np.less_equal(cost, 0.5 * spacing, out=inside)  # False for NaN heights too
        np.copyto(cost, np.inf, where=~inside)
        best = np.argmin(cost, axis=1)
        found = inside[columns, best]
        stack[level, found] = points[best[found], columns[found]]
    return stack


def upright_points(stack: NDArray[np.float32], T_base_sensor: Array) -> NDArray[np.float32]:
    """Per column, the stack's point on something that rises through the band; NaN if none.

    A point's rise is the spread of heights of all stack points (every column's) standing on
    the same spot of the floor plan, within ``UPRIGHT_CELL``: a wall's points at every height
    share its spot, a kettle's reach only its top, a counter's or a seat's one height. A point
    is kept if it rises through most (``UPRIGHT_SHARE``) of the band, or of the part of the
    band its column sees at all (near a camera only a sliver of it is in view), and if what it
    stands on reaches the top of what its column sees: an appliance on a counter ends below the
    wall seen above it. Of a column's kept points, the one rising highest is taken, then the
    one nearest the band's middle.
    """
    stack = plain(stack, np.float32)
    height, xy, valid, keys = band_kernels().base_positions(
        stack, plain(T_base_sensor, np.float64), UPRIGHT_CELL
    )
    # The column's point is the mean of its kept points on the best one's spot: a depth
    # camera's steps (a Kinect's are 4 cm at 3.5 m) fall at other columns on other rows, so the
    # mean of a wall's heights lies on the wall, where one row's points lie on a staircase.
    return band_kernels().upright_choice(
        stack, height, xy, valid, keys, np.argsort(keys), UPRIGHT_SHARE, UPRIGHT_TOP, UPRIGHT_CELL
    )


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
    searched: NDArray[np.float32],
    T_base_sensor: Array,
    band: tuple[float, float],
) -> NDArray[np.float32]:
    """What a player sends of the rows ``rows_to_search`` chose: the band's stack, or the row.

    Returns (STACK, w, 3) for a band, or the one searched row (a scan, or ``row`` mode).
    """
    if searched.shape[0] == 1:
        return searched
    return band_stack(searched, T_base_sensor, band)


def frame_band(
    points: NDArray[np.float32], T_base_sensor: Array, how: RowSelection
) -> tuple[float, float]:
    """The band for a whole cloud: the selection's, or what this frame's sensor sees."""
    if how.band is not None:
        return how.band
    searched = points[rows_to_search(how, points.shape[0])]
    return auto_band(_heights(searched, T_base_sensor).ravel().astype(np.float64))


def frame_stack(
    points: NDArray[np.float32],
    T_base_sensor: Array,
    how: RowSelection,
    stacked: bool = False,
) -> NDArray[np.float32]:
    """A frame's points as the detector reads them: the band's stack (k, w, 3), or one row.

    ``points`` is a whole organized cloud, one row (a scan), or, with ``stacked``, the band's
    stack a player sent (``pick_points``).
    """
    if points.shape[0] == 1 or stacked:
        return points
    band = frame_band(points, T_base_sensor, how)
    return pick_points(points[rows_to_search(how, points.shape[0])], T_base_sensor, band)


def select_points(
    points: NDArray[np.float32],
    T_base_sensor: Array,
    how: RowSelection,
    stacked: bool = False,
) -> NDArray[np.float32]:
    """The scan row (columns x 3, sensor frame, NaN for no point) from a frame's points."""
    stack = frame_stack(points, T_base_sensor, how, stacked)
    return stack[0] if stack.shape[0] == 1 else upright_points(stack, T_base_sensor)


MAX_FREE_RAYS = 64  # rays a frame reports as free space


def free_rays(stack: NDArray[np.float32], T_base_sensor: Array) -> tuple[Array, Array]:
    """Where some of the sensor's rays in the band ended: its position and (n, 2) ends.

    Per sampled column the farthest return of the stack, in the base frame: the space from
    the sensor to it is free at some height of the band, whatever stands nearer below it.
    """
    mount = plain(T_base_sensor, np.float64)
    origin = mount[:2, 3].copy()
    stack = plain(stack, np.float32)
    _, xy, valid, _ = band_kernels().base_positions(stack, mount, UPRIGHT_CELL)
    ends = band_kernels().farthest_ends(xy, valid, float(origin[0]), float(origin[1]))
    if len(ends) > MAX_FREE_RAYS:
        ends = ends[_evenly_spread(len(ends))]
    return origin, ends


def finite_rows(points: Array) -> Array:
    """The rows of ``points`` (n x k) with no NaN or infinity: the returns a sensor had."""
    return points[np.isfinite(points).all(axis=1)]


def scan_free_rays(scan: Array, T_base_sensor: Array) -> tuple[Array, Array]:
    """A scanner's free rays: its position and its returns (n, 2, base frame), evenly sampled.

    Every beam of a 2-D scanner ends where it met something, at the one height it sees.
    """
    origin = np.asarray(T_base_sensor, dtype=np.float64)[:2, 3].copy()
    ends = finite_rows(scan)
    if len(ends) > MAX_FREE_RAYS:
        ends = ends[_evenly_spread(len(ends))]
    return origin, ends


@functools.lru_cache(maxsize=1024)
def _evenly_spread(count: int) -> NDArray[np.intp]:
    """MAX_FREE_RAYS indices spread evenly over ``count``, both ends included."""
    return np.linspace(0, count - 1, MAX_FREE_RAYS).round().astype(np.intp)


def select_scan(
    points: NDArray[np.float32], T_base_sensor: Array, how: RowSelection, stacked: bool = False
) -> Array:
    """The scan row as 2-D points in the base frame (columns x 2, NaN for no point)."""
    return to_base_xy(select_points(points, T_base_sensor, how, stacked), T_base_sensor)


class CloudFrame(Protocol):
    """What ``finite_scan`` reads of a frame: a player's ``SensorFrame`` or a wire ``Frame``.

    A protocol because this layer sees neither class: the player's is a service's.
    """

    @property
    def points(self) -> NDArray[np.float32]:
        """The sensor-frame points: a whole cloud, a scan, or the band's stack."""
        ...

    @property
    def T_base_sensor(self) -> Array:
        """The sensor's mount in the base frame."""
        ...

    @property
    def band(self) -> tuple[float, float] | None:
        """The band ``points`` is the stack of, or None when it is no stack."""
        ...


def finite_scan(frame: CloudFrame, how: RowSelection) -> Array:
    """A frame's scan row with only the points it has (n x 2, base frame).

    What scan matching reads of a frame, the same whether the odometry service, the in-process
    pipeline or a script asks: a frame with a band carries the stack the player picked.
    """
    scan = select_scan(frame.points, frame.T_base_sensor, how, frame.band is not None)
    return finite_rows(scan)
