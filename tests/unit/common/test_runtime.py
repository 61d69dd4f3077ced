"""A service's counters: every refusal counted, logged at most once a second per reason."""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest

from wallmap.common import runtime
from wallmap.common.runtime import Stats


def test_refusals_are_all_counted_and_each_reason_logged_once_a_second(
    caplog: pytest.LogCaptureFixture,
) -> None:
    stats = Stats(logging.getLogger("test_runtime"))
    with caplog.at_level(logging.WARNING, logger="test_runtime"):
        for _ in range(5):
            stats.refuse("frame", "field 'stamp' must be a finite number, got 'abc'")
        stats.refuse("frame", "field 'seq' is missing")
    assert stats.snapshot()["refused"] == 6
    assert stats.snapshot()["refused.frame"] == 6
    assert [r.getMessage() for r in caplog.records] == [
        "refused frame: field 'stamp' must be a finite number, got 'abc'",
        "refused frame: field 'seq' is missing",
    ]


def test_reasons_that_quote_what_came_do_not_grow_the_log_limit_without_bound(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A sender of ever different bad values: the reasons differ, the memory does not grow."""
    monkeypatch.setattr(runtime, "MAX_KINDS", 50)
    clock = iter(float(t) for t in range(10_000))
    monkeypatch.setattr(runtime.time, "monotonic", lambda: next(clock))
    stats = Stats(logging.getLogger("test_runtime"))
    for value in range(1_000):
        stats.refuse("frame", f"field 'stamp' must be a finite number, got {value}")
    assert stats.snapshot()["refused"] == 1_000
    assert len(stats._last_logged) <= 51


def test_a_thread_that_dies_stops_the_service_and_is_remembered() -> None:
    """A worker dying of an exception sets the service's stop event (it would otherwise look
    alive and do nothing) and is kept for the command's exit status. In a process of its own:
    it sets signal handlers and the thread hook."""
    script = (
        "import threading\n"
        "from wallmap.common.runtime import stop_on_signals, thread_failures\n"
        "stop = stop_on_signals()\n"
        "worker = threading.Thread(target=lambda: 1 / 0, name='worker')\n"
        "worker.start(); worker.join()\n"
        "print(stop.is_set(), [type(e).__name__ for e in thread_failures()])\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], check=False, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[0] == "True ['ZeroDivisionError']"
    assert "worker died; the service stops" in done.stderr
    assert "ZeroDivisionError" in done.stderr, "its traceback is logged"


def test_startup_objects_leave_the_full_collections_and_startup_garbage_goes_first() -> None:
    # In a process of its own: freezing is for the whole interpreter.
    code = """
import gc, weakref
from wallmap.common.runtime import exempt_startup_objects
class Node: pass
kept = [[k] for k in range(50_000)]
cycle = Node(); cycle.me = cycle; gone = weakref.ref(cycle); del cycle
gc.disable()  # no collection of its own between the lines below
exempt_startup_objects()
assert gone() is None, "start-up's garbage was frozen with the rest"
assert gc.get_freeze_count() > len(kept), gc.get_freeze_count()
assert len(gc.get_objects(generation=2)) < 1000, len(gc.get_objects(generation=2))
print("ok")
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.stdout.strip() == "ok", done.stderr
