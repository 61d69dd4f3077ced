"""Playback controls like ``ros2 bag play``: pause, resume, step, seek and rate. Pure, thread-safe.

The player's loop asks ``wait_turn`` before each frame; the control queryable and the terminal
keys call the other methods from their own threads. Timing follows the bag's stamps scaled by the
rate, re-anchored whenever the rate changes, playback resumes or a seek lands, so a change takes
effect from the next frame without a burst or a stall.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

RATE_LIMITS = (0.01, 100.0)


@dataclass(frozen=True)
class Turn:
    """What the loop does next: publish the frame, or restart the bag at ``seek`` (s)."""

    seek: float | None = None


class Playback:
    """The state of one playback, shared by the loop and its controls."""

    def __init__(self, rate: float = 1.0, *, fast: bool = False, paused: bool = False) -> None:
        self.fast = fast
        self._rate = rate
        self._paused = paused
        self._steps = 0
        self._seek: float | None = None
        self._anchor: tuple[float, float] | None = None  # (wall clock, bag time) of the pace
        self._position = 0.0  # bag time (s from the start) of the last frame published
        self._changed = threading.Condition()

    def pause(self) -> None:
        """Hold before the next frame."""
        with self._changed:
            self._paused = True

    def resume(self) -> None:
        """Play on from where it is, at the current rate."""
        with self._changed:
            self._paused, self._anchor = False, None
            self._changed.notify_all()

    def step(self) -> None:
        """While paused, publish exactly one more frame."""
        with self._changed:
            self._steps += 1
            self._changed.notify_all()

    def seek(self, position: float) -> None:
        """Go to ``position`` seconds from the bag's start (the next frame at or after it)."""
        if position < 0:
            msg = f"seek needs a position >= 0 s, got {position}"
            raise ValueError(msg)
        with self._changed:
            self._seek, self._anchor = position, None
            self._changed.notify_all()

    def set_rate(self, rate: float) -> None:
        """Play at ``rate`` times the recorded speed from the next frame on."""
        low, high = RATE_LIMITS
        if not low <= rate <= high:
            msg = f"rate must be within {low}..{high}, got {rate}"
            raise ValueError(msg)
        with self._changed:
            self._rate, self._anchor = rate, None
            self._changed.notify_all()

    def status(self) -> dict[str, Any]:
        """State for replies and progress messages; a seek asked for is where it stands."""
        with self._changed:
            state = "paused" if self._paused else "playing"
            position = self._position if self._seek is None else self._seek
            return {"state": state, "rate": self._rate, "position": position}

    def wait_turn(self, position: float, stop: threading.Event) -> Turn:
        """Block until the frame at ``position`` (s from the bag's start) is due.

        Returns a seek when one was asked for meanwhile; the frame is then not published.
        """
        with self._changed:
            while not stop.is_set():
                if self._seek is not None:
                    target, self._seek = self._seek, None
                    return Turn(seek=target)
                if self._paused and not self._steps:
                    self._changed.wait(timeout=0.1)
                    continue
                if self._paused:
                    self._steps -= 1
                    break
                if self.fast:
                    break
                now = time.monotonic()
                if self._anchor is None:
                    self._anchor = (now, position)
                due = self._anchor[0] + (position - self._anchor[1]) / self._rate
                if due <= now:
                    break
                self._changed.wait(timeout=min(due - now, 0.1))
            self._position = position
            return Turn()
