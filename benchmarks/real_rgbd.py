"""Real RGB-D recordings (../shared/data/real/rgbd), brought in the three ways users have them.

Per recording and way: frames integrated, confirmed walls, fans (two confirmed walls within 8
degrees and 30 cm, overlapping more than 0.3 m: one surface mapped as several lines),
duplicates (within 3 degrees and 10 cm), the share of the points seen 0.9-1.6 m above the floor
that lie within 5 cm of a confirmed wall, and the time per frame; a picture of each map over
those points. The ways: the TUM folder itself (6-DoF camera trajectory, frame not level); a ROS 1
bag with a 6-DoF tf `map -> camera_link`; a ROS 1 bag with a planar `map -> base_link` and a
tilting `base_link -> camera_link` on /tf (made from the folder, levelled as wallmap levels it).

Runs the services' code in one process (`wallmap.offline.map_bag`); tests/e2e/test_real_rgbd.py
runs the same recordings through the real services.

    .venv/bin/python benchmarks/real_rgbd.py [--out docs/figures]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from wallmap.common.map_consistency import MappedWall, distance_to_walls, duplicates, fans
from wallmap.common.map_query import MapQuery
from wallmap.config import Config
from wallmap.offline import map_bag, points_at_heights, walls
from wallmap.plot import write_picture
from wallmap.recordings import RGBD, tum_as_bag
from wallmap.services.mapper import serving
from wallmap.services.player.settings import PlayerSettings
from wallmap.services.player.sources import SourceSettings


def row(name: str, way: str, recording: Path, options: SourceSettings, out: Path | None) -> None:
    config = Config(player=PlayerSettings(source=options))
    start = time.perf_counter()
    wall_map = map_bag(recording, config)
    seconds = time.perf_counter() - start
    served = walls(wall_map, min_obs=3)
    mapped = [MappedWall.from_reply(w) for w in served]
    seen = points_at_heights(recording, source=options)
    on_walls = float((distance_to_walls(seen, mapped) < 0.05).mean()) if len(seen) else 0.0
    frames = wall_map.frames
    print(
        f"{name:<20} {way:<22} {frames:>7} {len(served):>6} {len(fans(mapped)):>5} "
        f"{len(duplicates(mapped)):>5} {100 * on_walls:>8.0f} % {1e3 * seconds / frames:>8.1f}"
    )
    if out is not None:
        reply = serving.reply(wall_map, MapQuery(min_obs=3, trajectory=True))
        write_picture(out / f"real-{name}-{way}.png", reply, points=seen, size=800)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="folder for the pictures")
    args = parser.parse_args()
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    print(
        f"{'recording':<20} {'brought as':<22} {'frames':>7} {'walls':>6} {'fans':>5} "
        f"{'dups':>5} {'on walls':>10} {'ms/frame':>8}"
    )
    for name, (folder, camera) in RGBD.items():
        if not folder.is_dir():
            print(f"{name}: {folder} is absent")
            continue
        options = SourceSettings(intrinsics=camera.intrinsics, depth_scale=camera.depth_scale)
        row(name, "tum-folder", folder, options, args.out)
        with tempfile.TemporaryDirectory() as tmp:
            for way in ("tf-6dof", "planar-base"):
                bag = tum_as_bag(folder, Path(tmp) / f"{way}.bag", camera, way=way)
                row(name, way, bag, SourceSettings(), args.out)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
