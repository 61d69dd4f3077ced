"""Detector time per frame on 640-point rows, against a straightforward implementation.

The rows come from a generated scene rendered at 640x480 (the height band of each frame, in the
base frame). The straightforward implementation runs the paper's scheme with scikit-learn's
RANSACRegressor: split at NaN, then per cluster fit a line, drop its inliers, repeat. Both see the
same rows in the same run; medians per frame.

    .venv/bin/python benchmarks/detector_speed.py [--frames 40]

scikit-learn is read from .venv/bench-only, where `make bench` installs it, after the venv's own
packages: not in the venv, where numba would import its scipy at every service's start.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from wallmap.common.ransac import RansacConfig, detect_lines, split_at_nans
from wallmap.common.scan_row import RowSelection, select_scan
from wallmap.scene import (
    Camera,
    depth_to_points,
    generate_floorplan,
    generate_trajectory,
    render_depth,
)

BENCH_ONLY = Path(__file__).resolve().parents[1] / ".venv" / "bench-only"


def scene_rows(frames: int) -> list[np.ndarray]:
    """640-point scan rows (base frame, NaN for no point) along a generated drive."""
    camera = Camera(width=640, height=480)
    plan = generate_floorplan(3)
    trajectory = generate_trajectory(plan, 3)
    rng = np.random.default_rng(3)
    rows = []
    for i in np.linspace(0, len(trajectory) - 1, frames).astype(int):
        depth, _ = render_depth(plan, *trajectory.pose_at(i), camera, rng)
        points = depth_to_points(depth, camera)
        rows.append(select_scan(points, camera.T_base_camera, RowSelection()))
    return rows


def sklearn_lines(scan: np.ndarray, params: RansacConfig) -> int:
    """The paper's sequential scheme with scikit-learn's RANSAC; returns the lines found."""
    if str(BENCH_ONLY) not in sys.path:
        sys.path.append(str(BENCH_ONLY))  # after the venv's own packages
    # Imported here, where it is used: the rest of the script imports without it (a test
    # imports every benchmark), and `make bench` alone installs it.
    from sklearn.linear_model import RANSACRegressor  # noqa: PLC0415 - see above

    found = 0
    for cluster in split_at_nans(scan):
        points = scan[cluster]
        while len(points) >= params.min_points:
            centred = points - points.mean(axis=0)
            _, _, axes = np.linalg.svd(centred, full_matrices=False)
            local = centred @ axes.T  # the cluster's main direction along x
            model = RANSACRegressor(
                min_samples=2,
                residual_threshold=params.inlier_min,
                max_trials=params.iterations,
                random_state=0,
            )
            try:
                model.fit(local[:, :1], local[:, 1])
            except ValueError:  # no consensus
                break
            inliers = model.inlier_mask_
            if inliers.sum() < params.min_points:
                break
            found += 1
            points = points[~inliers]
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--passes", type=int, default=3)
    args = parser.parse_args()
    rows = scene_rows(args.frames)
    params = RansacConfig()
    rng = np.random.default_rng(0)
    ours, theirs, lines_ours, lines_theirs = [], [], [], []
    for _ in range(args.passes):  # alternating passes over all rows: a busy spell hits both
        for row in rows:
            start = time.perf_counter()
            lines_ours.append(len(detect_lines(row, params, rng)))
            ours.append(time.perf_counter() - start)
        for row in rows:
            start = time.perf_counter()
            lines_theirs.append(sklearn_lines(row, params))
            theirs.append(time.perf_counter() - start)
    mine, ref = statistics.median(ours), statistics.median(theirs)
    print(f"{'implementation':<36} {'ms/frame (median)':>18} {'lines/frame':>12}")
    for name, seconds, lines in (
        ("wallmap (compiled sequential RANSAC)", mine, lines_ours),
        ("scikit-learn RANSACRegressor", ref, lines_theirs),
    ):
        print(f"{name:<36} {seconds * 1e3:>18.2f} {np.mean(lines):>12.1f}")
    print(f"speed-up {ref / mine:.1f}x on {len(rows)} rows of {rows[0].shape[0]} points")


if __name__ == "__main__":
    main()
