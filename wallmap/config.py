"""wallmap's one configuration: a section per service, from a TOML file, ``--set`` and flags.

    [zenoh]      where the router is and the key prefix          ZenohSettings
    [history]    how much of the live streams is kept            HistorySettings
    [player]     how a recording is played, and read             PlayerSettings, SourceSettings
    [detector]   the height band, the line search                DetectorConfig
    [mapper]     association, merging, serving; --slam; state    MapperSettings
    [odometry]   the scan matcher                                OdometryConfig
    [up]         what ``wallmap up`` writes                      UpSettings
    [view]       where ``wallmap view`` serves its page          ViewSettings

Every value has its default, its type and its meaning in those dataclasses, next to the code
that uses it; ``wallmap config`` prints them all as TOML. Precedence, lowest first: the
defaults, ``--config FILE``, the environment (``WALLMAP_CONNECT``, ``WALLMAP_PREFIX``), ``--set
SECTION.KEY=VALUE``, the command's own flags. The result is one frozen ``Config`` handed to the
command, each service getting its section; runs write it beside their outputs (the mapper's
state file, ``wallmap up --json-out``), so a map says how it was made and a file printed by
``wallmap config`` gives the same run again.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from wallmap.arg_types import picture_problem
from wallmap.common import config_file
from wallmap.common.config_file import Tree, require
from wallmap.common.link_settings import HistorySettings, ZenohSettings
from wallmap.services.detector.detector import DetectorConfig
from wallmap.services.mapper.settings import MapperSettings
from wallmap.services.odometry.tracker import OdometryConfig
from wallmap.services.player.settings import PlayerSettings
from wallmap.services.ros2_source.settings import Ros2Settings

HEADER = """\
# wallmap configuration: `wallmap COMMAND --config FILE` reads it; `--set SECTION.KEY=VALUE` and
# the commands' flags override it. Keys left out keep their defaults. Angles are in radians,
# lengths in metres, times in seconds.
"""


@dataclass(frozen=True)
class UpSettings:
    """What ``wallmap up`` runs besides the three services, and what it writes.

    Attributes:
        odometry: Estimate the poses from the scans (``wallmap odometry``), for bags without.
        exit_when_done: Stop everything once the recording has played and the map is written.
        min_obs: The printed map holds the walls seen this many times.
        json_out: Write the final map, with this configuration, as JSON to this file.
        picture: Draw the final map to this file (.png or .svg).
        truth: Score the map against a generated scene's ground truth (``wallmap scene``).
        ros2: Map a live ROS 2 robot (``wallmap ros2``, the ``[ros2]`` section) instead of a
            recording, until stopped.
    """

    odometry: bool = False
    exit_when_done: bool = False
    min_obs: int = 3
    json_out: Path | None = None
    picture: Path | None = None
    truth: Path | None = None
    ros2: bool = False

    def __post_init__(self) -> None:
        require(self.min_obs >= 1, "min_obs", ">= 1", self.min_obs)
        if self.picture is not None:
            ok = picture_problem(Path(self.picture)) is None
            require(ok, "picture", ".png or .svg", str(self.picture))


@dataclass(frozen=True)
class ViewSettings:
    """Where ``wallmap view`` serves the live map.

    Attributes:
        host: Address to serve on (127.0.0.1: this machine only).
        port: HTTP port (0: any free one); beside Foxglove's 8765, so both can run at once.
    """

    host: str = "127.0.0.1"
    port: int = 8766


@dataclass(frozen=True)
class Config:
    """Everything that tunes wallmap, a section per service.

    Attributes:
        zenoh: Where the router is, the key prefix, a Zenoh json5 file.
        history: The window of the live streams kept for services that restart.
        player: How recordings are played and read.
        detector: How walls are found in each frame.
        mapper: How walls are mapped, served and kept.
        odometry: How poses are estimated from scans (``wallmap odometry``).
        up: What ``wallmap up`` runs and writes.
        view: Where ``wallmap view`` serves its page.
        ros2: What ``wallmap ros2`` reads of a live ROS 2 robot.
    """

    zenoh: ZenohSettings = field(default_factory=ZenohSettings)
    history: HistorySettings = field(default_factory=HistorySettings)
    player: PlayerSettings = field(default_factory=PlayerSettings)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    mapper: MapperSettings = field(default_factory=MapperSettings)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    up: UpSettings = field(default_factory=UpSettings)
    view: ViewSettings = field(default_factory=ViewSettings)
    ros2: Ros2Settings = field(default_factory=Ros2Settings)


def with_odometry_poses(config: Config) -> Config:
    """With ``up.odometry`` the poses are the scan matcher's: latency 0, not estimated.

    The scan matcher makes each pose at its frame's own stamp, so its latency is 0 by
    construction (unless the user gives one).
    """
    judge = config.mapper.judge
    if not config.up.odometry or judge.latency is not None:
        return config
    mapper = replace(config.mapper, judge=replace(judge, latency=0.0))
    return replace(config, mapper=mapper)


def environment(env: Mapping[str, str]) -> Tree:
    """What ``WALLMAP_CONNECT`` (comma-separated) and ``WALLMAP_PREFIX`` set."""
    tree: Tree = {}
    connect = [e.strip() for e in env.get("WALLMAP_CONNECT", "").split(",") if e.strip()]
    if connect:
        tree["connect"] = connect
    if env.get("WALLMAP_PREFIX"):
        tree["prefix"] = env["WALLMAP_PREFIX"]
    return {"zenoh": tree} if tree else {}


def resolve(
    file: Path | None = None,
    sets: Iterable[str] = (),
    flags: Tree | None = None,
    env: Mapping[str, str] | None = None,
) -> Config:
    """The effective configuration; ConfigError names the key or file that is wrong."""
    tree: Tree = config_file.load(file) if file is not None else {}
    tree = config_file.merge(tree, environment(os.environ if env is None else env))
    for assignment in sets:
        tree = config_file.merge(tree, config_file.assignment(assignment))
    tree = config_file.merge(tree, flags or {})
    return config_file.from_tree(Config, tree)


def to_toml(config: Config) -> str:
    """The configuration as a commented TOML file that ``--config`` reads back to it."""
    return HEADER + "\n" + config_file.dumps(config)


def to_plain(config: Config) -> dict[str, Any]:
    """The configuration as plain values, for JSON outputs (``None`` left out, as in TOML)."""
    return config_file.to_tree(config)


def configured(*assignments: str) -> Config:
    """The defaults with ``SECTION.KEY=VALUE`` assignments laid on: for scripts and tests.

    No file and no environment: ``configured("mapper.slam.enabled=true")`` is the same
    configuration on every machine.
    """
    return resolve(sets=assignments, env={})
