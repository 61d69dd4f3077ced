"""What the detector says about a row: the thresholds that turned candidates down, by name."""

from __future__ import annotations

import numpy as np
import pytest

from wallmap.common.ransac import RansacParams, RowReport, detect_lines


def _row() -> np.ndarray:
    """A 3 m wall 2 m ahead, a NaN, a 10 cm stub of 15 points, a NaN, and 5 stray points."""
    rng = np.random.default_rng(4)
    wall = np.column_stack([np.full(150, 2.0), np.linspace(-1.5, 1.5, 150)])
    stub = np.column_stack([np.full(15, 3.0), np.linspace(2.0, 2.1, 15)])
    strays = rng.uniform(4, 5, (5, 2))
    gap = np.full((1, 2), np.nan)
    row = np.vstack([wall, gap, stub, gap, strays])
    return row + rng.normal(0, 0.002, row.shape) * [1, 0]


def test_row_report_names_the_thresholds() -> None:
    report = RowReport()
    lines = detect_lines(_row(), RansacParams(), np.random.default_rng(0), report)
    assert len(lines) == 1
    assert report.points == 170
    assert report.clusters == [150, 15, 5]
    assert report.lines[0]["points"] >= 140
    assert report.lines[0]["length"] == pytest.approx(3.0, abs=0.05)
    assert report.rejected["shorter than min_length"] == 1  # the stub
    assert report.rejected["cluster below min_points"] == 1  # the strays
    assert set(report.to_map()) == {"points", "clusters", "lines", "rejected"}
