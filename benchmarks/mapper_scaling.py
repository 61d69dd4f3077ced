"""Association + EKF update per observation against the number of walls in the map.

The paper's figures 6 and 7 show data association and the EKF update against the number of
walls. Here a map of N walls (a grid of square rooms, 4 walls each) is built, then a robot drives
through one room observing its walls; the median time per observation is printed per N, as the
mapper runs by default (the poses as they come) and with ``--slam`` (the poses taken as odometry,
the pose and a window of walls estimated jointly), side by side on the same map.

    .venv/bin/python benchmarks/mapper_scaling.py [--sizes 10,100,1000,10000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from wallmap.common import se2
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.services.mapper.pose_correction import PoseCorrector
from wallmap.services.mapper.wall_map import WallMap

ROOM = 4.0  # m


def room_walls(i: int, j: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The four walls of room (i, j), 1.2 m apart, so no two rooms share a wall line."""
    x0, y0, x1, y1 = i * ROOM + 0.6, j * ROOM + 0.6, (i + 1) * ROOM - 0.6, (j + 1) * ROOM - 0.6
    corners = [np.array(c) for c in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
    return [(corners[k], corners[(k + 1) % 4]) for k in range(4)]


def observe(
    a: np.ndarray, b: np.ndarray, pose: np.ndarray, rng: np.random.Generator
) -> WallObservation:
    """The detector's view of wall a-b from pose, with 1 cm noise."""
    rot = se2.rotation(pose[2])
    d = (b - a) / np.linalg.norm(b - a)
    foot = a + ((pose[:2] - a) @ d) * d
    z = rot.T @ (foot - pose[:2]) + rng.normal(0, 0.01, 2)
    ends = [rot.T @ (p - pose[:2]) for p in (a, b)]
    return WallObservation(z, np.eye(2) * 1e-4, ends[0], ends[1], 60, 0.01)


def build(n_walls: int, rng: np.random.Generator) -> WallMap:
    """A map of about n_walls walls, each seen 4 times from its room's centre area."""
    wall_map = WallMap()
    side = max(1, round(np.sqrt(n_walls / 4)))
    stamp = 0.0
    for i in range(side):
        for j in range(side):
            for k in range(4):
                centre = np.array([(i + 0.5) * ROOM + 0.3 * (k - 1.5), (j + 0.5) * ROOM, 0.0])
                obs = [observe(a, b, centre, rng) for a, b in room_walls(i, j)]
                stamp += 0.1
                wall_map.integrate(
                    Observations("b", 0, stamp, "base_link", obs), Pose(stamp, *centre)
                )
    return wall_map


def time_per_observation(
    wall_map: WallMap,
    rng: np.random.Generator,
    frames: int = 200,
    corrector: PoseCorrector | None = None,
) -> float:
    """Median seconds per observation while driving around one room in the middle."""
    side = round(np.sqrt(len(wall_map.walls) / 4))
    i = j = side // 2
    centre = np.array([(i + 0.5) * ROOM, (j + 0.5) * ROOM])
    times = []
    stamp = 1e6
    for step in range(frames):
        angle = 2 * np.pi * step / frames
        pose = np.array([*(centre + 0.8 * np.array([np.cos(angle), np.sin(angle)])), angle])
        obs = [observe(a, b, pose, rng) for a, b in room_walls(i, j)]
        stamp += 0.1
        frame = Observations("t", step, stamp, "base_link", obs)
        start = time.perf_counter()
        if corrector is None:
            wall_map.integrate(frame, Pose(stamp, *pose))
        else:
            corrector.integrate(frame, Pose(stamp, *pose), wall_map)
        times.append((time.perf_counter() - start) / len(obs))
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,100,1000,10000")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'walls':>7} {'us/observation':>15} {'--slam':>8} {'ratio':>6} {'walls after':>12}")
    for size in (int(s) for s in args.sizes.split(",")):
        wall_map = build(size, rng)
        n = len(wall_map.walls)
        plain = time_per_observation(wall_map, rng)
        slam = time_per_observation(wall_map, rng, corrector=PoseCorrector())
        print(
            f"{n:>7} {plain * 1e6:>15.1f} {slam * 1e6:>8.1f} {slam / plain:>6.2f} "
            f"{len(wall_map.walls):>12}",
            flush=True,
        )


if __name__ == "__main__":
    main()
