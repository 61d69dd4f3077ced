"""``wallmap up`` and ``wallmap demo``: a router and the services as processes, one command.

Each service runs as its own process, exactly as in ``docker-compose.yml``, so what works here
works there, and every one reads the same configuration: ``up`` writes the effective one to a
file and starts each service with ``--config`` on it. The player waits for the detector and
mapper to be live before its first frame and, at the end of the bag, for the mapper to
acknowledge every frame; so when it exits, the map is complete and can be fetched.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from wallmap.common.link_settings import TransportError, ZenohSettings
from wallmap.common.map_query import MapQuery
from wallmap.common.map_requests import QueryError, fetch_map, fetch_rooms
from wallmap.common.runtime import stop_on_signals
from wallmap.common.transport import Keys, make_config, open_session
from wallmap.config import Config, UpSettings, to_plain, to_toml, with_odometry_poses
from wallmap.map_client import format_table, to_json

if TYPE_CHECKING:
    from wallmap.scene import FloorPlan, Trajectory

    Truth = tuple[FloorPlan, Trajectory, dict[int, int]]  # a generated scene's (load_truth)

STOP_TIMEOUT = 10.0  # s a service gets to save its state and exit after SIGTERM


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
        # A group of its own: a terminal's Ctrl-C reaches ``up`` alone, which asks the mapper
        # for the map so far before it stops them all (``_Services.stop``).
        proc = subprocess.Popen(_wallmap(*args), env=self._env, process_group=0)
        self._procs.append((name, proc))
        return proc

    def check_running(self) -> None:
        """Raises LaunchError if a service (not the player, which ends) has exited.

        It names all that have: the first one polled need not be the one that failed first.
        """
        ended = [
            f"the {name} exited with status {proc.returncode}"
            for name, proc in self._procs
            if name != "player" and proc.poll() is not None
        ]
        if ended:
            raise LaunchError("; ".join(ended) + " while the bag played")

    def stop(self) -> None:
        """Stop them all; raises LaunchError naming those that did not exit with status 0.

        One stopped while it was still starting, before it listened for SIGTERM, ends by the
        signal itself: that is a clean stop too. The player's own status is ``up``'s, and the
        player has said why it failed.
        """
        failed = []
        for name, proc in reversed(self._procs):
            stopped = proc.poll() is None
            if stopped:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(timeout=STOP_TIMEOUT)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
                    failed.append(f"the {name} did not stop within {STOP_TIMEOUT:.0f} s")
                    continue
            clean = proc.returncode == 0 or (stopped and proc.returncode == -signal.SIGTERM)
            if name != "player" and not clean:
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


def for_services(config: Config) -> Config:
    """The configuration the services of ``up`` run with: the player waits for all of them.

    With ``up.odometry`` the odometry service makes the poses, so the player sends none.
    """
    config = with_odometry_poses(config)
    services = ("detector", "mapper") + (("odometry",) if config.up.odometry else ())
    player = replace(config.player, wait_for=services)
    if config.up.odometry:
        player = replace(player, source=replace(player.source, pose_source="none"))
    return replace(config, player=player)


@contextlib.contextmanager
def _core_services(config: Config) -> Iterator[tuple[_Services, Path]]:
    """Router, mapper, detector (and odometry) on one configuration file; stopped at the end.

    Yields the running services and the file, for the source that feeds them.
    """
    env = {k: v for k, v in os.environ.items() if k not in ("WALLMAP_CONNECT", "WALLMAP_PREFIX")}
    env["WALLMAP_LOG"] = os.environ.get("WALLMAP_LOG", "WARNING")
    with tempfile.TemporaryDirectory(prefix="wallmap-up-") as tmp:
        path = Path(tmp) / "config.toml"
        path.write_text(to_toml(config), encoding="utf-8")
        with _processes(env) as procs:
            listen = config.zenoh.connect[0]
            procs.start("router", "router", "--config", str(path), "--listen", listen)
            for name in ("mapper", "detector", *(("odometry",) if config.up.odometry else ())):
                procs.start(name, name, "--config", str(path))
            yield procs, path


def up(config: Config, bag: Path) -> int:
    """Run router, mapper, detector and player; print the map when the bag is done."""
    config = for_services(config)
    _check_endpoint(config.zenoh)
    truth = _check_outputs(config.up, bag)
    stop = stop_on_signals()
    with _core_services(config) as (procs, path):
        player = procs.start("player", "player", str(bag), "--config", str(path))
        while player.poll() is None and not stop.is_set():
            procs.check_running()
            stop.wait(0.1)
        if stop.is_set():  # asked to stop (Ctrl-C, SIGTERM): the map so far, then stop
            _report_partial(config, bag, truth)
            return 0
        if player.returncode != 0:
            return player.returncode
        _report(config, bag, truth)
        if not config.up.exit_when_done:
            print("the services keep running: `wallmap query` reads the map; Ctrl-C stops them")
            stop.wait()
    return 0


def up_live(config: Config) -> int:
    """Run router, mapper, detector and ``wallmap ros2`` on a live robot; the map when stopped.

    ``--pose-source`` (the player's flag) goes to the live source; with ``up.odometry`` the
    odometry service makes the poses and the source sends none.
    """
    pose_source = "none" if config.up.odometry else config.player.source.pose_source
    ros2 = replace(config.ros2, pose_source=pose_source or config.ros2.pose_source)
    config = replace(with_odometry_poses(config), ros2=ros2)
    _check_endpoint(config.zenoh)
    truth = _check_outputs(config.up, None)
    stop = stop_on_signals()
    with _core_services(config) as (procs, path):
        procs.start("ros2", "ros2", "--config", str(path))
        print("mapping the live robot: Ctrl-C prints the map and stops", file=sys.stderr)
        while not stop.is_set():
            procs.check_running()
            stop.wait(0.1)
        _report(config, None, truth)
    return 0


def _check_endpoint(settings: ZenohSettings) -> None:
    """The endpoint ``up`` starts its router on: valid, and free (not another router's)."""
    make_config(settings)  # a malformed endpoint is one line, before anything starts
    endpoint = settings.connect[0]
    found = re.fullmatch(r"tcp/(.+):(\d+)", endpoint)
    if found is None:
        return
    port = int(found[2])
    if not 0 < port < 65536:
        raise LaunchError(f"cannot start a router on {endpoint}: a port is 1-65535")
    with socket.socket() as probe:
        # As a router binds: a port left in TIME_WAIT by one just stopped is free to it.
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((found[1].strip("[]"), port))
        except OSError as err:
            msg = (
                f"cannot start a router on {endpoint} ({err.strerror}): `wallmap up` runs its "
                "own; give it a free --connect endpoint, or start the services yourself on the "
                "router there (README, Running the services)"
            )
            raise LaunchError(msg) from err


def _check_outputs(options: UpSettings, bag: Path | None) -> Truth | None:
    """What ``up`` reads and writes, checked before anything starts; the truth, read.

    A wrong path fails now, in one line, not after the whole recording has played.
    """
    if bag is not None and not bag.exists():
        raise LaunchError(f"{bag} does not exist")
    for path in (options.json_out, options.picture):
        if path is not None and not path.parent.is_dir():
            raise LaunchError(f"cannot write {path}: {path.parent} is not a folder")
    if options.truth is None:
        return None
    from wallmap.scene import load_truth  # noqa: PLC0415 - see _report

    try:
        return load_truth(options.truth)
    except (OSError, ValueError, KeyError, TypeError) as err:
        reason = err.strerror if isinstance(err, OSError) else f"not a scene's truth ({err})"
        raise LaunchError(f"cannot read the ground truth {options.truth}: {reason}") from err


def _report_partial(config: Config, bag: Path, truth: Truth | None) -> None:
    """The map of a run stopped before its end, written as asked and marked partial.

    A mapper that cannot answer (stopped before it started) leaves nothing to write: said in
    one line.
    """
    try:
        _report(config, bag, truth, partial=True)
    except (QueryError, TransportError) as err:
        print(
            f"stopped before the mapper had a map to give ({err}): nothing written", file=sys.stderr
        )


def _report(
    config: Config, bag: Path | None, truth: Truth | None, *, partial: bool = False
) -> None:
    """The final map: printed, scored, written as JSON (with the configuration), drawn.

    ``partial``: the run was stopped before the recording's end; the JSON says so.
    """
    # Scoring and drawing, imported here: every `wallmap` command would pay for them.
    from wallmap.evaluation import evaluate_map  # noqa: PLC0415 - see above
    from wallmap.plot import write_picture  # noqa: PLC0415 - see above
    from wallmap.room_evaluation import evaluate_rooms  # noqa: PLC0415 - see above

    options = config.up
    with open_session(config.zenoh) as session:
        query = MapQuery(min_obs=options.min_obs, trajectory=True)
        reply = fetch_map(session, Keys(config.zenoh.prefix), query)
        wanted = options.json_out or options.picture or truth is not None
        rooms = fetch_rooms(session, Keys(config.zenoh.prefix)) if wanted else None
    if partial:
        print(
            f"stopped before the end of the recording: the map of its first {reply.frames} frames"
        )
    print(format_table(reply))
    if reply.frames and not reply.observations:
        nothing = f"no line was seen in any of the {reply.frames} frames"
        why = "nothing in the band the detector reads, or the camera is read wrong"
        ask = (
            f"(a TUM folder's --intrinsics, --depth-scale): `wallmap doctor {bag}` says more"
            if bag is not None
            else "(the --sensor topic and its type)"
        )
        print(f"wallmap up: {nothing}: {why} {ask}", file=sys.stderr)
    if truth is not None:
        plan, trajectory, seen = truth
        print(f"against the ground truth: {evaluate_map(reply.walls, plan, seen).summary()}")
        if plan.rooms and rooms is not None:
            score = evaluate_rooms(rooms, plan, trajectory.positions)
            print(f"rooms against the ground truth: {score.summary()}")
    if options.json_out:
        document = to_json(reply, config=to_plain(config), partial=partial, rooms=rooms)
        options.json_out.write_text(document, "utf-8")
    if options.picture:
        write_picture(options.picture, reply, rooms=rooms)
        print(f"picture: {options.picture}")


def sample_bag() -> Path:
    """The sample bag shipped inside the package."""
    return Path(str(resources.files("wallmap") / "data" / "sample.bag"))


def demo(out: Path, config: Config | None = None) -> int:
    """``wallmap up`` on the sample bag, on a private loopback port, with a picture.

    ``config``: the tuning (``--config``, ``--set``) the run is made with; where it runs and
    what it writes are the demo's own.
    """
    bag = sample_bag()
    base = config or Config()
    config = replace(
        base,
        zenoh=ZenohSettings(connect=(f"tcp/127.0.0.1:{free_loopback_port()}",)),
        player=replace(base.player, fast=True),
        up=replace(
            base.up,
            exit_when_done=True,
            picture=out,
            truth=bag.with_name(bag.name + ".truth.json"),
        ),
    )
    return up(config, bag)
