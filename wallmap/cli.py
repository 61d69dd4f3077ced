"""The ``wallmap`` command: one console script, one subcommand per service or tool.

Every failure a person can cause (a missing bag, a bad flag, no router) ends with one line
``wallmap <command>: error: <why>`` and exit status 1; usage errors exit 2, as argparse does.

Each service, the scenes and the drawing are imported by the command that runs them, not here:
every process would otherwise load every other's modules (a mapper the player's bag readers),
a tenth of a second and more of each service's start.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any, NoReturn, TypeVar

import zenoh

from wallmap import __version__
from wallmap.arg_types import (
    finite,
    non_negative,
    picture,
    positive,
    positive_int,
    robot_prefixes,
)
from wallmap.common.delivery import StalledError
from wallmap.common.link_settings import DEFAULT_CONNECT, TransportError
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply
from wallmap.common.map_requests import QueryError, fetch_map, fetch_rooms
from wallmap.common.runtime import setup_logging, stop_on_signals, thread_failures
from wallmap.common.tf_buffer import TfError
from wallmap.common.transport import (
    Keys,
    StoppedWaiting,
    key_expression,
    open_session,
    zenoh_reason,
)
from wallmap.config import Config, resolve, to_plain, to_toml
from wallmap.doctor import add_command as add_doctor_command
from wallmap.export import write_geojson
from wallmap.foxglove_cli import add_commands as add_foxglove_commands
from wallmap.launcher import LaunchError, demo, up, up_live
from wallmap.map_client import (
    fetch_robots,
    format_rooms,
    format_table,
    robot_paths,
    to_json,
)
from wallmap.options import (
    BAND,
    DETECTOR,
    HISTORY,
    MAPPER,
    ODOMETRY,
    PLAYER,
    POSES,
    ROS2,
    ROS2_TOPICS,
    ROUTER_JOIN,
    ROUTER_ZENOH,
    SLAM,
    SOURCE,
    SPEED,
    STATE,
    UP,
    VIEW,
    ZENOH,
    Option,
    add_command,
    given,
)
from wallmap.services.mapper.pose_input import make_pose_input
from wallmap.services.mapper.state_file import StateError
from wallmap.services.player.errors import PlayerError
from wallmap.status import fetch_status, format_status
from wallmap.status import to_json as status_json
from wallmap.view import add_command as add_view_command

FAILURES = (
    TransportError,
    PlayerError,
    TfError,
    StateError,
    QueryError,
    LaunchError,
    StalledError,
    OSError,
    ValueError,
)
SERVICE = math.inf  # services wait for their router as long as it takes
ASK_AT_LEAST = 0.5  # s a query has, whatever the wait for the router left of --timeout
T = TypeVar("T")
# What `up` does only with a BAG: the live robot's bridge reads its own sensor, as it comes.
BAG_ONLY = (
    *SPEED,
    *(o for o in SOURCE if o.flag != "--pose-source"),
    *(o for o in UP if o.flag == "--exit-when-done"),
)
WALL_FILTERS = ("--bbox", "--since", "--tentative")  # what `query --rooms` refuses
ALL = (
    ZENOH,
    HISTORY,
    SPEED,
    SOURCE,
    PLAYER,
    BAND,
    DETECTOR,
    STATE,
    MAPPER,
    POSES,
    SLAM,
    ODOMETRY,
    UP,
    VIEW,
    ROS2_TOPICS,
)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, without the usage block."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _cmd_router(args: argparse.Namespace, config: Config) -> int:
    log = setup_logging("router")
    stop = stop_on_signals()
    listen = tuple(args.listen or [DEFAULT_CONNECT])
    join = tuple(getattr(args, ROUTER_JOIN.dest) or ())  # the flag only: WALLMAP_CONNECT is
    with open_session(config.zenoh, mode="router", listen=listen, join=join):  # for services
        log.info(
            "listening on %s%s",
            ", ".join(listen),
            f"; joining the routers at {', '.join(join)}" if join else "",
        )
        stop.wait()
    return 0


def _cmd_detector(_: argparse.Namespace, config: Config) -> int:
    from wallmap.services.detector import service as detector_service  # noqa: PLC0415 - see doc

    zenoh_settings = replace(config.zenoh, wait_for_router=SERVICE)
    detector_service.run(zenoh_settings, config.detector, stop_on_signals(), config.history)
    return 0


def _cmd_mapper(_: argparse.Namespace, config: Config) -> int:
    from wallmap.services.mapper import service as mapper_service  # noqa: PLC0415 - see doc

    mapper = config.mapper
    make_pose_input(mapper.pose_format, mapper.pose_frames)  # a bad format fails here, in one line
    if mapper.pose_key is not None:
        key_expression(mapper.pose_key, "--pose-key")
    mapper_service.run(
        replace(config.zenoh, wait_for_router=SERVICE),
        mapper,
        stop_on_signals(),
        config.history,
        to_plain(config),
    )
    return 0


def _cmd_ros2(_: argparse.Namespace, config: Config) -> int:
    from wallmap.services.ros2_source import service as ros2_service  # noqa: PLC0415 - see doc

    zenoh_settings = replace(config.zenoh, wait_for_router=SERVICE)
    ros2_service.run(zenoh_settings, config.ros2, stop_on_signals(), config.history)
    return 0


def _cmd_odometry(_: argparse.Namespace, config: Config) -> int:
    from wallmap.services.odometry import service as odometry_service  # noqa: PLC0415 - see doc

    zenoh_settings = replace(config.zenoh, wait_for_router=SERVICE)
    odometry_service.run(
        zenoh_settings,
        config.odometry,
        stop_on_signals(),
        rows=config.detector.rows,
        history=config.history,
    )
    return 0


def _cmd_merge(args: argparse.Namespace, config: Config) -> int:
    from wallmap.services.merge import service as merge_service  # noqa: PLC0415 - see doc

    zenoh_settings = replace(config.zenoh, wait_for_router=SERVICE)
    merge_service.run(zenoh_settings, args.robots, stop_on_signals())
    return 0


def _cmd_player(args: argparse.Namespace, config: Config) -> int:
    from wallmap.services.player import service as player_service  # noqa: PLC0415 - see doc

    player = config.player
    zenoh_settings = replace(config.zenoh, wait_for_router=player.wait_timeout)
    result = player_service.run(zenoh_settings, args.bag, player, stop_on_signals(), config.history)
    print(result.summary())
    return 0


def _fetch(args: argparse.Namespace, config: Config, **parameters: str) -> MapReply:
    """The live map, filtered by the command's --min-obs and --tentative, and ``parameters``.

    The selection is checked here as the mapper checks it, so a bad --bbox fails at once.
    """
    parameters |= {"min_obs": str(args.min_obs), "tentative": str(args.tentative).lower()}
    query = MapQuery.from_parameters(parameters)
    keys = Keys(config.zenoh.prefix)
    return _ask(args, config, lambda s, left: fetch_map(s, keys, query, timeout=left, wait=True))


def _fetch_rooms(args: argparse.Namespace, config: Config) -> dict[str, Any]:
    """The live rooms and doors (``{prefix}/map/rooms``)."""
    keys = Keys(config.zenoh.prefix)
    return _ask(args, config, lambda s, left: fetch_rooms(s, keys, timeout=left, wait=True))


def _ask(args: argparse.Namespace, config: Config, fetch: Callable[[zenoh.Session, float], T]) -> T:
    """``fetch(session, seconds left)``: --timeout covers the wait for a router and a mapper.

    A command run as the services start (``wallmap up &``, then ``wallmap query``) waits for
    both, rather than failing at once.
    """
    started = time.monotonic()
    with open_session(replace(config.zenoh, wait_for_router=args.timeout)) as session:
        return fetch(session, max(args.timeout - (time.monotonic() - started), ASK_AT_LEAST))


def _cmd_query(args: argparse.Namespace, config: Config) -> int:
    if args.rooms:
        if given := [f for f in WALL_FILTERS if getattr(args, f[2:]) not in (None, False)]:
            msg = f"--rooms answers every room; {', '.join(given)}: walls only"
            raise ValueError(msg)
        body = _fetch_rooms(args, config)
        print(json.dumps(body, indent=1) if args.json else format_rooms(body))
        return 0
    filters = {"bbox": args.bbox, "since": None if args.since is None else repr(args.since)}
    reply = _fetch(args, config, **{k: v for k, v in filters.items() if v is not None})
    print(to_json(reply) if args.json else format_table(reply))
    return 0


def _cmd_status(args: argparse.Namespace, config: Config) -> int:
    with open_session(config.zenoh) as session:
        services = fetch_status(session, Keys(config.zenoh.prefix), timeout=args.timeout)
    print(status_json(services) if args.json else format_status(services, config.zenoh.prefix))
    return 0


def _cmd_up(args: argparse.Namespace, config: Config) -> int:
    if config.up.ros2:
        if args.bag is not None:
            raise PlayerError(f"--ros2 maps a live robot: give it no BAG ({args.bag})")
        _refuse_other_modes_flags(args, BAG_ONLY, "a BAG's, not --ros2's")
        return up_live(config)
    if args.bag is None:
        raise PlayerError("a BAG to play is needed (or --ros2 for a live robot)")
    _refuse_other_modes_flags(args, ROS2_TOPICS, "--ros2's, not a BAG's")
    if config.up.odometry and config.player.source.pose_source not in (None, "tf", "none"):
        msg = (
            "--odometry estimates the poses itself; "
            f"drop --pose-source {config.player.source.pose_source}"
        )
        raise PlayerError(msg)
    return up(config, args.bag)


def _refuse_other_modes_flags(
    args: argparse.Namespace, flags: Iterable[Option], whose: str
) -> None:
    """`up` plays a BAG or maps a live robot: a flag of the other mode would be ignored."""
    if wrong := [o.flag for o in flags if getattr(args, o.dest, None) is not None]:
        raise PlayerError(f"{', '.join(wrong)}: {whose} (it would be ignored)")


def _cmd_scene(args: argparse.Namespace, _: Config) -> int:
    from wallmap.scene import Camera, PoseFaults, write_scene_bag  # noqa: PLC0415 - see doc
    from wallmap.scene.bags import tum_path_for  # noqa: PLC0415 - see doc

    truth = args.out.with_name(f"{args.out.name}.truth.json")
    if args.keep and args.out.exists() and truth.is_file():
        print(f"kept {args.out}: written before (its ground truth {truth} beside it)")
        return 0
    if args.out.exists():
        msg = f"{args.out} exists; choose a new path"
        raise FileExistsError(msg)
    if args.format == "ros1" and args.out.suffix != ".bag":
        msg = f"a ROS 1 bag's name ends in .bag (the player reads it by its suffix): {args.out}"
        raise ValueError(msg)
    if args.format != "ros1" and args.out.suffix:
        folder = args.out.with_suffix("")
        inside = f"{folder.name}.{'mcap' if args.format == 'ros2-mcap' else 'db3'}"
        msg = f"a ROS 2 bag is a folder: name it without a suffix ({folder} holds {inside})"
        raise ValueError(msg)
    faults = PoseFaults(
        latency=args.pose_latency,
        heading_sd_deg=args.pose_noise,
        position_sd=args.pose_position_noise,
        glitches=tuple(args.glitch or ()),
        seed=args.seed,
    )
    info = write_scene_bag(
        args.out,
        seed=args.seed,
        n_frames=args.frames,
        fmt=args.format,
        sensor=args.sensor,
        camera=Camera(width=args.width, height=args.height),
        rate_hz=args.rate,
        compress=args.compress,
        faults=faults,
        reverse=args.reverse,
        own_frame=args.own_frame,
    )
    seen = sum(1 for n in info.seen_counts.values() if n >= 3)
    print(f"wrote {info.path}: {info.n_frames} frames, {seen} walls seen in 3 frames or more")
    print(f"ground truth: {info.truth_path}")
    if args.own_frame:
        x, y, yaw = info.map_in_world
        where = f"x {x:.3f} m, y {y:.3f} m, yaw {math.degrees(yaw):.2f} deg"
        print(f"its map frame in the plan's frame: {where} (map_in_world in the ground truth)")
    if faults.any:
        print(f"the faulty poses as a TUM file: {tum_path_for(info.path)}")
    return 0


def _glitch(text: str) -> object:
    """``--glitch START:DUR:DEG:M`` as a ``wallmap.scene.Glitch``, its error in one line."""
    from wallmap.scene import Glitch  # noqa: PLC0415 - see doc

    try:
        return Glitch.parse(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _cmd_plot(args: argparse.Namespace, config: Config) -> int:
    from wallmap.plot import write_picture  # noqa: PLC0415 - see doc

    reply = _fetch(args, config, trajectory="true")
    rooms = _fetch_rooms(args, config)
    write_picture(args.out, reply, _fleet_paths(args, config, reply), args.size, rooms=rooms)
    print(f"picture: {args.out}")
    return 0


def _fleet_paths(args: argparse.Namespace, config: Config, reply: MapReply) -> list[Any] | None:
    """A fleet's map (its walls have sources): each robot's path in the fleet's frame."""
    if not any(w.sources for w in reply.walls):
        return None
    with open_session(config.zenoh) as session:
        return robot_paths(fetch_robots(session, Keys(config.zenoh.prefix), timeout=args.timeout))


def _cmd_export(args: argparse.Namespace, config: Config) -> int:
    reply = _fetch(args, config, trajectory="true")
    write_geojson(args.out, reply, _fetch_rooms(args, config))
    print(f"GeoJSON: {args.out}")
    return 0


def _cmd_demo(args: argparse.Namespace, config: Config) -> int:
    return demo(args.out, config)


def _cmd_config(_: argparse.Namespace, config: Config) -> int:
    print(to_toml(config), end="")
    return 0


def _add_bag_argument(p: argparse.ArgumentParser, *, optional: bool = False) -> None:
    what = "ROS 1 .bag file, ROS 2 bag folder, or TUM RGB-D folder (depth.txt, depth/*.png)"
    p.add_argument(
        "bag",
        type=Path,
        metavar="BAG",
        nargs="?" if optional else None,
        help=what + (" (not with --ros2)" if optional else ""),
    )


def _add_map_filters(p: argparse.ArgumentParser, *, min_obs: int = 1) -> None:
    p.add_argument(
        "--min-obs",
        type=positive_int,
        default=min_obs,
        metavar="N",
        help="walls seen at least N times",
    )
    p.add_argument("--tentative", action="store_true", help="also walls not yet confirmed")
    p.add_argument(
        "--timeout",
        type=positive,
        default=5.0,
        help="seconds to wait for the router and a mapper to answer (asked again while none is up)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The whole command line."""
    parser = _Parser(
        prog="wallmap", description="Map the walls of a building from a moving RGB-D sensor."
    )
    parser.add_argument("--version", action="version", version=f"wallmap {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    _add_service_commands(sub)
    _add_map_commands(sub)
    _add_scene_command(sub)
    p = add_command(
        sub, "demo", "run the pipeline on the sample bag shipped with wallmap", _cmd_demo
    )
    p.add_argument(
        "--out", type=Path, default=Path("wallmap-demo.png"), help="picture (.png or .svg)"
    )
    add_command(
        sub,
        "config",
        "print the effective configuration as TOML (every flag, --config, "
        "--set): a file for --config",
        _cmd_config,
        *ALL,
    )
    add_foxglove_commands(sub)
    add_doctor_command(sub)
    add_view_command(sub)
    return parser


def _add_service_commands(sub: Any) -> None:
    """The services, one per process: router, player, detector, mapper, odometry, merge, ros2."""
    p = add_command(sub, "router", "a Zenoh router", _cmd_router, ROUTER_ZENOH)
    p.add_argument(
        "--listen", action="append", metavar="ENDPOINT", help=f"default {DEFAULT_CONNECT}"
    )
    p = add_command(
        sub,
        "player",
        "play a bag: sensor frames and poses",
        _cmd_player,
        SPEED,
        SOURCE,
        PLAYER,
        HISTORY,
        ZENOH,
    )
    _add_bag_argument(p)
    add_command(
        sub,
        "detector",
        "sensor frames -> wall observations",
        _cmd_detector,
        DETECTOR,
        BAND,
        HISTORY,
        ZENOH,
    )
    add_command(
        sub,
        "mapper",
        "the EKF wall map, served as a queryable",
        _cmd_mapper,
        STATE,
        MAPPER,
        POSES,
        SLAM,
        HISTORY,
        ZENOH,
    )
    _add_more_service_commands(sub)


def _add_more_service_commands(sub: Any) -> None:
    """The services beyond the core four: odometry, merge (a fleet), ros2 (a live robot)."""
    add_command(
        sub,
        "odometry",
        "poses from the sensor frames (scan matching)",
        _cmd_odometry,
        ODOMETRY,
        HISTORY,
        ZENOH,
    )

    p = add_command(
        sub, "merge", "one map of several robots' maps, aligned by their walls", _cmd_merge, ZENOH
    )
    p.add_argument(
        "--robots",
        type=robot_prefixes,
        required=True,
        metavar="A,B[,...]",
        help="the robots' prefixes; the fleet's map is in the first one's frame",
    )

    add_command(
        sub,
        "ros2",
        "a live ROS 2 robot's topics on Zenoh -> frames and poses",
        _cmd_ros2,
        ROS2,
        HISTORY,
        ZENOH,
    )


def _add_map_commands(sub: Any) -> None:
    """What reads or makes a map: query, status, up, plot, export."""
    p = add_command(sub, "query", "print the current wall map", _cmd_query, ZENOH)
    p.add_argument("--json", action="store_true", help="the contract's JSON instead of a table")
    _add_map_filters(p)
    p.add_argument("--bbox", metavar="XMIN,YMIN,XMAX,YMAX", help="walls crossing this box (m)")
    p.add_argument("--since", type=float, metavar="STAMP", help="walls seen since this stamp")
    p.add_argument(
        "--rooms",
        action="store_true",
        help="all the rooms and doors instead of the walls (not with --bbox, --since, --tentative)",
    )

    p = add_command(sub, "status", "the live services and their counters", _cmd_status, ZENOH)
    p.add_argument("--json", action="store_true", help="JSON instead of a table")
    p.add_argument("--timeout", type=positive, default=2.0, help="seconds to wait for answers")

    p = add_command(
        sub,
        "up",
        "router + detector + mapper (+ odometry) + player, one machine",
        _cmd_up,
        SPEED,
        SOURCE,
        BAND,
        STATE,
        POSES,
        SLAM,
        UP,
        ROS2_TOPICS,
        HISTORY,
        ZENOH,
    )
    _add_bag_argument(p, optional=True)

    p = add_command(sub, "plot", "draw the current map (.png or .svg)", _cmd_plot, ZENOH)
    p.add_argument("out", type=picture, metavar="OUT", help="output file, .png or .svg")
    p.add_argument("--size", type=positive_int, default=1000, help="longer side in pixels")
    _add_map_filters(p)
    p = add_command(sub, "export", "the map as GeoJSON", _cmd_export, ZENOH)
    p.add_argument("out", type=Path, metavar="OUT", help="output file")
    _add_map_filters(p)


def _add_scene_command(sub: Any) -> None:
    """``wallmap scene``: a generated building's bag and its ground truth."""
    p = add_command(
        sub,
        "scene",
        "write a bag of a generated scene, with its ground truth",
        _cmd_scene,
        configured=False,
    )
    p.add_argument("out", type=Path, metavar="OUT", help="bag file (ROS 1) or folder (ROS 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the floor plan and the drive")
    p.add_argument(
        "--frames", type=positive_int, default=600, help="most frames (the drive may end first)"
    )
    p.add_argument("--format", choices=("ros1", "ros2-mcap", "ros2-sqlite3"), default="ros1")
    p.add_argument(
        "--sensor", choices=("pointcloud", "depth16", "depth32", "laserscan"), default="pointcloud"
    )
    p.add_argument("--width", type=positive_int, default=160, help="image width (px)")
    p.add_argument("--height", type=positive_int, default=120, help="image height (px)")
    p.add_argument("--rate", type=positive, default=15.0, help="frames per second")
    p.add_argument("--compress", action="store_true", help="LZ4 chunks (ROS 1)")
    p.add_argument(
        "--keep",
        action="store_true",
        help="a scene written to OUT before (its ground truth beside it) is kept, not an error: "
        "a setup step run again",
    )
    p.add_argument(
        "--reverse",
        action="store_true",
        help="drive the plan's route the other way, from its end to its start: "
        "another robot's drive through the same building",
    )
    p.add_argument(
        "--own-frame",
        action="store_true",
        help="every pose of the bag (tf, /odom, /ground_truth, /amcl_pose, the TUM file) in a "
        "map frame at the robot's first pose; the ground truth's map_in_world places that "
        "frame in the plan's",
    )
    _add_pose_fault_flags(p)


def _add_pose_fault_flags(p: argparse.ArgumentParser) -> None:
    """``wallmap scene``'s poses as real sources give them: late, noisy, at times wrong."""
    p.add_argument(
        "--pose-latency",
        type=finite,
        default=0.0,
        metavar="SECONDS",
        help="every pose source of the bag late by this: its pose stamped t is the "
        "robot's at t - SECONDS",
    )
    p.add_argument(
        "--pose-noise",
        type=non_negative,
        default=0.0,
        metavar="DEG",
        help="white noise of every pose's heading (degrees)",
    )
    p.add_argument(
        "--pose-position-noise",
        type=non_negative,
        default=0.0,
        metavar="M",
        help="white noise of every pose's position (m)",
    )
    p.add_argument(
        "--glitch",
        type=_glitch,
        action="append",
        metavar="START:DUR:DEG:M",
        help="a stretch of wrong poses: from START s for DUR s, DEG degrees and M "
        "metres off (repeatable)",
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # said by the command's own parser: `wallmap up: error: ...`
        command = getattr(args, "command_parser", parser)
        command.error(f"unrecognized arguments: {' '.join(unknown)}")
    func: Callable[[argparse.Namespace, Config], int] = args.func
    try:
        config = resolve(args.config, args.sets, given(args, args.options))
        status = func(args, config)
        if failed := thread_failures():  # logged with its traceback as it happened
            print(f"wallmap {args.command}: error: a worker died: {failed[0]!r}", file=sys.stderr)
            return 1
        return status
    except BrokenPipeError:  # `wallmap query | head -1`: the reader has all it wanted
        # Python would flush stdout again at exit, into the closed pipe, and complain.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except FAILURES as err:
        print(f"wallmap {args.command}: error: {err}", file=sys.stderr)
        return 1
    except StoppedWaiting as stopped:  # asked to stop before there was anything to stop
        logging.getLogger(f"wallmap.{args.command}").info("%s", stopped)  # flushed at once
        # Out at once: the thread still in zenoh.open must not meet the interpreter's shutdown
        # (a router answering then makes Zenoh's thread abort the process).
        os._exit(0)
    except zenoh.ZError as err:  # one Zenoh did not foresee here either: still one line
        print(f"wallmap {args.command}: error: zenoh: {zenoh_reason(err)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
