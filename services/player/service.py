"""The player service: a bag's sensor frames and poses, published over Zenoh.

At ``--rate X`` it keeps the bag's timing, scaled. With ``--fast`` it publishes as fast as the
pipeline takes it and loses nothing: it keeps at most ``window`` frames in flight, counting the
frames the mapper acknowledges for this run on the progress key. Before the first frame it waits
for the services it feeds (their liveliness tokens), so no frame goes out to nobody.
"""

from __future__ import annotations

import sys
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import zenoh

from wallmap.common.allocator import keep_large_buffers
from wallmap.common.codec import MessageError, decode
from wallmap.common.messages import Frame, pack, unpack_progress
from wallmap.common.runtime import setup_logging
from wallmap.common.scan_row import RowSelection
from wallmap.common.transport import Keys, ZenohSettings, open_session
from wallmap.services.player.bag_source import LASERSCAN, BagSource
from wallmap.services.player.errors import PlayerError

POLL = 0.001  # s between checks of the acknowledgement channel


@dataclass(frozen=True)
class PlayerSettings:
    """How to play a bag.

    Attributes:
        bag: a ROS 1 ``.bag`` file or a ROS 2 bag folder.
        rate: speed factor on the recorded timing (ignored with ``fast``).
        fast: as fast as the pipeline takes it, with no frame lost.
        pose_source: the contract's ``--pose-source`` spec.
        sensor_topic: the sensor topic, when the bag has several candidates.
        window: frames in flight with ``fast``.
        wait_for: services whose liveliness to wait for before playing.
        wait_timeout: how long to wait for them (s).
        stall_timeout: with ``fast``, how long without an acknowledgement is a failure (s).
        whole_clouds: send whole clouds instead of only the row the detector asks for.
    """

    bag: Path
    rate: float = 1.0
    fast: bool = False
    pose_source: str = "tf"
    sensor_topic: str | None = None
    window: int = 16
    wait_for: tuple[str, ...] = ()
    wait_timeout: float = 30.0
    stall_timeout: float = 30.0
    whole_clouds: bool = False


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
    session: zenoh.Session, keys: Keys, names: tuple[str, ...], timeout: float
) -> None:
    deadline = time.monotonic() + timeout
    missing = set(names)
    while missing:
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
            time.sleep(0.1)


def _ask_rows(session: zenoh.Session, keys: Keys) -> RowSelection | None:
    """The detector's row selection, or None (send whole clouds) when no detector answers."""
    for reply in session.get(keys.detector_rows, timeout=2.0):
        if reply.ok is not None:
            try:
                return RowSelection.from_map(decode(reply.ok.payload.to_bytes()))
            except MessageError:
                return None
    return None


class _Acks:
    """The mapper's acknowledgements of this run, read from the progress channel."""

    def __init__(self, channel: zenoh.handlers.Handler[zenoh.Sample], run: str) -> None:
        self.channel = channel
        self.run = run
        self.processed = 0
        self.integrated = 0
        self.last_change = time.monotonic()

    def poll(self) -> None:
        while (sample := self.channel.try_recv()) is not None:
            try:
                progress = unpack_progress(sample.payload.to_bytes())
            except MessageError:
                continue
            if progress.run == self.run and progress.processed > self.processed:
                self.processed, self.integrated = progress.processed, progress.integrated
                self.last_change = time.monotonic()

    def wait_until(self, processed: int, stall_timeout: float, stop: threading.Event) -> None:
        self.poll()
        while self.processed < processed and not stop.is_set():
            if time.monotonic() - self.last_change > stall_timeout:
                msg = (
                    f"the mapper acknowledged no frame for {stall_timeout:.0f} s "
                    f"({self.processed} of {processed} done); is it running?"
                )
                raise PlayerError(msg)
            time.sleep(POLL)
            self.poll()


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


def run(settings: ZenohSettings, player: PlayerSettings, stop: threading.Event) -> PlayResult:
    """Play the bag once; raises PlayerError (or TransportError) with a readable message."""
    log = setup_logging("player")
    keep_large_buffers()  # bag messages are megabytes each
    keys = Keys(settings.prefix)
    run_id = uuid.uuid4().hex[:12]
    with BagSource(
        player.bag, sensor_topic=player.sensor_topic, pose_source=player.pose_source
    ) as bag:
        for warning in bag.warnings:
            log.warning("%s", warning)
        log.info(
            "%s: %d frames on %s (%s), poses from %s",
            player.bag,
            bag.frame_count,
            bag.sensor_topic,
            bag.sensor_type,
            player.pose_source,
        )
        with open_session(settings) as session:
            block = zenoh.CongestionControl.BLOCK
            frames_pub = session.declare_publisher(keys.frames, congestion_control=block)
            pose_pub = session.declare_publisher(keys.pose, congestion_control=block)
            progress_sub = session.declare_subscriber(
                keys.progress, zenoh.handlers.FifoChannel(256)
            )
            acks = _Acks(progress_sub.handler, run_id)
            _wait_for_services(session, keys, player.wait_for, player.wait_timeout)
            sensor = "scan" if bag.sensor_type == LASERSCAN else "depth"
            rows = None if player.whole_clouds or sensor == "scan" else _ask_rows(session, keys)
            log.info(
                "sending %s", "whole clouds" if rows is None else f"one row per frame ({rows})"
            )
            bar = _ProgressLine(bag.frame_count)
            published = poses = 0
            start_wall = time.monotonic()
            first_stamp: float | None = None
            for frame, pose in bag.frames(rows):
                if stop.is_set():
                    break
                if player.fast:
                    acks.wait_until(published - player.window + 1, player.stall_timeout, stop)
                else:
                    first_stamp = frame.stamp if first_stamp is None else first_stamp
                    due = start_wall + (frame.stamp - first_stamp) / player.rate
                    stop.wait(max(0.0, due - time.monotonic()))
                if pose is not None:
                    pose_pub.put(pack(pose))
                    poses += 1
                message = Frame(
                    run_id,
                    published,
                    frame.stamp,
                    frame.frame_id,
                    frame.points,
                    frame.T_base_sensor,
                    sensor,
                )
                frames_pub.put(pack(message))
                published += 1
                bar.update(published)
            bar.update(published, force=True)
            if player.fast or "mapper" in player.wait_for:
                acks.wait_until(published, player.stall_timeout, stop)
            seconds = time.monotonic() - start_wall
            progress_sub.undeclare()
    waited = player.fast or "mapper" in player.wait_for
    return PlayResult(published, poses, seconds, acks.integrated if waited else None)
