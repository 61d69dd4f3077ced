"""The rolling median against numpy's median of the same window."""

from __future__ import annotations

import collections

import numpy as np
import pytest

from wallmap.common.rolling_median import RollingMedian


@pytest.mark.parametrize("window", [1, 2, 7, 200])
def test_the_rolling_median_is_the_median_of_the_last_values(window: int) -> None:
    rng = np.random.default_rng(window)
    rolling, kept = RollingMedian(window), collections.deque(maxlen=window)
    values = np.round(rng.normal(0, 1, 600), 2).tolist()  # rounded: equal values occur
    for value in values:
        rolling.add(value)
        kept.append(value)
        assert rolling.median() == float(np.median(kept))
        assert len(rolling) == len(kept)
    assert list(rolling) == list(kept)  # in the order they came, for a state file


def test_cleared_and_refilled_it_starts_afresh() -> None:
    rolling = RollingMedian(3)
    rolling.extend([5.0, 1.0, 9.0, 4.0])
    assert rolling.median() == 4.0
    rolling.clear()
    with pytest.raises(ValueError, match="no values"):
        rolling.median()
    rolling.extend([2.0, 3.0])
    assert rolling.median() == 2.5
