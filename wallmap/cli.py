"""The ``wallmap`` command: one console script, one subcommand per service or tool.

Every failure a person can cause (a missing bag, a bad flag, no router) ends with one line
``wallmap <command>: error: <why>`` and exit status 1; usage errors exit 2, as argparse does.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

import zenoh

from wallmap import __version__
from wallmap.arg_types import finite, intrinsics, non_negative, positive
from wallmap.common.history import History
from wallmap.common.ransac import RansacParams
from wallmap.common.runtime import setup_logging, stop_on_signals
from wallmap.common.scan_row import RowSelection
from wallmap.common.tf_buffer import TfError
from wallmap.common.transport import (
    DEFAULT_CONNECT,
    Keys,
    TransportError,
    add_zenoh_arguments,
    key_expression,
    open_session,
    settings_from_args,
    zenoh_reason,
)
from wallmap.doctor import add_command as add_doctor_command
from wallmap.export import write_geojson
from wallmap.foxglove_cli import add_commands as add_foxglove_commands
from wallmap.launcher import LaunchError, UpOptions, demo, up
from wallmap.map_client import QueryError, fetch_map, format_table, to_json
from wallmap.plot import write_picture
from wallmap.scene import Camera, write_scene_bag
from wallmap.services.detector import service as detector_service
from wallmap.services.detector.detector import DetectorConfig
from wallmap.services.mapper import service as mapper_service
from wallmap.services.mapper.pose_correction import SlamConfig
from wallmap.services.mapper.pose_input import FORMATS as POSE_FORMATS
from wallmap.services.mapper.pose_input import make_pose_input
from wallmap.services.mapper.state_file import StateError
from wallmap.services.odometry import service as odometry_service
from wallmap.services.odometry.tracker import OdometryConfig
from wallmap.services.player import service as player_service
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.sources import SourceOptions
from wallmap.services.player.tum_folder import TUM_DEPTH_SCALE, TUM_INTRINSICS
from wallmap.status import fetch_status, format_status
from wallmap.status import to_json as status_json
from wallmap.view import add_command as add_view_command

FAILURES = (
    TransportError, PlayerError, TfError, StateError, QueryError, LaunchError, OSError, ValueError,
)  # fmt: skip


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, without the usage block."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _pose(value: str) -> tuple[float, float, float]:
    try:
        x, y, yaw = (float(v) for v in value.split(","))
    except ValueError:
        msg = f"expected X,Y,YAW (metres, radians), got {value!r}"
        raise argparse.ArgumentTypeError(msg) from None
    if not all(map(math.isfinite, (x, y, yaw))):
        msg = f"X,Y,YAW must be finite, got {value!r}"
        raise argparse.ArgumentTypeError(msg)
    return x, y, yaw


def _band(value: str) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in value.split(","))
    except ValueError as err:
        msg = f"expected LOW,HIGH in metres, got {value!r}"
        raise argparse.ArgumentTypeError(msg) from err
    if not low < high:
        msg = f"LOW must be below HIGH, got {value!r}"
        raise argparse.ArgumentTypeError(msg)
    return low, high


def _cmd_router(args: argparse.Namespace) -> int:
    log = setup_logging("router")
    stop = stop_on_signals()
    listen = tuple(args.listen or [DEFAULT_CONNECT])
    settings = settings_from_args(args, wait_for_router=0.0)
    with open_session(settings, mode="router", listen=listen):
        log.info("listening on %s", ", ".join(listen))
        stop.wait()
    return 0


def _cmd_detector(args: argparse.Namespace) -> int:
    config = DetectorConfig(
        rows=RowSelection(mode=args.rows, band=args.band, row_fraction=args.row_fraction),
        ransac=RansacParams(noise_k=args.noise_k),
        seed=args.seed,
    )
    detector_service.run(
        settings_from_args(args, wait_for_router=math.inf),
        config,
        stop_on_signals(),
        History(seconds=args.history),
    )
    return 0


def _cmd_mapper(args: argparse.Namespace) -> int:
    make_pose_input(args.pose_format, args.pose_frames)  # a bad format fails here, in one line
    mapper = mapper_service.MapperSettings(
        state=args.state,
        pose_key=args.pose_key and key_expression(args.pose_key, "--pose-key"),
        pose_format=args.pose_format,
        pose_frames=args.pose_frames,
        pose_wait=args.pose_wait,
        gap_wait=args.gap_wait,
        history=History(seconds=args.history),
        slam=SlamConfig() if args.slam else None,
        ros2_out=args.ros2_out,
    )
    mapper_service.run(
        settings_from_args(args, wait_for_router=math.inf), mapper, stop_on_signals()
    )
    return 0


def _cmd_odometry(args: argparse.Namespace) -> int:
    config = OdometryConfig(initial_pose=args.initial_pose, use_walls=not args.no_walls)
    odometry_service.run(
        settings_from_args(args, wait_for_router=math.inf),
        config,
        stop_on_signals(),
        history=History(seconds=args.history),
    )
    return 0


def _cmd_player(args: argparse.Namespace) -> int:
    player = player_service.PlayerSettings(
        bag=args.bag,
        rate=args.rate,
        fast=args.fast,
        source=_source_options(args),
        wait_for=tuple(filter(None, args.wait_for.split(",")))
        if args.wait_for is not None
        else ("detector", "mapper")
        if args.fast
        else (),
        wait_timeout=args.wait_timeout,
        whole_clouds=args.whole_clouds,
        start=args.start,
        duration=args.duration,
        loop=args.loop,
        paused=args.paused,
        history=History(seconds=args.history),
    )
    settings = settings_from_args(args, wait_for_router=args.wait_timeout)
    result = player_service.run(settings, player, stop_on_signals())
    print(result.summary())
    return 0


def _fetch(args: argparse.Namespace, **parameters: object) -> dict[str, object]:
    """The live map, filtered by the command's --min-obs and --tentative, and ``parameters``."""
    settings = settings_from_args(args, wait_for_router=0.0)
    with open_session(settings) as session:
        return fetch_map(
            session,
            Keys(settings.prefix),
            timeout=args.timeout,
            min_obs=args.min_obs,
            tentative=args.tentative or None,
            **parameters,
        )


def _cmd_query(args: argparse.Namespace) -> int:
    reply = _fetch(args, bbox=args.bbox, since=args.since)
    print(to_json(reply) if args.json else format_table(reply))
    return 0


def _cmd_status(args: argparse.Namespace) -> int:
    settings = settings_from_args(args, wait_for_router=0.0)
    with open_session(settings) as session:
        services = fetch_status(session, Keys(settings.prefix), timeout=args.timeout)
    print(status_json(services) if args.json else format_status(services, settings.prefix))
    return 0


def _cmd_up(args: argparse.Namespace) -> int:
    settings = settings_from_args(args, wait_for_router=0.0)
    options = UpOptions(
        bag=args.bag,
        fast=args.fast,
        rate=args.rate,
        source=_source_options(args),
        band=args.band,
        state=args.state,
        exit_when_done=args.exit_when_done,
        json_out=args.json_out,
        picture=args.picture,
        min_obs=args.min_obs,
        truth=args.truth,
        odometry=args.odometry,
        history=args.history,
        slam=args.slam,
    )
    if args.odometry and args.pose_source not in (None, "tf", "none"):
        msg = f"--odometry estimates the poses itself; drop --pose-source {args.pose_source}"
        raise PlayerError(msg)
    return up(settings, options)


def _cmd_scene(args: argparse.Namespace) -> int:
    if args.out.exists():
        msg = f"{args.out} exists; choose a new path"
        raise FileExistsError(msg)
    if args.format == "ros1" and args.out.suffix != ".bag":
        msg = f"a ROS 1 bag's name ends in .bag (the player reads it by its suffix): {args.out}"
        raise ValueError(msg)
    info = write_scene_bag(
        args.out,
        seed=args.seed,
        n_frames=args.frames,
        fmt=args.format,
        sensor=args.sensor,
        camera=Camera(width=args.width, height=args.height),
        rate_hz=args.rate,
        compress=args.compress,
    )
    seen = sum(1 for n in info.seen_counts.values() if n >= 3)
    print(f"wrote {info.path}: {info.n_frames} frames, {seen} walls seen in 3 frames or more")
    print(f"ground truth: {info.truth_path}")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    write_picture(args.out, _fetch(args, trajectory=True), size=args.size)
    print(f"picture: {args.out}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    write_geojson(args.out, _fetch(args, trajectory=True))
    print(f"GeoJSON: {args.out}")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    return demo(args.out)


def _add_bag_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "bag",
        type=Path,
        metavar="BAG",
        help="ROS 1 .bag file, ROS 2 bag folder, or TUM RGB-D folder (depth.txt, depth/*.png)",
    )
    speed = p.add_mutually_exclusive_group()
    speed.add_argument("--rate", type=positive, default=1.0, help="speed factor (default 1)")
    speed.add_argument("--fast", action="store_true", help="as fast as the pipeline takes it")
    p.add_argument(
        "--pose-source",
        metavar="SPEC",
        help="tf | tf:PARENT>CHILD | odom[:TOPIC] | pose[:TOPIC] | tum:FILE | none (default: tf "
        "for a bag, the folder's groundtruth.txt for a TUM folder)",
    )
    p.add_argument("--sensor-topic", metavar="TOPIC", help="sensor topic, if the bag has several")
    p.add_argument(
        "--level",
        choices=("auto", "none"),
        default="auto",
        help="auto (default): level a fixed frame that is not level, and find its floor, from "
        "the depth data; none: take it as it is, floor at z = 0",
    )
    p.add_argument(
        "--floor-z", type=finite, metavar="Z", help="the floor's height in the fixed frame (m)"
    )
    p.add_argument(
        "--intrinsics",
        type=intrinsics,
        default=TUM_INTRINSICS,
        metavar="FX,FY,CX,CY",
        help="a TUM folder's camera, pixels (default TUM's 525,525,319.5,239.5)",
    )
    p.add_argument(
        "--depth-scale",
        type=positive,
        default=TUM_DEPTH_SCALE,
        metavar="N",
        help="a TUM folder's depth units per metre (default 5000; 1000 for millimetres)",
    )


def _add_slam_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--slam",
        action="store_true",
        help="take the poses as odometry and correct them with the walls; the corrected pose "
        "goes out on {prefix}/pose/corrected, map -> odom on {prefix}/pose/correction",
    )


def _add_history_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--history",
        type=positive,
        default=History.seconds,
        metavar="SECONDS",
        help="how much of the live streams is kept for a service that restarts or a link that "
        f"comes back (default {History.seconds:g} s; at most 512 MB a stream)",
    )


def _add_band_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--band",
        type=_band,
        default=None,
        metavar="LOW,HIGH",
        help="height band (m above the floor; default: what the sensor sees above furniture, "
        "at most 1.3-2.1)",
    )


def _source_options(args: argparse.Namespace) -> SourceOptions:
    return SourceOptions(
        sensor_topic=args.sensor_topic,
        pose_source=args.pose_source,
        topics=tuple(filter(None, args.topics.split(",")))
        if getattr(args, "topics", None)
        else None,
        level=args.level,
        floor_z=args.floor_z,
        intrinsics=args.intrinsics,
        depth_scale=args.depth_scale,
    )


def build_parser() -> argparse.ArgumentParser:
    """The whole command line."""
    parser = _Parser(
        prog="wallmap", description="Map the walls of a building from a moving RGB-D sensor."
    )
    parser.add_argument("--version", action="version", version=f"wallmap {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("router", help="a Zenoh router")
    p.add_argument(
        "--listen", action="append", metavar="ENDPOINT", help=f"default {DEFAULT_CONNECT}"
    )
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_router)

    p = sub.add_parser("player", help="play a bag: sensor frames and poses")
    _add_history_argument(p)
    _add_bag_arguments(p)
    p.add_argument(
        "--wait-timeout", type=positive, default=30.0, help="wait for router and services (s)"
    )
    p.add_argument(
        "--whole-clouds",
        action="store_true",
        help="send whole clouds, not only the row the detector asks for (e.g. to record them)",
    )
    p.add_argument("--start", type=non_negative, default=0.0, help="begin S seconds into the bag")
    p.add_argument("--duration", type=positive, help="play S seconds of the bag")
    p.add_argument("--loop", action="store_true", help="start over at the end, until stopped")
    p.add_argument("--topics", metavar="T1,T2", help="read only these topics (sensor, tf, poses)")
    p.add_argument(
        "--paused", action="store_true", help="start paused (resume or step: keys or control)"
    )
    p.add_argument(
        "--wait-for",
        metavar="SERVICES",
        help="services to wait for before playing, comma-separated (default with --fast: "
        "detector,mapper; else none); waiting for the mapper also waits for it to finish",
    )
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_player)

    p = sub.add_parser("detector", help="sensor frames -> wall observations")
    _add_history_argument(p)
    p.add_argument(
        "--rows", choices=("band", "row"), default="band", help="row choice (default band)"
    )
    _add_band_argument(p)
    p.add_argument(
        "--row-fraction", type=float, default=0.25, help="row from the top, for --rows row"
    )
    p.add_argument(
        "--noise-k", type=float, default=1.425e-3, help="depth noise: sigma = k * range^2"
    )
    p.add_argument("--seed", type=int, default=0, help="RANSAC seed")
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_detector)

    p = sub.add_parser("mapper", help="the EKF wall map, served as a queryable")
    _add_history_argument(p)
    p.add_argument(
        "--state", type=Path, metavar="FILE", help="keep the map in FILE across restarts"
    )
    p.add_argument(
        "--pose-key", metavar="KEYEXPR", help="where poses come from (default PREFIX/pose)"
    )
    p.add_argument(
        "--pose-format",
        default="wallmap",
        choices=POSE_FORMATS,
        metavar="FORMAT",
        help="wallmap (default) or ros2:TYPE for CDR from a ROS 2 system: "
        + ", ".join(POSE_FORMATS[1:]),
    )
    p.add_argument(
        "--pose-frames",
        default="map>base_link",
        metavar="PARENT>CHILD",
        help="the pose wanted from ros2:tf2_msgs/msg/TFMessage (default map>base_link)",
    )
    p.add_argument("--pose-wait", type=positive, default=5.0, help="max wait for a pose (s)")
    _add_slam_argument(p)
    p.add_argument(
        "--ros2-out",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="publish the map as ROS 2 messages on {prefix}/markers (MarkerArray) and "
        "{prefix}/trajectory (Path), CDR, for RViz through zenoh-bridge-ros2dds (default on)",
    )
    p.add_argument(
        "--gap-wait",
        type=positive,
        default=mapper_service.MapperSettings.gap_wait,
        metavar="SECONDS",
        help="how long a frame waits for the earlier ones of its run to come back from history "
        f"before they are given up as lost (default {mapper_service.MapperSettings.gap_wait:g} s)",
    )
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_mapper)

    p = sub.add_parser("odometry", help="poses from the sensor frames (scan matching)")
    _add_history_argument(p)
    p.add_argument(
        "--initial-pose",
        type=_pose,
        default=(0.0, 0.0, 0.0),
        metavar="X,Y,YAW",
        help="where the first scan was taken, in the map frame (default 0,0,0)",
    )
    p.add_argument(
        "--no-walls", action="store_true", help="do not refine poses against the mapped walls"
    )
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_odometry)

    p = sub.add_parser("query", help="print the current wall map")
    p.add_argument("--json", action="store_true", help="the contract's JSON instead of a table")
    p.add_argument(
        "--min-obs", type=int, default=1, metavar="N", help="walls seen at least N times"
    )
    p.add_argument("--tentative", action="store_true", help="also walls not yet confirmed")
    p.add_argument("--bbox", metavar="XMIN,YMIN,XMAX,YMAX", help="walls crossing this box (m)")
    p.add_argument("--since", type=float, metavar="STAMP", help="walls seen since this stamp")
    p.add_argument("--timeout", type=positive, default=5.0, help="seconds to wait for the mapper")
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_query)

    p = sub.add_parser("status", help="the live services and their counters")
    p.add_argument("--json", action="store_true", help="JSON instead of a table")
    p.add_argument("--timeout", type=positive, default=2.0, help="seconds to wait for answers")
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_status)

    p = sub.add_parser("up", help="router + detector + mapper (+ odometry) + player, one machine")
    _add_history_argument(p)
    _add_slam_argument(p)
    _add_bag_arguments(p)
    _add_band_argument(p)
    p.add_argument("--state", type=Path, metavar="FILE", help="the mapper's state file")
    p.add_argument("--exit-when-done", action="store_true", help="stop everything after the bag")
    p.add_argument("--json-out", type=Path, metavar="FILE", help="write the final map as JSON")
    p.add_argument("--picture", type=Path, metavar="FILE", help="draw the final map (.png or .svg)")
    p.add_argument(
        "--min-obs", type=int, default=3, metavar="N", help="walls printed: seen N times"
    )
    p.add_argument(
        "--truth", type=Path, metavar="FILE", help="score the map against a scene's truth"
    )
    p.add_argument(
        "--odometry",
        action="store_true",
        help="estimate the poses from the scans (wallmap odometry), for bags without poses",
    )
    add_zenoh_arguments(p)
    p.set_defaults(func=_cmd_up)

    for name, what in (
        ("plot", "draw the current map (.png or .svg)"),
        ("export", "the map as GeoJSON"),
    ):
        p = sub.add_parser(name, help=what)
        p.add_argument("out", type=Path, metavar="OUT", help="output file")
        if name == "plot":
            p.add_argument("--size", type=int, default=1000, help="longer side in pixels")
        p.add_argument("--min-obs", type=int, default=1, metavar="N", help="walls seen N times")
        p.add_argument("--tentative", action="store_true", help="also walls not yet confirmed")
        p.add_argument(
            "--timeout", type=positive, default=5.0, help="seconds to wait for the mapper"
        )
        add_zenoh_arguments(p)
        p.set_defaults(func=_cmd_plot if name == "plot" else _cmd_export)

    p = sub.add_parser("scene", help="write a bag of a generated scene, with its ground truth")
    p.add_argument("out", type=Path, metavar="OUT", help="bag file (ROS 1) or folder (ROS 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the floor plan and the drive")
    p.add_argument("--frames", type=int, default=600, help="most frames (the drive may end first)")
    p.add_argument("--format", choices=("ros1", "ros2-mcap", "ros2-sqlite3"), default="ros1")
    p.add_argument(
        "--sensor", choices=("pointcloud", "depth16", "depth32", "laserscan"), default="pointcloud"
    )
    p.add_argument("--width", type=int, default=160, help="image width (px)")
    p.add_argument("--height", type=int, default=120, help="image height (px)")
    p.add_argument("--rate", type=positive, default=15.0, help="frames per second")
    p.add_argument("--compress", action="store_true", help="LZ4 chunks (ROS 1)")
    p.set_defaults(func=_cmd_scene)

    p = sub.add_parser("demo", help="run the pipeline on the sample bag shipped with wallmap")
    p.add_argument(
        "--out", type=Path, default=Path("wallmap-demo.png"), help="picture (.png or .svg)"
    )
    p.set_defaults(func=_cmd_demo)
    add_foxglove_commands(sub)
    add_doctor_command(sub)
    add_view_command(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script."""
    args = build_parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except FAILURES as err:
        print(f"wallmap {args.command}: error: {err}", file=sys.stderr)
        return 1
    except zenoh.ZError as err:  # one Zenoh did not foresee here either: still one line
        print(f"wallmap {args.command}: error: zenoh: {zenoh_reason(err)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
