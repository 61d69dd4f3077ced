"""`make bench`: the performance benchmarks, one after the other, each printing its table.

Accuracy (benchmarks/accuracy.py) and the row choice (benchmarks/row_choice.py) take minutes and
are run on their own; see docs/accuracy.md and docs/detector.md.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCRIPTS = [
    ("detector per frame on 640-point rows, against scikit-learn", ["detector_speed.py"]),
    ("where a 320x240 depth frame's detector time goes, stage by stage", ["detector_stages.py"]),
    (
        "...and a 640x480 point cloud's",
        [
            "detector_stages.py",
            "--sensor",
            "pointcloud",
            "--width",
            "640",
            "--height",
            "480",
            "--frames",
            "150",
        ],
    ),
    ("where a 320x240 depth frame's mapper time goes, part by part", ["mapper_stages.py"]),
    ("association + EKF update per observation", ["mapper_scaling.py"]),
    ("map/walls query latency, 10 concurrent clients", ["query_latency.py"]),
    ("end to end, 30 Hz 640x480 PointCloud2, against the read floor", ["end_to_end.py"]),
    ("end to end, the same bag LZ4-compressed", ["end_to_end.py", "--compress"]),
    ("the issue-26 bags against the read floor, 3 rounds", ["floor_ratio.py"]),
    ("the data path alone (the messages, no work) against the read floor", ["data_path.py"]),
    ("memory of each service over four bags", ["memory.py"]),
    ("start-up of each service", ["startup.py"]),
    ("the paper's four timing figures (SVG)", ["figures.py", "--out", "../docs/figures"]),
]


def main() -> None:
    for title, command in SCRIPTS:
        print(f"\n== {title}", flush=True)
        subprocess.run([sys.executable, *command], cwd=HERE, check=True)


if __name__ == "__main__":
    main()
