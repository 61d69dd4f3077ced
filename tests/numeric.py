"""Numeric differentiation, against which every Jacobian of the method is tested."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wallmap.common import se2


def numeric_jacobian(
    f: Callable[[np.ndarray], np.ndarray], x, eps: float = 1e-6, angles: slice | None = None
) -> np.ndarray:
    """Central differences of ``f`` at ``x``, a column per entry of ``x``.

    ``angles``: the entries of ``f``'s value that are angles, whose differences wrap.
    """
    x = np.asarray(x, float)
    cols = []
    for i in range(len(x)):
        d = np.zeros_like(x)
        d[i] = eps
        diff = np.asarray(f(x + d) - f(x - d), float)
        if angles is not None:
            diff[angles] = [se2.wrap(v) for v in diff[angles]]
        cols.append(diff / (2 * eps))
    return np.column_stack(cols)
