"""A scan row with known contents, for the tests of what the detector says about a row."""

from __future__ import annotations

import numpy as np


def wall_stub_strays() -> np.ndarray:
    """A 3 m wall 2 m ahead, a NaN, a 10 cm stub of 15 points, a NaN, and 5 stray points."""
    rng = np.random.default_rng(4)
    wall = np.column_stack([np.full(150, 2.0), np.linspace(-1.5, 1.5, 150)])
    stub = np.column_stack([np.full(15, 3.0), np.linspace(2.0, 2.1, 15)])
    strays = rng.uniform(4, 5, (5, 2))
    gap = np.full((1, 2), np.nan)
    row = np.vstack([wall, gap, stub, gap, strays])
    return row + rng.normal(0, 0.002, row.shape) * [1, 0]
