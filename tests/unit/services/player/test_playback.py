"""Playback controls like `ros2 bag play`: the state machine alone (pause, step, seek, rate)."""

from __future__ import annotations

import threading
import time

import pytest

from wallmap.scene import write_scene_bag
from wallmap.services.player.playback import Playback

N_FRAMES = 60  # 4 s of bag at 15 Hz


def _turn_in_thread(playback: Playback, position: float, stop: threading.Event) -> list:
    out: list = []
    threading.Thread(target=lambda: out.append(playback.wait_turn(position, stop))).start()
    return out


def test_pause_holds_step_lets_one_through_and_seek_interrupts() -> None:
    stop = threading.Event()
    playback = Playback(fast=True, paused=True)
    waiting = _turn_in_thread(playback, 1.0, stop)
    time.sleep(0.3)
    assert waiting == [], "paused: the frame waits"
    playback.step()
    time.sleep(0.3)
    assert len(waiting) == 1
    assert waiting[0].seek is None
    assert playback.status() == {"state": "paused", "rate": 1.0, "position": 1.0}
    waiting = _turn_in_thread(playback, 2.0, stop)
    playback.seek(0.5)
    time.sleep(0.3)
    assert waiting[0].seek == 0.5
    playback.resume()
    assert playback.wait_turn(0.5, stop).seek is None
    with pytest.raises(ValueError, match="rate must be within"):
        playback.set_rate(0.0)
    with pytest.raises(ValueError, match="seek needs a position"):
        playback.seek(-1.0)
    stop.set()


def test_rate_scales_the_bags_timing() -> None:
    """A second of bag at rate 10 takes about a tenth of a second (loose: a shared machine)."""
    stop = threading.Event()
    playback = Playback(rate=10.0)
    begin = time.monotonic()
    for i in range(11):
        playback.wait_turn(0.1 * i, stop)
    elapsed = time.monotonic() - begin
    assert 0.09 <= elapsed < 0.6


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("playback") / "s.bag"
    write_scene_bag(path, seed=11, n_frames=N_FRAMES, fmt="ros1", sensor="depth16")
    return path


def test_a_seek_asked_for_is_the_position_the_reply_shows() -> None:
    """The control query's reply to a seek: where playback goes, not the last frame sent."""
    playback = Playback(fast=True, paused=True)
    playback.seek(3.0)
    assert playback.status()["position"] == 3.0
