"""Where a depth frame's detector time goes: each stage of ``WallDetector.detect``, timed alone.

A generated scene's 320x240 16UC1 depth bag (the issue-26 bag's size) is read as the player sends
it (the band's rows, 6 heights per column), then every frame goes through the detector's stages
one by one, in the order ``detect`` runs them, each timed with ``perf_counter``; the table gives
each stage's median per frame and its share of the whole. The stages are the detector's own
functions, so the sum is ``detect`` less its bookkeeping (the observations built, the noise
learned).

    .venv/bin/python benchmarks/detector_stages.py [--frames 300] [--width 320 --height 240]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from wallmap.common.ransac import detect_lines
from wallmap.common.scan_row import frame_stack, free_rays, to_base_xy, upright_points
from wallmap.config import Config
from wallmap.offline import pipeline_for, played
from wallmap.scene import Camera, write_scene_bag


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--sensor", default="depth16", choices=("depth16", "pointcloud"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "depth"
        camera = Camera(width=args.width, height=args.height)
        write_scene_bag(
            bag, seed=7, n_frames=args.frames, fmt="ros2-mcap", sensor=args.sensor, camera=camera
        )
        config = Config()
        pipeline = pipeline_for(config)
        frames = list(played(bag, config, pipeline))
    detector = pipeline.detector
    stages: dict[str, list[float]] = {k: [] for k in ("stack", "upright", "row", "rays", "lines")}
    whole: list[float] = []
    for frame in frames:
        mount = frame.T_base_sensor
        clock = time.perf_counter()
        stacked = frame.band is not None
        stack = frame_stack(frame.points, mount, detector.config.rows, stacked=stacked)
        marks = [time.perf_counter()]
        row = stack[0] if stack.shape[0] == 1 else upright_points(stack, mount)
        marks.append(time.perf_counter())
        scan = to_base_xy(row, mount)
        marks.append(time.perf_counter())
        free_rays(stack, mount)
        marks.append(time.perf_counter())
        base = detector.config.ransac
        params = base.scaled(detector.noise["depth"].scale)
        detect_lines(scan, params, np.random.default_rng((detector.config.seed, frame.seq)))
        marks.append(time.perf_counter())
        for name, start, end in zip(stages, [clock, *marks[:-1]], marks, strict=True):
            stages[name].append(end - start)
        start = time.perf_counter()
        detector.detect(frame)
        whole.append(time.perf_counter() - start)
    total = statistics.median(whole)
    print(
        f"{len(frames)} frames of {args.width}x{args.height} {args.sensor}, "
        f"{frames[0].points.shape[0]} heights a column\n"
    )
    print("| stage | what | ms / frame (median) | share of detect |")
    print("|---|---|---:|---:|")
    what = {
        "stack": "the band's heights per column (frame_stack)",
        "upright": "what rises through the band (upright_points)",
        "row": "the row in the base frame (to_base_xy)",
        "rays": "free space (free_rays)",
        "lines": "split at NaN, sequential RANSAC, refits (detect_lines)",
    }
    for name, times in stages.items():
        median = statistics.median(times)
        print(f"| {name} | {what[name]} | {1e3 * median:.3f} | {median / total:.0%} |")
    print(f"| detect | the whole, as the service runs it | {1e3 * total:.3f} | 100% |")


if __name__ == "__main__":
    main()
