"""Keys on a terminal for the player, as ``ros2 bag play`` has: space, s, +, -, q."""

from __future__ import annotations

import contextlib
import select
import sys
import termios
import threading
import tty
from collections.abc import Iterator

from wallmap.services.player.playback import RATE_LIMITS, Playback

HELP = "keys: space pause/resume, s step, + faster, - slower, q quit"


def _handle(key: str, playback: Playback, stop: threading.Event) -> None:
    status = playback.status()
    if key == " ":
        (playback.resume if status["state"] == "paused" else playback.pause)()
    elif key == "s":
        playback.pause()
        playback.step()
    elif key in "+-":
        rate = status["rate"] * (2.0 if key == "+" else 0.5)
        playback.set_rate(min(max(rate, RATE_LIMITS[0]), RATE_LIMITS[1]))
    elif key == "q":
        stop.set()


@contextlib.contextmanager
def terminal_keys(playback: Playback, stop: threading.Event) -> Iterator[bool]:
    """Read single keys from a terminal while the block runs; yields False when not a terminal.

    The terminal is put in cbreak mode (keys arrive unbuffered, without Enter) and restored on
    the way out, also after an error.
    """
    if not sys.stdin.isatty():
        yield False
        return
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    done = threading.Event()

    def read() -> None:
        while not done.is_set() and not stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.1)
            if ready:
                _handle(sys.stdin.read(1), playback, stop)

    tty.setcbreak(fd)
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        yield True
    finally:
        done.set()
        reader.join(timeout=1.0)
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
