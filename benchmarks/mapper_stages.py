"""Where a frame's mapper time goes: ``Mapping.integrate`` and its parts, per frame, in process.

A generated scene's 320x240 16UC1 depth bag (the issue-26 bag) goes through the offline runner
(the services' code in one process, ``wallmap.offline``), with tf poses judged by the walls as
the mapper does by default. Each part is timed where the mapper calls it, with ``perf_counter``
around the method; the table gives the median per frame and the mean (the latency estimate runs
every tenth turn, so its median is nearly nothing and its mean is what it costs). The mapper's
compiled loops are loaded first, as the service loads them before it says it is ready: else
the first frames would time numba reading its cache.

    .venv/bin/python benchmarks/mapper_stages.py [--frames 784]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

from floor_ratio import write_depth_bag

from wallmap.common import compiled
from wallmap.offline import run_bag
from wallmap.services.mapper.mapping import Mapping
from wallmap.services.mapper.pose_judge import PoseJudge
from wallmap.services.mapper.room_map import RoomMap
from wallmap.services.mapper.wall_map import WallMap

# (what, class, method): the parts, outermost first; each is timed wherever it is called.
PARTS = (
    ("the whole: judge, walls, rooms' frame", Mapping, "integrate"),
    ("pose judge (latency, association, fit)", PoseJudge, "judge"),
    ("...the latency's turns and estimate", PoseJudge, "_learn_latency"),
    ("walls: association, EKF updates, merges", WallMap, "integrate"),
    ("...rays seen through walls", WallMap, "finish_frame"),
    ("rooms: the frame's rays on the floor grid", RoomMap, "add_frame"),
)


def _timed(spent: dict[str, float], name: str, method: Callable[..., Any]) -> Callable[..., Any]:
    def timed(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return method(*args, **kwargs)
        finally:
            spent[name] += time.perf_counter() - start

    return timed


def measure(bag: Path) -> dict[str, list[float]]:
    """Each part's seconds, per frame the mapper integrated."""
    compiled.compile_mapper()
    spent: dict[str, float] = defaultdict(float)
    per_frame: dict[str, list[float]] = defaultdict(list)
    originals = [(cls, method, getattr(cls, method)) for _, cls, method in PARTS]
    for (name, cls, method), (_, _, original) in zip(PARTS, originals, strict=True):
        setattr(cls, method, _timed(spent, name, original))
    whole = Mapping.integrate

    def frame(self: Mapping, *args: Any) -> Any:
        spent.clear()
        try:
            return whole(self, *args)
        finally:
            for name, _, _ in PARTS:
                per_frame[name].append(spent[name])

    Mapping.integrate = frame  # type: ignore[method-assign]
    try:
        run_bag(bag)
    finally:
        for cls, method, original in originals:
            setattr(cls, method, original)
    return per_frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=784)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        per_frame = measure(write_depth_bag(Path(folder) / "depth", args.frames))
    frames = len(per_frame[PARTS[0][0]])
    print(f"{frames} frames of 320x240 depth16, tf poses judged\n")
    print("| part | ms / frame (median) | mean |\n|---|---:|---:|")
    for name, _, _ in PARTS:
        times = per_frame[name]
        median, mean = 1e3 * statistics.median(times), 1e3 * statistics.fmean(times)
        print(f"| {name} | {median:.3f} | {mean:.3f} |")


if __name__ == "__main__":
    main()
