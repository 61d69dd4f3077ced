"""The data path alone: what the pipeline's messages cost with no work done on them.

Three processes and a real router carry what the services carry for a 320x240 depth bag, as
they carry it (``common.delivery``'s publishers with a history cache, subscribers with history
and recovery, the player's window of frames in flight and the mapper's acknowledgements every
``ACK_EVERY`` frames), but nobody reads a bag, detects or maps: a source sends pre-made
payloads of the sizes measured on that bag, a relay answers each frame with an observation and
a diagnostics message as the detector does, and a sink takes the observations and the poses and
acknowledges. Its time is what any pipeline of these processes and messages pays before it does
anything; against the read floor (``end_to_end.read_floor`` on the same bag) it says how far the
design itself is from the floor, whatever the services' work is cut to.

    .venv/bin/python benchmarks/data_path.py [--rounds 3] [--frames 784]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh
from end_to_end import read_floor
from floor_ratio import write_depth_bag
from versus import ROOT, run_once

from wallmap.common.delivery import (
    CatchUpInbox,
    declare_history_publisher,
    subscribe_with_history,
)
from wallmap.common.frame_order import ACK_EVERY
from wallmap.common.link_settings import HistorySettings, ZenohSettings
from wallmap.common.runtime import drain
from wallmap.common.transport import open_session
from wallmap.launcher import free_loopback_port

# Bytes per message and poses per frame, as `wallmap player --fast` sends a generated 784-frame
# 320x240 16UC1 bag (counted by a subscriber to every key): the band's stack, a pose of tf,
# the detector's observations and diagnostics, the mapper's acknowledgement.
FRAME, POSE, OBSERVATION, DIAGNOSTICS, ACK = 23_352, 80, 1_525, 234, 60
POSES_PER_FRAME = 2615 / 784
WINDOW = 16  # the player's frames in flight (``PlayerSettings.window``)
HISTORY = HistorySettings()
KEYS = {name: f"datapath/{name}" for name in ("frames", "pose", "observations", "diag", "ack")}


def _source(session: zenoh.Session, frames: int) -> None:
    """Send ``frames`` frames and their poses, at most WINDOW unacknowledged; print seconds."""
    publishers = {
        name: declare_history_publisher(session, KEYS[name], HISTORY.samples(sample_bytes=size))
        for name, size in (("frames", FRAME), ("pose", POSE))
    }
    acked, changed = [0], threading.Condition()

    def on_ack(sample: zenoh.Sample) -> None:  # Zenoh's thread: a few microseconds
        with changed:
            acked[0] = max(acked[0], int(sample.payload.to_bytes()[:12]))
            changed.notify_all()

    ack_sub = session.declare_subscriber(KEYS["ack"], on_ack)
    frame, pose = bytes(FRAME), bytes(POSE)
    time.sleep(1.0)  # the relay and the sink subscribe meanwhile (later, the history serves them)
    start, poses_sent = time.perf_counter(), 0
    for n in range(frames):
        with changed:
            changed.wait_for(lambda n=n: acked[0] >= n - WINDOW + 1)
        while poses_sent < round((n + 1) * POSES_PER_FRAME):
            publishers["pose"].put(pose)
            poses_sent += 1
        publishers["frames"].put(frame)
    with changed:
        changed.wait_for(lambda: acked[0] >= frames)
    print(time.perf_counter() - start, flush=True)
    ack_sub.undeclare()


def _relay(session: zenoh.Session, stop: threading.Event) -> None:
    """Answer each frame with an observation and a diagnostics message, as the detector does."""
    observations = declare_history_publisher(
        session, KEYS["observations"], HISTORY.samples(sample_bytes=OBSERVATION)
    )
    diagnostics = session.declare_publisher(KEYS["diag"])
    observation, diagnostic = bytes(OBSERVATION), bytes(DIAGNOSTICS)

    def work(channel: zenoh.handlers.Handler[zenoh.Sample]) -> None:
        for sample in drain(channel):
            sample.payload.to_bytes()
            observations.put(observation)
            diagnostics.put(diagnostic)

    subscription = subscribe_with_history(session, KEYS["frames"], HISTORY, work, print)
    stop.wait()
    subscription.undeclare()


def _sink(session: zenoh.Session, stop: threading.Event) -> None:
    """Take observations and poses; acknowledge every ACK_EVERY observations and when idle."""
    ack = session.declare_publisher(KEYS["ack"])

    def observations(inbox: CatchUpInbox) -> None:
        done = 0
        while True:
            try:
                inbox.recv().payload.to_bytes()
            except zenoh.ZError:
                return
            done += 1
            for _ in range(ACK_EVERY - 1):  # what has come meanwhile, ACK_EVERY in all at most
                if (sample := inbox.try_recv()) is None:
                    break
                sample.payload.to_bytes()
                done += 1
            ack.put(str(done).ljust(ACK).encode())  # every ACK_EVERY, or idle, as the mapper

    def poses(channel: zenoh.handlers.Handler[zenoh.Sample]) -> None:
        for sample in drain(channel):
            sample.payload.to_bytes()

    subscriptions = [
        subscribe_with_history(session, KEYS[key], HISTORY, take, print)
        for key, take in (("observations", observations), ("pose", poses))
    ]
    stop.wait()
    for subscription in subscriptions:
        subscription.undeclare()


def _role(role: str, endpoint: str, frames: int) -> None:
    """One process of the data path, until the source is done (or SIGTERM for the others)."""
    settings = ZenohSettings(connect=(endpoint,), wait_for_router=10.0)
    stop = threading.Event()
    with open_session(settings) as session:
        if role == "source":
            _source(session, frames)
        else:
            threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
            (_relay if role == "relay" else _sink)(session, stop)


def data_path_seconds(frames: int) -> float:
    """One run of the data path: router, sink, relay and source as processes; the source's time."""
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    me = [sys.executable, __file__, "--endpoint", endpoint, "--frames", str(frames), "--role"]
    router = subprocess.Popen([sys.executable, "-m", "wallmap", "router", "--listen", endpoint])
    others = [
        subprocess.Popen([*me, role], stdin=subprocess.PIPE, cwd=Path(__file__).parent)
        for role in ("sink", "relay")
    ]
    try:
        out = subprocess.run(
            [*me, "source"], capture_output=True, text=True, check=True, cwd=Path(__file__).parent
        ).stdout
    finally:
        for proc in others:
            proc.communicate(b"", timeout=10)
        router.terminate()
        router.wait()
    return float(out.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=784)
    parser.add_argument("--role", choices=("source", "relay", "sink"), help=argparse.SUPPRESS)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role is not None:
        _role(args.role, args.endpoint, args.frames)
        return
    floors, paths, pipelines = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        bag = write_depth_bag(Path(tmp) / "depth", args.frames)
        for _ in range(args.rounds):
            floors.append(read_floor(bag, "sensor_msgs/msg/Image"))
            paths.append(data_path_seconds(args.frames))
            pipelines.append(run_once(ROOT, bag, ())["seconds"])
    print(f"{args.frames} frames of 320x240 depth, {args.rounds} rounds (medians, range)")
    print("| what | seconds | ms / frame | floor / it |\n|---|---:|---:|---:|")
    floor = statistics.median(floors)
    for name, times in (
        ("rosbags reads the frames (the floor)", floors),
        ("the data path alone, no work", paths),
        ("the pipeline (router, player --fast, detector, mapper)", pipelines),
    ):
        mid = statistics.median(times)
        spread = f"{min(times):.2f}-{max(times):.2f}"
        per_frame = 1e3 * mid / args.frames
        print(f"| {name} | {mid:.2f} ({spread}) | {per_frame:.2f} | {floor / mid:.2f} |")


if __name__ == "__main__":
    main()
