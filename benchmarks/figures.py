"""The paper's four timing figures, for this implementation, as SVG charts.

One generated drive is mapped in one process with the real detector and mapper; per frame it
records the detector's time, the time spent in data association (the walls near each
observation, scored on their innovations) and in EKF updates, the total, and the number of
walls in the map. The association and update times are measured by wrapping ``WallMap.match``
and the compiled update here, in the benchmark, not in the code.

    .venv/bin/python benchmarks/figures.py [--frames 600] [--out docs/figures]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wallmap.common import compiled
from wallmap.scene import write_scene_bag
from wallmap.services.detector.detector import DetectorConfig, WallDetector
from wallmap.services.mapper.wall_map import WallMap
from wallmap.services.player.bag_source import BagSource

W, H, M = 640, 400, 60  # chart size and margin, px


def timed(function: Callable[..., object], bucket: list[float]) -> Callable[..., object]:
    def wrapper(*args: object) -> object:
        start = time.perf_counter()
        try:
            return function(*args)
        finally:
            bucket.append(time.perf_counter() - start)

    return wrapper


def chart(
    path: Path, title: str, xlabel: str, ylabel: str, x: np.ndarray, ys: dict[str, np.ndarray]
) -> None:
    """A plain SVG line chart with axes, ticks and a legend."""
    colours = ["#c22", "#25a", "#2a5", "#a52"]
    x_max = float(x.max()) or 1.0
    y_max = max(float(np.nanmax(y)) for y in ys.values()) * 1.1 or 1.0

    def px(v: float) -> float:
        return M + (W - 2 * M) * v / x_max

    def py(v: float) -> float:
        return H - M - (H - 2 * M) * v / y_max

    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}"'
        ' font-family="sans-serif" font-size="12">',
        f'<rect width="{W}" height="{H}" fill="white"/>',
        f'<text x="{W / 2}" y="22" text-anchor="middle" font-size="15">{title}</text>',
        f'<line x1="{M}" y1="{H - M}" x2="{W - M}" y2="{H - M}" stroke="black"/>',
        f'<line x1="{M}" y1="{M}" x2="{M}" y2="{H - M}" stroke="black"/>',
        f'<text x="{W / 2}" y="{H - 18}" text-anchor="middle">{xlabel}</text>',
        f'<text x="16" y="{H / 2}" text-anchor="middle"'
        f' transform="rotate(-90 16 {H / 2})">{ylabel}</text>',
    ]
    for k in range(6):
        xv, yv = x_max * k / 5, y_max * k / 5
        out.append(f'<text x="{px(xv):.0f}" y="{H - M + 16}" text-anchor="middle">{xv:.0f}</text>')
        out.append(f'<text x="{M - 6}" y="{py(yv) + 4:.0f}" text-anchor="end">{yv:.2f}</text>')
    for row, ((name, y), colour) in enumerate(zip(ys.items(), colours, strict=False)):
        points = " ".join(
            f"{px(a):.1f},{py(b):.1f}" for a, b in zip(x, y, strict=True) if np.isfinite(b)
        )
        out.append(
            f'<polyline points="{points}" fill="none" stroke="{colour}" stroke-width="1.2"/>'
        )
        legend = M + 16 * (row + 1)
        out.append(f'<text x="{W - M - 150}" y="{legend}" fill="{colour}">{name}</text>')
    out.append("</svg>")
    path.write_text("\n".join(out) + "\n", encoding="utf-8")


def binned(walls: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Median of ``values`` per number of walls."""
    keys = np.unique(walls)
    return keys, np.array([np.median(values[walls == k]) for k in keys])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    association: list[float] = []
    updates: list[float] = []
    # Association: the walls near each observation and their scores (``WallMap.match``); the
    # update: the chosen wall's EKF update (the compiled loop ``WallMap`` calls).
    WallMap.match = timed(WallMap.match, association)  # type: ignore[method-assign]
    compiled.compile_detector()  # the loops loaded, as the services load them before frames
    compiled.compile_mapper()
    kernels = compiled.map_kernels()
    kernels.update = timed(kernels.update, updates)
    detector, wall_map = WallDetector(DetectorConfig()), WallMap()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        info = write_scene_bag(
            Path(tmp) / "s.bag", seed=21, n_frames=args.frames, fmt="ros1", sensor="depth16"
        )
        with BagSource(info.path) as source:
            for seq, (frame, pose) in enumerate(source.frames()):
                message = frame.to_frame(run="fig", seq=seq, sensor="depth")
                association.clear()
                updates.clear()
                start = time.perf_counter()
                observations = detector.detect(message)
                detected = time.perf_counter()
                wall_map.integrate(observations, pose)
                done = time.perf_counter()
                rows.append(
                    (
                        seq,
                        len(wall_map.walls),
                        detected - start,
                        sum(association),
                        sum(updates),
                        done - start,
                    )
                )
    seq, walls, det, assoc, upd, total = (np.array(c, dtype=float) for c in zip(*rows, strict=True))
    ms = 1e3
    per_step = {"total": total, "detector": det, "association": assoc, "EKF update": upd}
    chart(
        args.out / "time-per-timestep.svg",
        "Execution time per timestep",
        "frame",
        "ms",
        seq,
        {name: values * ms for name, values in per_step.items()},
    )
    for name, values, title in (
        ("association-vs-walls.svg", assoc, "Data association per frame vs walls in the map"),
        ("ekf-update-vs-walls.svg", upd, "EKF updates per frame vs walls in the map"),
        ("total-vs-walls.svg", total, "Total per frame vs walls in the map"),
    ):
        keys, medians = binned(walls, values * ms)
        chart(args.out / name, title, "walls in the map", "ms (median)", keys, {"median": medians})
    print(f"{len(rows)} frames, up to {int(walls.max())} walls; figures in {args.out}/")
    print(f"{'per frame':<12} {'median ms':>10} {'p99 ms':>8}")
    for name, values in (
        ("detector", det),
        ("association", assoc),
        ("EKF update", upd),
        ("total", total),
    ):
        median, p99 = statistics.median(values) * ms, np.percentile(values, 99) * ms
        print(f"{name:<12} {median:>10.3f} {p99:>8.3f}")


if __name__ == "__main__":
    main()
