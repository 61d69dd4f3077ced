"""What the detector says about a row: the thresholds that turned candidates down, by name."""

from __future__ import annotations

import numpy as np
import pytest
from rows import wall_stub_strays

from wallmap.common.ransac import RansacConfig, RowReport, detect_lines


def test_row_report_names_the_thresholds() -> None:
    report = RowReport()
    lines = detect_lines(wall_stub_strays(), RansacConfig(), np.random.default_rng(0), report)
    assert len(lines) == 1
    assert report.points == 170
    assert report.clusters == [150, 15, 5]
    assert report.lines[0]["points"] >= 140
    assert report.lines[0]["length"] == pytest.approx(3.0, abs=0.05)
    assert report.rejected["shorter than min_length"] == 1  # the stub
    assert report.rejected["cluster below min_points"] == 1  # the strays
    assert set(report.to_map()) == {"points", "clusters", "lines", "rejected"}
