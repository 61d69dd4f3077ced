"""How the compiled loops are reached: imported when first used, fed one kind of array.

The loops (``line_kernels``, ``band_kernels``, ``room_kernels``, ``pose_kernels``,
``map_kernels``) are numba functions. Importing numba takes 0.2 s, which every wallmap command
would pay, since the configuration they all read imports the modules that call the loops; so
those modules reach them through these functions instead.

numba compiles a loop once per kind of array it is given: read-only (a frame decoded from the
wire) or not, contiguous or not, each dtype. ``plain`` hands them one kind only, so the loops
compiled at install (``compile_all``) are the ones every frame uses, and none is compiled in
the middle of a run.
"""

from __future__ import annotations

import functools
import threading
import time
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import DTypeLike, NDArray


@functools.cache  # an import statement costs microseconds even when done: once per process
def line_kernels() -> ModuleType:
    """``common/line_kernels.py``: the line search's loops."""
    from wallmap.common import line_kernels as module  # noqa: PLC0415 - see the module's doc

    return module


@functools.cache
def band_kernels() -> ModuleType:
    """``common/band_kernels.py``: the band stack's loops."""
    from wallmap.common import band_kernels as module  # noqa: PLC0415 - see the module's doc

    return module


@functools.cache
def room_kernels() -> ModuleType:
    """``common/room_kernels.py``: room segmentation's passes over the grid."""
    from wallmap.common import room_kernels as module  # noqa: PLC0415 - see the module's doc

    return module


@functools.cache
def pose_kernels() -> ModuleType:
    """``common/pose_kernels.py``: the pose judge's association scores and pose fit."""
    from wallmap.common import pose_kernels as module  # noqa: PLC0415 - see the module's doc

    return module


@functools.cache
def map_kernels() -> ModuleType:
    """``common/map_kernels.py``: the wall map's EKF update and see-through test."""
    from wallmap.common import map_kernels as module  # noqa: PLC0415 - see the module's doc

    return module


def plain(array: Any, dtype: DTypeLike) -> NDArray[Any]:
    """``array`` as the loops take it: C-contiguous, writeable, ``dtype`` (copied if need be)."""
    if (
        isinstance(array, np.ndarray)
        and array.dtype == dtype
        and array.flags.c_contiguous
        and array.flags.writeable
    ):
        return array  # the usual case, checked in a fraction of np.require's time
    return np.array(array, dtype=dtype, order="C")


@dataclass(frozen=True)
class Readied:
    """Loops made ready: the seconds it took, and how many numba compiled (not in its cache).

    Only a compile is worth a line in a service's log: loading from the cache on a busy
    machine can take as long, and a line saying "compiled" then would send a user looking for
    a cache that does not work.
    """

    seconds: float
    compiled: int


def make_ready(*modules: ModuleType) -> Readied:
    """Run each module's ``warm_up``; what it took."""
    start = time.perf_counter()
    for module in modules:
        module.warm_up()
    seconds = time.perf_counter() - start
    compiled = sum(
        len(loop.stats.cache_misses)
        for module in modules
        for loop in vars(module).values()
        if hasattr(loop, "signatures")  # numba's dispatchers
    )
    return Readied(seconds, compiled)


def compile_detector() -> Readied:
    """Make the detector's loops ready (compiled, or loaded from numba's cache).

    numba compiles them on a machine's first run (about 10 s on two cores) and caches them;
    afterwards they load in a fraction of a second. Done at a detector's start, so that the
    first frame does not wait; not the rooms' loops, which a detector never runs.
    """
    return make_ready(line_kernels(), band_kernels())


def loaded_band_kernels() -> ModuleType | None:
    """``band_kernels`` once some thread has loaded it; None before, without loading it."""
    return band_kernels() if band_kernels.cache_info().currsize else None


def load_band_stack_meanwhile() -> threading.Thread:
    """Load the band stack's loop on a thread of its own (a ``--fast`` player's).

    Until it is loaded, ``scan_row.band_stack`` picks the same points in numpy.
    """
    loading = threading.Thread(target=lambda: band_kernels().warm_up_stack(), daemon=True)
    loading.start()
    return loading


def compile_mapper() -> Readied:
    """Make the loops of the mapper's frame path ready (the pose judge's, the map's).

    Not the rooms': rooms are drawn and segmented off the frame path, on a worker of their
    own, which loads them as it starts (0.05 s) rather than before the mapper says ready.
    """
    return make_ready(pose_kernels(), map_kernels())


def compile_all() -> float:
    """Make every loop ready, the detector's, the mapper's and the rooms'; the seconds it took.

    Done by ``make`` after installing and when the image is built, so that no service
    compiles at run time; the mapper loads its frame path's loops as it starts.
    """
    start = time.perf_counter()
    room_kernels().warm_up()
    compile_detector()
    compile_mapper()
    return time.perf_counter() - start
