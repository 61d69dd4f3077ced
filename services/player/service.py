"""The player service: a bag's sensor frames and poses, published over Zenoh.

At ``--rate X`` it keeps the bag's timing, scaled; it can be paused, stepped, sought and sped up
through ``{prefix}/player/control`` or keys on a terminal, and says where it is on
``{prefix}/player/progress``. Frames and poses are published with a history window
(``common.delivery``): a service that restarts, or a link that comes back, gets what it missed.
With ``--fast`` it publishes as fast as the pipeline takes it: it keeps at most ``window`` frames
in flight, counting the frames the mapper acknowledges for this run on the progress key. Before
the first frame it waits for the services it feeds (their liveliness tokens), so no frame goes
out to nobody.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
from zenoh.ext import AdvancedPublisher

from wallmap.common import compiled
from wallmap.common.allocator import keep_large_buffers
from wallmap.common.codec import encode
from wallmap.common.delivery import AckWindow, declare_history_publisher
from wallmap.common.link_settings import MAX_RATE, HistorySettings, ZenohSettings
from wallmap.common.messages import pack
from wallmap.common.runtime import drain, exempt_startup_objects, setup_logging
from wallmap.common.scan_row import RowSelection
from wallmap.common.transport import Keys, make_config, open_session
from wallmap.services.detector_rows import ask_rows
from wallmap.services.player.bag_contents import LASERSCAN
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.frames import SensorFrame
from wallmap.services.player.playback import Playback
from wallmap.services.player.pose_stream import POSE_PERIOD, stream_of
from wallmap.services.player.settings import PlayerSettings
from wallmap.services.player.sources import FrameSource, open_source
from wallmap.services.player.terminal_keys import HELP, terminal_keys

JOIN_TIMEOUT = 2.0  # s the control thread gets to see its queryable undeclared
PROGRESS_PERIOD = 0.2  # s between progress messages


@dataclass(frozen=True)
class PlayResult:
    """What the player did."""

    frames: int
    poses: int
    seconds: float
    integrated: int | None  # frames the mapper integrated for this run (``fast`` only)

    def summary(self) -> str:
        """One line for people."""
        fps = self.frames / self.seconds if self.seconds > 0 else 0.0
        line = f"published {self.frames} frames and {self.poses} poses in {self.seconds:.2f} s"
        line += f" ({fps:.1f} frames/s)"
        if self.integrated is not None:
            line += f"; the mapper integrated {self.integrated}"
        return line


def _wait_for_services(
    session: zenoh.Session,
    keys: Keys,
    names: tuple[str, ...],
    timeout: float,
    stop: threading.Event,
) -> None:
    deadline = time.monotonic() + timeout
    missing = set(names)
    while missing and not stop.is_set():
        for reply in session.liveliness().get(keys.health("*"), timeout=1.0):
            if reply.ok is not None:
                missing.discard(str(reply.ok.key_expr).rsplit("/", 1)[-1])
        if missing and time.monotonic() > deadline:
            msg = (
                f"no {' and no '.join(sorted(missing))} running under prefix {keys.prefix!r} "
                f"(waited {timeout:.0f} s); start them first, or play without --fast"
            )
            raise PlayerError(msg)
        if missing:
            stop.wait(0.1)


class _ProgressLine:
    """A progress line on a terminal; silent when stderr is not one (logs, CI)."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.enabled = sys.stderr.isatty()
        self.last = 0.0

    def update(self, done: int, *, force: bool = False) -> None:
        now = time.monotonic()
        if not self.enabled or (now - self.last < 0.2 and not force):
            return
        self.last = now
        width = 30
        filled = int(width * done / max(self.total, 1))
        bar = "#" * filled + "-" * (width - filled)
        end = "\n" if force else ""
        print(f"\r[{bar}] {done}/{self.total} frames", end=end, file=sys.stderr, flush=True)


def _control(
    channel: zenoh.handlers.Handler[zenoh.Query], playback: Playback, state: dict[str, Any]
) -> None:
    """Answer ``{prefix}/player/control?cmd=C``: pause, resume, step, seek (t=S), rate (x=F).

    Every reply is the playback's state (also for ``cmd=status``), as on the progress key.
    """
    for query in drain(channel):
        with query:
            params = dict(query.parameters)
            command = params.get("cmd", "status")
            try:
                if command == "pause":
                    playback.pause()
                elif command == "resume":
                    playback.resume()
                elif command == "step":
                    playback.pause()
                    playback.step()
                elif command == "seek":
                    playback.seek(float(params["t"]))
                elif command == "rate":
                    playback.set_rate(float(params["x"]))
                elif command != "status":
                    msg = (
                        f"unknown cmd {command!r}: pause, resume, step, seek;t=S, rate;x=F, status"
                    )
                    raise ValueError(msg)
            except (KeyError, ValueError) as err:
                query.reply_err(f"player control: {err}")
                continue
            query.reply(query.key_expr, encode({**state, **playback.status()}))


class _Outlet:
    """Where the frames go: the publishers with their history, and the progress messages.

    Frames and poses keep the history window in their caches (``common.delivery``), so that a
    detector or mapper that restarts, or a link that comes back, gets what it missed. The
    frames' cache is sized on the first frame, by its bytes.
    """

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        run_id: str,
        sensor: str,
        playback: Playback,
        bag: FrameSource,
        history: HistorySettings,
        speed: float,
    ) -> None:
        rate = bag.frame_count / bag.duration if bag.duration > 0 else MAX_RATE
        self._rate = min(rate * (1.0 if playback.fast else speed), MAX_RATE * 8)
        self._session, self._keys, self._history = session, keys, history
        self._frames: AdvancedPublisher | None = None
        pose_rate = self._rate + (1.0 if playback.fast else speed) / POSE_PERIOD
        self._poses = declare_history_publisher(session, keys.pose, history.samples(pose_rate))
        self._stream = stream_of(bag)
        self._progress = session.declare_publisher(keys.player_progress)
        self._run, self._sensor, self._playback = run_id, sensor, playback
        self.lossless = playback.fast  # only --fast waits for the pipeline
        self.published = self.poses = 0
        self.bar = _ProgressLine(bag.frame_count)
        self.state: dict[str, Any] = {
            "run": run_id,
            "published": 0,
            "frames": bag.frame_count,
            "duration": bag.duration,
            "bag": str(bag.path),
        }
        self._last_progress = 0.0

    def send(self, frame: SensorFrame) -> None:
        """Publish one frame, and say so at most every PROGRESS_PERIOD.

        The source's poses go first, up to a little past the frame (``pose_stream``).
        """
        for pose in self._stream.until(frame.stamp):
            self._poses.put(pack(pose))
            self.poses += 1
        message = pack(
            frame.to_frame(
                run=self._run, seq=self.published, sensor=self._sensor, lossless=self.lossless
            )
        )
        if self._frames is None:
            samples = self._history.samples(self._rate, len(message))
            self._frames = declare_history_publisher(self._session, self._keys.frames, samples)
        self._frames.put(message)
        self.published += 1
        self.state["published"] = self.published
        self.bar.update(self.published)
        if time.monotonic() - self._last_progress >= PROGRESS_PERIOD:
            self._last_progress = time.monotonic()
            self._progress.put(encode({**self.state, **self._playback.status()}))

    def finish(self) -> None:
        """The last progress message: done."""
        self._progress.put(encode({**self.state, **self._playback.status(), "state": "done"}))


def _band_loop_loading(bag: FrameSource, player: PlayerSettings) -> threading.Thread | None:
    """With ``--fast``, the band stack's compiled loop, loading while the player connects.

    A ``--fast`` run is measured by how fast the pipeline takes the frames, and the loop picks
    a camera frame's band stack at half the cost of numpy; numba's import and start (0.3 s)
    go before the first frame, not among them, where they cost a short run more than they
    save. In real time the sensor's rate paces the frames and numpy picks them (the same
    points): the player starts sending sooner. None: no loop to load.
    """
    if not player.fast or player.whole_clouds or bag.sensor_type == LASERSCAN:
        return None
    return compiled.load_band_stack_meanwhile()


def _play_pass(
    bag: FrameSource,
    rows: RowSelection | None,
    start: float,
    player: PlayerSettings,
    playback: Playback,
    outlet: _Outlet,
    acks: AckWindow,
    stop: threading.Event,
) -> float | None:
    """Publish the bag's frames from ``start`` (s) on; returns where to seek to, if asked."""
    end = None if player.duration is None else player.start + player.duration
    for frame, _ in bag.frames(rows, start=start, stop=end):
        turn = playback.wait_turn(frame.bag_time, stop)
        if stop.is_set():
            return None
        if turn.seek is not None:
            return turn.seek
        if player.fast:
            acks.wait_until(outlet.published - player.window + 1, player.stall_timeout, stop)
        outlet.send(frame)
    return None


def _play(
    bag: FrameSource,
    rows: RowSelection | None,
    player: PlayerSettings,
    playback: Playback,
    outlet: _Outlet,
    acks: AckWindow,
    stop: threading.Event,
) -> None:
    """Play the passes the settings and the controls ask for: once, sought, or in a loop."""
    position = player.start
    while not stop.is_set():
        seek = _play_pass(bag, rows, position, player, playback, outlet, acks, stop)
        if seek is None and not player.loop and player.fast:
            acks.wait_until(outlet.published, player.stall_timeout, stop)
        if seek is not None:
            position = seek
        elif player.loop and not stop.is_set():
            position = player.start
        else:
            return


def _check_and_describe(
    bag: FrameSource, recording: Path, player: PlayerSettings, log: logging.Logger
) -> None:
    """Refuse a start past the recording's end; log what will be played, and how."""
    if player.start > bag.duration:
        raise PlayerError(
            f"--start {player.start:g} s is past the end of {recording}, {bag.duration:.1f} s long"
        )
    for warning in bag.warnings:
        log.warning("%s", warning)
    log.info(
        "%s: %d frames on %s (%s), poses from %s",
        recording,
        bag.frame_count,
        bag.sensor_topic,
        bag.sensor_type,
        bag.pose_spec,
    )
    if placed := bag.placement.describe():
        log.info("%s", placed)


def run(
    settings: ZenohSettings,
    recording: Path,
    player: PlayerSettings,
    stop: threading.Event,
    history: HistorySettings | None = None,
) -> PlayResult:
    """Play ``recording`` once (or in a loop); raises PlayerError (or TransportError) saying why.

    ``history``: the window of frames and poses kept for services that missed them.
    """
    history = history or HistorySettings()
    log = setup_logging("player")
    keep_large_buffers()  # bag messages are megabytes each
    keys = Keys(settings.prefix)
    run_id = uuid.uuid4().hex[:12]
    make_config(settings)  # a bad endpoint or Zenoh file is said before the bag is read
    with open_source(recording, player.source) as bag:
        _check_and_describe(bag, recording, player, log)
        loading = _band_loop_loading(bag, player)
        # a player comes and goes: its frames would stay in the router's and services' memory
        with open_session(settings, stop=stop, shared_memory=False) as session:
            acks = AckWindow(run_id)
            progress_sub = session.declare_subscriber(keys.progress, acks.on_sample)
            _wait_for_services(session, keys, player.services, player.wait_timeout, stop)
            sensor = "scan" if bag.sensor_type == LASERSCAN else "depth"
            rows = None if player.whole_clouds or sensor == "scan" else ask_rows(session, keys)
            if loading is not None:
                loading.join()
            exempt_startup_objects()  # the bag's index and tf among them: they stay till the end
            log.info(
                "sending %s", "whole clouds" if rows is None else f"one row per frame ({rows})"
            )
            playback = Playback(player.rate, fast=player.fast, paused=player.paused)
            outlet = _Outlet(session, keys, run_id, sensor, playback, bag, history, player.rate)
            control = session.declare_queryable(keys.player_control, zenoh.handlers.FifoChannel(16))
            answering = threading.Thread(
                target=_control, args=(control.handler, playback, outlet.state), daemon=True
            )
            answering.start()
            start_wall = time.monotonic()
            with terminal_keys(playback, stop) as interactive:
                if interactive:
                    print(HELP, file=sys.stderr)
                _play(bag, rows, player, playback, outlet, acks, stop)
            outlet.bar.update(outlet.published, force=True)
            if "mapper" in player.services and not player.fast:
                acks.wait_until(outlet.published, player.stall_timeout, stop)
            seconds = time.monotonic() - start_wall
            outlet.finish()
            control.undeclare()
            # Out of Zenoh's recv before the interpreter ends: a thread woken inside it then
            # is unwound through Zenoh's frames and aborts the process.
            answering.join(timeout=JOIN_TIMEOUT)
            progress_sub.undeclare()
    waited = player.fast or "mapper" in player.services
    return PlayResult(outlet.published, outlet.poses, seconds, acks.integrated if waited else None)
