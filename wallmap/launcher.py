"""``wallmap up`` and ``wallmap demo``: a router and the services as processes, one command.

Each service runs as its own process, exactly as in ``docker-compose.yml``, so what works here
works there. The player waits for the detector and mapper to be live before its first frame and,
at the end of the bag, for the mapper to acknowledge every frame; so when it exits, the map is
complete and can be fetched.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

from wallmap.common.history import History
from wallmap.common.runtime import stop_on_signals
from wallmap.common.transport import Keys, ZenohSettings, open_session
from wallmap.evaluation import evaluate_map
from wallmap.map_client import fetch_map, format_table, to_json
from wallmap.plot import write_picture
from wallmap.scene import load_truth
from wallmap.services.player.sources import SourceOptions

STOP_TIMEOUT = 10.0  # s a service gets to save its state and exit after SIGTERM


@dataclass(frozen=True)
class UpOptions:
    """What ``wallmap up`` runs and what it writes."""

    bag: Path
    fast: bool = False
    rate: float = 1.0
    source: SourceOptions = field(default_factory=SourceOptions)
    band: tuple[float, float] | None = None
    state: Path | None = None
    exit_when_done: bool = False
    json_out: Path | None = None
    picture: Path | None = None
    min_obs: int = 3
    truth: Path | None = None
    odometry: bool = False  # poses from the scans (wallmap odometry), for bags without poses
    history: float = History.seconds  # s of the live streams kept for a service that restarts
    slam: bool = False  # the mapper corrects the poses with the walls (mapper --slam)


def source_flags(source: SourceOptions) -> list[str]:
    """The player's command-line flags that read a recording as ``source`` says."""
    flags = ["--level", source.level]
    if source.pose_source is not None:
        flags += ["--pose-source", source.pose_source]
    if source.sensor_topic is not None:
        flags += ["--sensor-topic", source.sensor_topic]
    if source.topics is not None:
        flags += ["--topics", ",".join(source.topics)]
    if source.floor_z is not None:
        flags += ["--floor-z", repr(source.floor_z)]
    flags += ["--intrinsics", ",".join(repr(v) for v in source.intrinsics)]
    return [*flags, "--depth-scale", repr(source.depth_scale)]


def free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wallmap(*args: str) -> list[str]:
    return [sys.executable, "-m", "wallmap", *args]


class LaunchError(RuntimeError):
    """A service of ``wallmap up`` failed; the message names it and its exit status."""


class _Services:
    """The started processes by name; stopped in reverse order, SIGTERM then SIGKILL.

    Their logs go to this terminal. A service that exits while the bag plays, or that does not
    exit cleanly when stopped, is a failure of ``up`` with its name and status.
    """

    def __init__(self, env: dict[str, str]) -> None:
        self._env = env
        self._procs: list[tuple[str, subprocess.Popen[bytes]]] = []

    def start(self, name: str, *args: str) -> subprocess.Popen[bytes]:
        proc = subprocess.Popen(_wallmap(*args), env=self._env)
        self._procs.append((name, proc))
        return proc

    def check_running(self) -> None:
        """Raises LaunchError if a service (not the player, which ends) has exited."""
        for name, proc in self._procs:
            if name != "player" and proc.poll() is not None:
                msg = f"the {name} exited with status {proc.returncode} while the bag played"
                raise LaunchError(msg)

    def stop(self) -> None:
        """Stop them all; raises LaunchError naming those that did not exit with status 0."""
        failed = []
        for name, proc in reversed(self._procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(timeout=STOP_TIMEOUT)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
                    failed.append(f"the {name} did not stop within {STOP_TIMEOUT:.0f} s")
                    continue
            if proc.returncode != 0:
                failed.append(f"the {name} exited with status {proc.returncode}")
        if failed:
            raise LaunchError("; ".join(failed))


@contextlib.contextmanager
def _processes(env: dict[str, str]) -> Iterator[_Services]:
    services = _Services(env)
    try:
        yield services
    except BaseException:
        with contextlib.suppress(LaunchError):  # the first failure is the one to tell
            services.stop()
        raise
    services.stop()


def up(settings: ZenohSettings, options: UpOptions) -> int:
    """Run router, mapper, detector and player; print the map when the bag is done."""
    endpoint = settings.connect[0]
    common = ["--connect", endpoint, "--prefix", settings.prefix]
    common += ["--history", repr(options.history)]
    if settings.config_file:
        common += ["--zenoh-config", str(settings.config_file)]
    env = {**os.environ, "WALLMAP_LOG": os.environ.get("WALLMAP_LOG", "WARNING")}
    mapper_args = ["mapper", *common] + (["--state", str(options.state)] if options.state else [])
    mapper_args += ["--slam"] if options.slam else []
    speed = ["--fast"] if options.fast else ["--rate", str(options.rate)]
    source = options.source
    if options.odometry:
        source = replace(source, pose_source="none")
    services = ["detector", "mapper"] + (["odometry"] if options.odometry else [])
    player_args = ["player", str(options.bag), *speed, *source_flags(source)]
    player_args += ["--wait-for", ",".join(services), *common]
    detector_args = ["detector", *common]
    if options.band is not None:
        detector_args += ["--band", f"{options.band[0]},{options.band[1]}"]
    stop = stop_on_signals()
    with _processes(env) as procs:
        procs.start("router", "router", "--listen", endpoint, "--prefix", settings.prefix)
        procs.start("mapper", *mapper_args)
        procs.start("detector", *detector_args)
        if options.odometry:
            procs.start("odometry", "odometry", *common)
        player = procs.start("player", *player_args)
        while player.poll() is None and not stop.is_set():
            procs.check_running()
            stop.wait(0.1)
        if stop.is_set():
            return 0  # asked to stop (Ctrl-C, SIGTERM): the services stop cleanly
        if player.returncode != 0:
            return player.returncode
        with open_session(settings) as session:
            reply = fetch_map(
                session, Keys(settings.prefix), min_obs=options.min_obs, trajectory=True
            )
        print(format_table(reply))
        if options.truth:
            plan, _, seen = load_truth(options.truth)
            print(f"against the ground truth: {evaluate_map(reply['walls'], plan, seen).summary()}")
        if options.json_out:
            options.json_out.write_text(to_json(reply), encoding="utf-8")
        if options.picture:
            write_picture(options.picture, reply)
            print(f"picture: {options.picture}")
        if not options.exit_when_done:
            print("the services keep running: `wallmap query` reads the map; Ctrl-C stops them")
            stop.wait()
    return 0


def sample_bag() -> Path:
    """The sample bag shipped inside the package."""
    return Path(str(resources.files("wallmap") / "data" / "sample.bag"))


def demo(out: Path) -> int:
    """``wallmap up`` on the sample bag, on a private loopback port, with a picture."""
    settings = ZenohSettings(connect=(f"tcp/127.0.0.1:{free_loopback_port()}",))
    bag = sample_bag()
    truth = bag.with_name(bag.name + ".truth.json")
    options = UpOptions(bag=bag, fast=True, exit_when_done=True, picture=out, truth=truth)
    return up(settings, options)
