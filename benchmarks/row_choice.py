"""Which scan row should the detector use? The paper's fixed upper row against a height band.

Generated scenes with furniture below the band and a ceiling above it, a level camera and one
tilted up by 8 degrees. Prints precision, recall and duplicates per choice (median over scenes).

    .venv/bin/python benchmarks/row_choice.py [--seeds 1,2,3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from wallmap.common.scan_row import RowSelection
from wallmap.config import Config
from wallmap.evaluation import evaluate_map
from wallmap.offline import map_bag, walls
from wallmap.scene import Camera, write_scene_bag
from wallmap.services.detector.detector import DetectorConfig

CHOICES = {
    "band 1.3-2.1 m (default)": RowSelection(mode="band", band=(1.3, 2.1)),
    "row at 10% from the top": RowSelection(mode="row", row_fraction=0.10),
    "row at 25% from the top": RowSelection(mode="row", row_fraction=0.25),
    "row at 40% from the top": RowSelection(mode="row", row_fraction=0.40),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1,2,3,4,5")
    parser.add_argument("--frames", type=int, default=400)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"{'camera':<12} {'row choice':<28} {'precision':>9} {'recall':>7} {'dups':>5}")
    with tempfile.TemporaryDirectory() as tmp:
        for tilt in (0.0, 8.0):
            bags = []
            for seed in seeds:
                bag = Path(tmp) / f"s{seed}_t{tilt:.0f}.bag"
                info = write_scene_bag(
                    bag,
                    seed=seed,
                    n_frames=args.frames,
                    fmt="ros1",
                    sensor="depth16",
                    camera=Camera(tilt_deg=tilt),
                )
                bags.append(info)
            for name, rows in CHOICES.items():
                scores = [
                    evaluate_map(
                        walls(map_bag(info.path, Config(detector=DetectorConfig(rows=rows)))),
                        info.plan,
                        info.seen_counts,
                    )
                    for info in bags
                ]
                print(
                    f"{f'tilt {tilt:.0f} deg':<12} {name:<28}"
                    f" {statistics.median(s.precision for s in scores):>9.3f}"
                    f" {statistics.median(s.recall for s in scores):>7.3f}"
                    f" {sum(s.duplicates for s in scores):>5}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
