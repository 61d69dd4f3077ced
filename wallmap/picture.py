"""A picture of the wall map over the trajectory, as SVG (no plotting library needed)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

SIZE = 900  # px, the longer side
MARGIN = 40


def write_svg(path: Path, walls: Sequence[dict[str, Any]], trajectory: np.ndarray) -> None:
    """Draw walls (with ids) and the trajectory (N x 2, map frame) to an SVG file."""
    points = [np.array([w["p0"], w["p1"]]) for w in walls]
    everything = np.vstack([*points, trajectory.reshape(-1, 2), np.zeros((1, 2))])
    lo, hi = everything.min(axis=0) - 0.5, everything.max(axis=0) + 0.5
    scale = (SIZE - 2 * MARGIN) / max(float((hi - lo).max()), 1e-6)
    width, height = ((hi - lo) * scale + 2 * MARGIN).astype(int)

    def px(p: np.ndarray) -> tuple[float, float]:
        return MARGIN + (p[0] - lo[0]) * scale, height - MARGIN - (p[1] - lo[1]) * scale

    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" font-family="sans-serif">',
        f'<rect width="{width}" height="{height}" fill="white"/>',
    ]
    if len(trajectory) > 1:
        path_d = " ".join(f"{x:.1f},{y:.1f}" for x, y in map(px, trajectory))
        out.append(f'<polyline points="{path_d}" fill="none" stroke="#8aa" stroke-width="1.5"/>')
    for w, seg in zip(walls, points, strict=True):
        (x0, y0), (x1, y1) = px(seg[0]), px(seg[1])
        out.append(
            f'<line x1="{x0:.1f}" y1="{y0:.1f}" x2="{x1:.1f}" y2="{y1:.1f}" '
            'stroke="#c22" stroke-width="3" stroke-linecap="round"/>'
        )
        mx, my = (x0 + x1) / 2, (y0 + y1) / 2
        out.append(f'<text x="{mx:.1f}" y="{my - 4:.1f}" font-size="11">{w["id"]}</text>')
    bar = 1.0 * scale
    out.append(
        f'<line x1="{MARGIN}" y1="{height - 15}" x2="{MARGIN + bar:.1f}" y2="{height - 15}" '
        'stroke="black" stroke-width="2"/>'
        f'<text x="{MARGIN + bar + 6:.1f}" y="{height - 11}" font-size="11">1 m</text>'
    )
    out.append("</svg>")
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
