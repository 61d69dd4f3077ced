"""The ``[player]`` section: how a recording is played. Plain values, no Zenoh imported."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from wallmap.common.config_file import require
from wallmap.services.player.sources import SourceSettings


@dataclass(frozen=True)
class PlayerSettings:
    """How to play a recording (which one is the command's argument, not configuration).

    Attributes:
        rate: speed factor on the recorded timing (ignored with ``fast``).
        fast: as fast as the pipeline takes it, with no frame lost.
        source: how to read it: pose source, sensor topic, levelling, a TUM folder's camera.
        window: frames in flight with ``fast``.
        wait_for: services whose liveliness to wait for before playing (not set: the detector
            and the mapper with ``fast``, none in real time).
        wait_timeout: how long to wait for them (s).
        stall_timeout: with ``fast``, how long without an acknowledgement is a failure (s).
        whole_clouds: send whole clouds instead of only the row the detector asks for.
        start: begin this many seconds into the bag.
        duration: play this many seconds of the bag (None: to the end).
        loop: start over at the end, until stopped.
        paused: start paused (step or resume through the controls).
    """

    rate: float = 1.0
    fast: bool = False
    source: SourceSettings = field(default_factory=SourceSettings)
    window: int = 16
    wait_for: tuple[str, ...] | None = None
    wait_timeout: float = 30.0
    stall_timeout: float = 30.0
    whole_clouds: bool = False
    start: float = 0.0
    duration: float | None = None
    loop: bool = False
    paused: bool = False

    def __post_init__(self) -> None:
        require(0 < self.rate < math.inf, "rate", "a positive number", self.rate)
        require(self.window >= 1, "window", "at least 1", self.window)
        require(self.wait_timeout >= 0, "wait_timeout", ">= 0", self.wait_timeout)
        require(self.stall_timeout > 0, "stall_timeout", "positive", self.stall_timeout)
        require(self.start >= 0, "start", ">= 0", self.start)
        duration = self.duration
        require(duration is None or duration > 0, "duration", "positive", duration)

    @property
    def services(self) -> tuple[str, ...]:
        """The services to wait for, ``wait_for`` or its default."""
        if self.wait_for is not None:
            return self.wait_for
        return ("detector", "mapper") if self.fast else ()
