"""``wallmap doctor BAG``: what the player will make of a bag, said before anything runs.

A bag that plays badly usually fails late and quietly: no pose for most frames, a sensor mounted
at the robot's origin, a clock that jumps. The doctor opens the bag the way the player does and
gathers the facts (``doctor_inspect``), concludes from them (``doctor_verdict``), and prints one
screen of plain text (``doctor_text``), or the same facts as JSON, ending in a verdict: the
command to run, or why there is none. This module is the command: its flags and that sequence.
"""

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from wallmap.arg_types import positive_int
from wallmap.config import Config
from wallmap.doctor_facts import Report
from wallmap.options import SOURCE
from wallmap.options import add_command as add_options_command


def report_json(report: Report) -> str:
    """The report's facts as JSON, for scripts (``exit_status`` as the command returns it)."""
    facts: dict[str, Any] = dataclasses.asdict(report)
    facts["exit_status"] = report.exit_status
    return json.dumps(facts, indent=2)


def _cmd_doctor(args: argparse.Namespace, config: Config) -> int:
    """Inspect the recording, estimate the latency only for a bag that is ready, print.

    Returns:
        The exit status: 1 when the player would refuse the run.
    """
    # Imported here, not above: every wallmap command builds this one's parser.
    from wallmap.doctor_inspect import inspect_bag, inspect_latency, inspect_tum  # noqa: PLC0415
    from wallmap.doctor_text import render_text  # noqa: PLC0415
    from wallmap.services.player.tum_folder import is_tum_folder  # noqa: PLC0415

    source = config.player.source
    if is_tum_folder(args.bag):
        report = inspect_tum(args.bag, source)
    else:
        report = inspect_bag(
            args.bag,
            source.sensor_topic,
            source.pose_source,
            level=source.level,
            floor_z=source.floor_z,
        )
    if args.latency and report.verdict.status == "ready":
        report.latency = inspect_latency(args.bag, config, args.latency_frames)
    print(report_json(report) if args.json else render_text(report))
    return report.exit_status


def add_command(sub: Any) -> None:
    """Add ``doctor`` to the ``wallmap`` subcommands (``sub`` from ``add_subparsers``).

    It takes the player's flags for reading a recording (the TUM folder's camera, levelling),
    so what it says is what the player will do with the same flags.
    """
    p = add_options_command(
        sub,
        "doctor",
        "inspect a bag: what the player will use, and what is wrong",
        _cmd_doctor,
        SOURCE,
    )
    p.add_argument(
        "bag",
        type=Path,
        metavar="BAG",
        help="ROS 1 .bag file, ROS 2 bag folder, .mcap file or TUM RGB-D folder",
    )
    p.add_argument("--json", action="store_true", help="the same facts as JSON, for scripts")
    p.add_argument(
        "--latency",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="estimate the pose source's latency as the mapper would, from the first "
        "frames (a few seconds of work)",
    )
    p.add_argument(
        "--latency-frames",
        type=positive_int,
        default=400,
        metavar="N",
        help="frames the latency is estimated from",
    )
