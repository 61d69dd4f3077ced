"""The commands' flags, each a short way to set one key of the configuration.

A flag is declared once, with the configuration key it sets (``--rate`` sets ``player.rate``);
its default is the configuration's, shown in ``--help``, so nothing is repeated between the
command line and the dataclasses. A flag left out sets nothing: the file, ``--set`` or the
default decide. Flags that are not configuration (what to print, where to write one picture)
stay plain argparse arguments of their command.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wallmap.arg_types import (
    band,
    domain_id,
    finite,
    intrinsics,
    non_negative,
    picture,
    planar_pose,
    port,
    positive,
)
from wallmap.common.config_file import Tree
from wallmap.config import Config
from wallmap.services.mapper.pose_input import FORMATS as POSE_FORMATS


def _names(value: str) -> tuple[str, ...]:
    return tuple(filter(None, (v.strip() for v in value.split(","))))


@dataclass(frozen=True)
class Option:
    """A flag that sets one configuration key.

    Attributes:
        flag: The flag, e.g. ``--rate``.
        key: The dotted configuration key it sets, e.g. ``player.rate``.
        help: What it does; the configuration's default is added.
        kind: Reads the flag's text (argparse ``type``); a bad value is one line.
        metavar: The value's name in ``--help``.
        choices: The values allowed.
        const: A switch: the flag sets the key to this value.
        repeat: The flag may be given several times; the key gets the list.
        negatable: ``--x`` sets true, ``--no-x`` false.
        exclusive: Options naming the same group here may not be given together.
        show_default: Whether ``--help`` shows the key's default (not when the flag means
            something else there, as the router's ``--connect``).
    """

    flag: str
    key: str
    help: str
    kind: Callable[[str], Any] | None = None
    metavar: str | None = None
    choices: tuple[str, ...] | None = None
    const: Any = None
    repeat: bool = False
    negatable: bool = False
    exclusive: str | None = None
    show_default: bool = True

    @property
    def dest(self) -> str:
        """Where argparse keeps the value: the key, dots made safe."""
        return "set__" + self.key.replace(".", "__")

    def add_to(self, parser: argparse.ArgumentParser | Any, defaults: Config) -> None:
        """Add the flag to ``parser``; ``--help`` shows the default from ``defaults``."""
        text = self.help
        if self.show_default:
            text += _default_text(_lookup(defaults, self.key), self)
        common: dict[str, Any] = {"dest": self.dest, "default": None, "help": text}
        if self.const is not None:
            parser.add_argument(self.flag, action="store_const", const=self.const, **common)
        elif self.negatable:
            parser.add_argument(self.flag, action=argparse.BooleanOptionalAction, **common)
        else:
            action = "append" if self.repeat else "store"
            metavar = self.metavar or (None if self.choices else self.key.rsplit(".")[-1].upper())
            parser.add_argument(
                self.flag,
                action=action,
                type=self.kind,
                metavar=metavar,
                choices=self.choices,
                **common,
            )


def _lookup(config: Any, key: str) -> Any:
    for name in key.split("."):
        config = getattr(config, name)
    return config


def _default_text(value: Any, option: Option) -> str:
    if option.negatable:
        return f" (default {'on' if value else 'off'})"
    if value is None or option.const is not None:
        return ""
    if isinstance(value, tuple):
        value = ",".join(map(str, value))
    return f" (default {value})" if value != "" else " (default: none)"


def add_options(parser: argparse.ArgumentParser | Any, options: Iterable[Option]) -> None:
    """Add ``options`` to a command's parser (or one of its argument groups)."""
    defaults = Config()
    groups: dict[str, Any] = {}
    for option in options:
        if option.exclusive is None:
            option.add_to(parser, defaults)
            continue
        if option.exclusive not in groups:
            groups[option.exclusive] = parser.add_mutually_exclusive_group()
        option.add_to(groups[option.exclusive], defaults)


def given(args: argparse.Namespace, options: Iterable[Option]) -> Tree:
    """The keys the command line set, as a tree to lay over the configuration."""
    tree: Tree = {}
    for option in options:
        value = getattr(args, option.dest, None)
        if value is None:
            continue
        node = tree
        *parents, last = option.key.split(".")
        for name in parents:
            node = node.setdefault(name, {})
        node[last] = list(value) if isinstance(value, tuple) else value
    return tree


# --- the flags, by what they configure ----------------------------------------------------------

ZENOH = (
    Option(
        "--connect",
        "zenoh.connect",
        "router endpoint, repeatable; env WALLMAP_CONNECT",
        metavar="ENDPOINT",
        repeat=True,
    ),
    Option("--prefix", "zenoh.prefix", "key prefix; env WALLMAP_PREFIX", metavar="PREFIX"),
    Option(
        "--zenoh-config",
        "zenoh.config_file",
        "Zenoh json5 config applied first",
        Path,
        metavar="FILE",
    ),
)

ROUTER_JOIN = Option(
    "--connect",
    "zenoh.connect",
    "another router to join, repeatable: a "
    "mesh, each robot's router joined to the map's (default: none)",
    metavar="ENDPOINT",
    repeat=True,
    show_default=False,
)
ROUTER_ZENOH = (ROUTER_JOIN, ZENOH[2])  # a router serves every prefix: it has none

HISTORY = (
    Option(
        "--history",
        "history.seconds",
        "seconds of the live streams kept for a service that "
        "restarts or a link that comes back (at most 512 MB a stream)",
        positive,
        metavar="SECONDS",
    ),
)

SPEED = (
    Option("--rate", "player.rate", "speed factor", positive, metavar="X", exclusive="speed"),
    Option(
        "--fast",
        "player.fast",
        "as fast as the pipeline takes it, losing nothing",
        const=True,
        exclusive="speed",
    ),
)

SOURCE = (
    Option(
        "--pose-source",
        "player.source.pose_source",
        "tf | tf:PARENT>CHILD | odom[:TOPIC] | "
        "pose[:TOPIC] | tum:FILE | none (not set: tf for a bag, the folder's groundtruth.txt "
        "for a TUM folder)",
        metavar="SPEC",
    ),
    Option(
        "--sensor-topic",
        "player.source.sensor_topic",
        "sensor topic, if the bag has several",
        metavar="TOPIC",
    ),
    Option(
        "--level",
        "player.source.level",
        "auto: level a fixed frame that is not level, and "
        "find its floor, from the depth data; none: take it as it is, floor at z = 0",
        choices=("auto", "none"),
    ),
    Option(
        "--floor-z",
        "player.source.floor_z",
        "the floor's height in the fixed frame (m)",
        finite,
        metavar="Z",
    ),
    Option(
        "--intrinsics",
        "player.source.intrinsics",
        "a TUM folder's camera, pixels",
        intrinsics,
        metavar="FX,FY,CX,CY",
    ),
    Option(
        "--depth-scale",
        "player.source.depth_scale",
        "a TUM folder's depth units per metre "
        "(1000 for millimetres; default: millimetres if its depth.txt or its depths say so, "
        "else TUM's 5000)",
        positive,
        metavar="N",
    ),
)

ROS2_TOPICS = (
    Option(
        "--namespace",
        "ros2.namespace",
        "the bridge's --namespace: topic /T is the key NAMESPACE/T (empty: none)",
        metavar="NS",
    ),
    Option(
        "--sensor",
        "ros2.sensor",
        "the sensor topic and its type: sensor_msgs/msg/Image "
        "(16UC1, 32FC1), sensor_msgs/msg/PointCloud2 or sensor_msgs/msg/LaserScan (not set: "
        "the one such topic the bridge or rmw_zenoh announces)",
        metavar="TOPIC:TYPE",
    ),
    Option(
        "--rmw-zenoh",
        "ros2.rmw_zenoh",
        "read a robot speaking rmw_zenoh in this ROS domain "
        "(keys DOMAIN/TOPIC/TYPE/HASH), not zenoh-bridge-ros2dds's keys",
        domain_id,
        metavar="DOMAIN",
    ),
    Option(
        "--discover-wait",
        "ros2.discover_wait",
        "seconds to wait for the sensor topic to be announced (without --sensor)",
        positive,
        metavar="S",
    ),
    Option(
        "--camera-info",
        "ros2.camera_info",
        "a depth image's CameraInfo topic (not set: camera_info beside the image)",
        metavar="TOPIC",
    ),
    Option(
        "--tf-wait",
        "ros2.tf_wait",
        "seconds a sensor message waits for its tf, then is dropped and counted",
        positive,
        metavar="S",
    ),
)

ROS2 = (
    *ROS2_TOPICS,
    Option(
        "--pose-source",
        "ros2.pose_source",
        "tf | tf:PARENT>CHILD | odom[:TOPIC] | pose[:TOPIC] | none",
        metavar="SPEC",
    ),
    Option(
        "--whole-clouds",
        "ros2.whole_clouds",
        "send whole clouds, not only the rows the detector asks for",
        const=True,
    ),
)

PLAYER = (
    Option(
        "--wait-timeout",
        "player.wait_timeout",
        "wait for router and services (s)",
        positive,
        metavar="S",
    ),
    Option(
        "--whole-clouds",
        "player.whole_clouds",
        "send whole clouds, not only the rows the detector asks for (e.g. to record them)",
        const=True,
    ),
    Option("--start", "player.start", "begin S seconds into the bag", non_negative, metavar="S"),
    Option("--duration", "player.duration", "play S seconds of the bag", positive, metavar="S"),
    Option("--loop", "player.loop", "start over at the end, until stopped", const=True),
    Option(
        "--topics",
        "player.source.topics",
        "read only these topics (sensor, tf, poses)",
        _names,
        metavar="T1,T2",
    ),
    Option(
        "--paused", "player.paused", "start paused (resume or step: keys or control)", const=True
    ),
    Option(
        "--wait-for",
        "player.wait_for",
        "services to wait for before playing, comma-separated "
        "(not set: detector,mapper with --fast, else none); waiting for the mapper also waits "
        "for it to finish",
        _names,
        metavar="SERVICES",
    ),
)

BAND = (
    Option(
        "--band",
        "detector.rows.band",
        "height band, m above the floor (not set: what the "
        "sensor sees above furniture, at most 1.3-2.1)",
        band,
        metavar="LOW,HIGH",
    ),
)

DETECTOR = (
    Option("--rows", "detector.rows.mode", "row choice", choices=("band", "row")),
    Option(
        "--row-fraction",
        "detector.rows.row_fraction",
        "row from the top, for --rows row",
        float,
        metavar="F",
    ),
    Option(
        "--noise-k",
        "detector.ransac.noise_k",
        "depth noise: sigma = k * range^2",
        float,
        metavar="K",
    ),
    Option("--seed", "detector.seed", "RANSAC seed", int),
)

SLAM = (
    Option(
        "--slam",
        "mapper.slam.enabled",
        "take the poses as odometry and correct them with the "
        "walls; the corrected pose goes out on {prefix}/pose/corrected, map -> odom on "
        "{prefix}/pose/correction",
        const=True,
    ),
)

POSES = (
    Option(
        "--trust-poses",
        "mapper.judge.enabled",
        "take every pose as it comes: do not judge it against the walls (nor estimate its latency)",
        const=False,
    ),
    Option(
        "--pose-latency",
        "mapper.judge.latency",
        "the pose source's latency: its pose of an "
        "instant is stamped this much later (not set: estimated from the walls)",
        finite,
        metavar="SECONDS",
    ),
)

STATE = (
    Option("--state", "mapper.state", "keep the map in FILE across restarts", Path, metavar="FILE"),
)

MAPPER = (
    Option(
        "--pose-key",
        "mapper.pose_key",
        "where poses come from (not set: PREFIX/pose)",
        metavar="KEYEXPR",
    ),
    Option(
        "--pose-format",
        "mapper.pose_format",
        "wallmap or ros2:TYPE for CDR from a ROS 2 system: " + ", ".join(POSE_FORMATS[1:]),
        choices=POSE_FORMATS,
        metavar="FORMAT",
    ),
    Option(
        "--pose-frames",
        "mapper.pose_frames",
        "the pose wanted from ros2:tf2_msgs/msg/TFMessage",
        metavar="PARENT>CHILD",
    ),
    Option("--pose-wait", "mapper.pose_wait", "max wait for a pose (s)", positive, metavar="S"),
    Option(
        "--ros2-out",
        "mapper.ros2_out",
        "publish the map as ROS 2 messages on {prefix}/markers "
        "(MarkerArray) and {prefix}/trajectory (Path), CDR, for RViz through "
        "zenoh-bridge-ros2dds",
        negatable=True,
    ),
    Option(
        "--gap-wait",
        "mapper.gap_wait",
        "how long a frame waits for the earlier ones of its "
        "run to come back from history before they are given up as lost",
        positive,
        metavar="SECONDS",
    ),
)

ODOMETRY = (
    Option(
        "--initial-pose",
        "odometry.initial_pose",
        "where the first scan was taken, in the map frame",
        planar_pose,
        metavar="X,Y,YAW",
    ),
    Option(
        "--no-walls",
        "odometry.use_walls",
        "do not refine poses against the mapped walls",
        const=False,
    ),
)

UP = (
    Option("--exit-when-done", "up.exit_when_done", "stop everything after the bag", const=True),
    Option("--json-out", "up.json_out", "write the final map as JSON", Path, metavar="FILE"),
    Option("--picture", "up.picture", "draw the final map (.png or .svg)", picture, metavar="FILE"),
    Option("--min-obs", "up.min_obs", "walls printed: seen N times", int, metavar="N"),
    Option("--truth", "up.truth", "score the map against a scene's truth", Path, metavar="FILE"),
    Option(
        "--odometry",
        "up.odometry",
        "estimate the poses from the scans (wallmap odometry), for bags without poses",
        const=True,
    ),
    Option(
        "--ros2",
        "up.ros2",
        "map a live ROS 2 robot (wallmap ros2: --sensor, --namespace...) "
        "instead of a BAG, until Ctrl-C",
        const=True,
    ),
)

VIEW = (
    Option("--port", "view.port", "HTTP port", port),
    Option("--host", "view.host", "address to serve on (127.0.0.1: this machine only)"),
)


def add_command(
    sub: Any,
    name: str,
    help: str,
    func: Callable[..., int],
    *groups: Iterable[Option],
    configured: bool = True,
) -> argparse.ArgumentParser:
    """A subcommand that reads the configuration: ``--config``, ``--set`` and its ``groups``.

    ``func(args, config)`` runs it with the effective configuration (``wallmap.config``).
    ``configured=False``: a command no configuration tunes (``scene``) takes neither flag, so
    none is accepted and ignored; it is given the defaults.
    """
    parser = sub.add_parser(name, help=help)
    options = [option for group in groups for option in group]
    parser.set_defaults(func=func, options=options, command_parser=parser, config=None, sets=[])
    if configured:
        settings = parser.add_argument_group("configuration")
        settings.add_argument(
            "--config",
            type=Path,
            metavar="FILE",
            help="TOML configuration (wallmap config prints one)",
        )
        settings.add_argument(
            "--set",
            action="append",
            dest="sets",
            default=[],
            metavar="SECTION.KEY=VALUE",
            help="set one configuration key (repeatable), e.g. --set detector.seed=3",
        )
    add_options(parser, options)
    return parser
