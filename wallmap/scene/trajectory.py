"""Sensor trajectories through a floor plan, drifting odometry estimates of them, TUM files."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wallmap.common import se2
from wallmap.scene.floorplan import FloorPlan, smooth_route

_RAMP_S = 1.0  # time to accelerate from rest to cruise speed (and to stop again)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Planar poses of base_link at increasing stamps (seconds since the epoch)."""

    stamps: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def positions(self) -> np.ndarray:
        """Where base_link was, (n, 2): the path the robot drove."""
        return np.column_stack([self.x, self.y])

    def pose_at(self, i: int) -> tuple[float, float, float]:
        """Pose (x, y, yaw) of sample ``i``."""
        return float(self.x[i]), float(self.y[i]), float(self.yaw[i])

    def sliced(self, index: slice) -> Trajectory:
        """The samples selected by ``index``, e.g. ``slice(None, None, 2)`` for every other."""
        return Trajectory(self.stamps[index], self.x[index], self.y[index], self.yaw[index])

    def relative_to(self, origin: tuple[float, float, float]) -> Trajectory:
        """The same poses in the frame that pose ``origin`` places: ``origin^-1 * pose`` each.

        A robot's map starts where it was switched on, not in the building's frame; its poses
        relative to its first one are what it would have published.
        """
        x0, y0, yaw0 = origin
        x, y = se2.unrotate((self.x - x0, self.y - y0), yaw0)
        return Trajectory(self.stamps.copy(), x, y, se2.wrap(self.yaw - yaw0))

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form for ground-truth files."""
        return {
            "stamps": self.stamps.tolist(),
            "x": self.x.tolist(),
            "y": self.y.tolist(),
            "yaw": self.yaw.tolist(),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Trajectory:
        """Inverse of :meth:`to_json`."""
        return cls(*(np.asarray(data[k], dtype=float) for k in ("stamps", "x", "y", "yaw")))


def _arc_length_at(t: np.ndarray, duration: float, speed: float) -> np.ndarray:
    """Distance driven at time t: linear ramps up and down, cruise in between (C1 in t)."""
    s = speed * (t - _RAMP_S / 2)
    start = t < _RAMP_S
    s[start] = speed * t[start] ** 2 / (2 * _RAMP_S)
    end = t > duration - _RAMP_S
    rest = duration - t[end]
    s[end] = speed * (duration - _RAMP_S) - speed * rest**2 / (2 * _RAMP_S)
    return s


def _path(plan: FloorPlan, *, reverse: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The smoothed route, driven forward or ``reverse``: points (K, 2), arc length and heading.

    Repeated points are dropped, so that the arc length increases and the heading is defined
    everywhere.
    """
    # Corner cutting is symmetric: the reversed route's curve is the forward one, reversed.
    curve = smooth_route(plan.route[::-1] if reverse else plan.route)
    steps = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    keep = np.concatenate([[True], steps > 1e-9])
    curve = curve[keep]
    s_curve = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    tangent = np.gradient(curve, s_curve, axis=0)
    return curve, s_curve, np.unwrap(np.arctan2(tangent[:, 1], tangent[:, 0]))


def generate_trajectory(
    plan: FloorPlan,
    seed: int,
    *,
    rate_hz: float = 15.0,
    speed: float = 0.4,
    start_stamp: float = 1_700_000_000.0,
    sweep_deg: float = 60.0,
    reverse: bool = False,
) -> Trajectory:
    """Drive once along the plan's route, sweeping the sensor left and right.

    The path is the smoothed route (see :func:`smooth_route`), which the plan generator
    keeps at least 0.7 m from walls and 0.85 m from furniture. Speed ramps up from rest
    and back down in 1 s, so velocity is continuous. The yaw is the path heading plus a
    sinusoidal sweep of +-``sweep_deg`` (random period 7-10 s and phase), so that side
    walls are seen and not only the walls ahead. The path depends only on the plan; the
    seed changes the sweep. Sampling the same plan and seed at another rate gives samples
    of the same continuous trajectory. ``reverse`` drives the same path the other way, as a
    second robot mapping the same building would: from rest at the route's end, facing along
    the path, to rest at its start.

    Args:
        plan: Plan with a route.
        seed: Random seed for the sweep.
        rate_hz: Sample rate.
        speed: Cruise speed in m/s.
        start_stamp: Stamp of the first sample, seconds.
        sweep_deg: Amplitude of the yaw sweep around the heading.
        reverse: Drive the route from its last waypoint to its first.

    Returns:
        The trajectory, sampled from rest at the route's start to rest at its end (or from
        its end to its start, if ``reverse``).

    Raises:
        ValueError: If the plan has no route.
    """
    if len(plan.route) < 2:
        raise ValueError("the plan has no route to drive along")
    curve, s_curve, heading_curve = _path(plan, reverse=reverse)
    length = float(s_curve[-1])

    duration = length / speed + _RAMP_S
    t = np.arange(math.floor(duration * rate_hz) + 1) / rate_hz
    s = np.clip(_arc_length_at(t, duration, speed), 0.0, length)

    rng = np.random.default_rng(seed)
    period = rng.uniform(7.0, 10.0)
    phase = rng.uniform(0.0, 2 * math.pi)
    sweep = math.radians(sweep_deg) * np.sin(2 * math.pi * t / period + phase)
    return Trajectory(
        stamps=start_stamp + t,
        x=np.interp(s, s_curve, curve[:, 0]),
        y=np.interp(s, s_curve, curve[:, 1]),
        yaw=se2.wrap(np.interp(s, s_curve, heading_curve) + sweep),
    )


def _slow_noise(rng: np.random.Generator, distance: np.ndarray) -> np.ndarray:
    """A smooth random function of distance travelled with magnitude about 1.

    A constant bias plus a few slow sinusoids (wavelengths 3-12 m), like calibration
    errors that vary with the floor: it is smooth so that map→odom changes smoothly and a
    tf buffer interpolating it between 10 Hz samples stays exact to well under 1 mm.
    """
    value = np.full_like(distance, rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0))
    for _ in range(3):
        wavelength = rng.uniform(3.0, 12.0)
        value += rng.normal(0.0, 0.3) * np.sin(
            2 * math.pi * distance / wavelength + rng.uniform(0, 2 * math.pi)
        )
    return value


def drifting_odometry(
    traj: Trajectory, seed: int, *, drift_xy: float = 0.02, drift_yaw_deg: float = 1.0
) -> Trajectory:
    """An odometry estimate of ``traj`` that drifts, starting at its true first pose.

    The true motion between consecutive samples is taken in the body frame, corrupted and
    re-integrated: forward and lateral motion get a scale error of about ``drift_xy``
    (plus a lateral slip of ``drift_xy`` per metre), heading gets about ``drift_yaw_deg``
    of error per metre driven. The errors vary slowly with distance (see
    :func:`_slow_noise`), so the drift accumulates without jitter.

    Args:
        traj: True trajectory.
        seed: Random seed for the errors.
        drift_xy: Position error per metre driven (0.02 = 2 %).
        drift_yaw_deg: Heading error in degrees per metre driven.

    Returns:
        The odometry trajectory, same stamps as ``traj``.
    """
    rng = np.random.default_rng(seed)
    dx, dy = np.diff(traj.x), np.diff(traj.y)
    dyaw = np.diff(np.unwrap(traj.yaw))
    forward, lateral = se2.unrotate((dx, dy), traj.yaw[:-1])  # each step in the body frame
    step = np.hypot(dx, dy)
    travelled = np.concatenate([[0.0], np.cumsum(step)])[:-1] + step / 2

    scale = 1.0 + drift_xy * _slow_noise(rng, travelled)
    slip = drift_xy * _slow_noise(rng, travelled)
    yaw_rate = math.radians(drift_yaw_deg) * _slow_noise(rng, travelled)

    odo_yaw = traj.yaw[0] + np.concatenate([[0.0], np.cumsum(dyaw + yaw_rate * step)])
    fwd_o, lat_o = forward * scale, lateral * scale + slip * step
    step_x, step_y = se2.rotate((fwd_o, lat_o), odo_yaw[:-1])  # back into the odometry frame
    odo_x = traj.x[0] + np.concatenate([[0.0], np.cumsum(step_x)])
    odo_y = traj.y[0] + np.concatenate([[0.0], np.cumsum(step_y)])
    return Trajectory(traj.stamps.copy(), odo_x, odo_y, se2.wrap(odo_yaw))


def write_tum(trajectory: Trajectory, path: str | Path) -> None:
    """Write a trajectory in the TUM RGB-D format, for evaluation tools and ``tum:FILE``.

    One line per pose, ``t x y z qx qy qz qw``: stamp in seconds with nanosecond digits so
    that it matches the bag's header stamps, z = 0 and the quaternion (scalar last) of a
    rotation by yaw about z. A ``#`` line names the columns.
    """
    half = trajectory.yaw / 2
    rows = np.column_stack(
        [
            trajectory.x,
            trajectory.y,
            np.zeros(len(trajectory)),
            np.zeros(len(trajectory)),
            np.zeros(len(trajectory)),
            np.sin(half),
            np.cos(half),
        ]
    )
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    lines += [
        f"{stamp:.9f} " + " ".join(f"{v:.9f}" for v in row)
        for stamp, row in zip(trajectory.stamps, rows, strict=True)
    ]
    Path(path).write_text("\n".join(lines) + "\n")


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM trajectory file as planar poses; z and any roll or pitch are dropped."""
    data = np.loadtxt(path, comments="#", ndmin=2)
    qx, qy, qz, qw = data[:, 4:8].T
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return Trajectory(data[:, 0], data[:, 1], data[:, 2], yaw)
