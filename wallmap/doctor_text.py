"""The doctor's report as one screen of plain text: each fact in words, the verdict last.

A user reads the report to decide what to run, so it fits one screen (about 40 lines of 100
columns) whatever the bag holds: long lists are cut to the ones the player uses first, and
``--json`` (``doctor.report_json``) lists everything. Only wording lives here; the facts and
the verdict come ready made (``doctor_inspect``).
"""

import math
import textwrap
from datetime import UTC, datetime

from wallmap.common.ros_poses import ODOMETRY_TYPE, POSE_TYPES
from wallmap.doctor_facts import (
    GAP_LIMIT,
    JUMP_LIMIT,
    ChainFacts,
    ClockFacts,
    Intervals,
    LatencyFacts,
    Report,
    SensorFacts,
    TopicFacts,
)
from wallmap.services.player.bag_contents import (
    CAMERA_INFO,
    IMAGE,
    LASERSCAN,
    POINTCLOUD2,
    TF_TYPES,
)

WIDTH = 100  # columns of the text report
LABEL = 9  # width of the section names on the left
# Caps that keep the report on one screen; --json lists everything.
MOST_TOPICS = 8  # topics listed one a line
MOST_LINKS = 4  # dynamic tf links
MOST_POSES = 6  # candidate pose sources
MOST_CLOCKS = 3  # clock lines
MOST_WARNINGS = 3  # the player's warnings
# Topics the player may read, listed before the others when there are too many: sensors, tf,
# then poses.
TOPIC_RANKS = [{POINTCLOUD2, IMAGE, LASERSCAN, CAMERA_INFO}, TF_TYPES, {ODOMETRY_TYPE, *POSE_TYPES}]
FORMAT_NAMES = {"ros1": "ROS 1 bag 2.0", "ros2-mcap": "ROS 2 mcap", "ros2-sqlite3": "ROS 2 sqlite3"}
CHUNK_NAMES = {"none": "uncompressed", "lz4": "LZ4 chunks", "bz2": "bz2 chunks"}


def _wrap(label: str, text: str) -> list[str]:
    """One fact, wrapped to the screen under its section label."""
    return textwrap.wrap(
        text,
        WIDTH,
        initial_indent=label.ljust(LABEL),
        subsequent_indent=" " * LABEL,
        break_on_hyphens=False,
    )


def _section(label: str, texts: list[str]) -> list[str]:
    """Several facts under one label, the label on the first line only."""
    lines: list[str] = []
    for text in texts:
        lines += _wrap("" if lines else label, text)
    return lines


def _plural(count: int, noun: str) -> str:
    """``1 frame``, ``2 frames``: counts read as words."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def _span(start: float | None, end: float | None) -> str:
    """A table cell: the covered times, or ``always`` for a static chain (no times)."""
    return f"{start:.1f}..{end:.1f} s" if start is not None and end is not None else "always"


def _gaps(gaps: Intervals) -> str:
    """A table cell: how many gaps, and the longest."""
    if gaps.largest is None:
        return "none"
    return f"{gaps.count} (max {gaps.largest.length:.1f} s at {gaps.largest.start:.1f} s)"


def _size(size: int) -> str:
    """A file size in the unit people read it in."""
    if size >= 1e6:
        return f"{size / 1e6:.1f} MB"
    return f"{size / 1e3:.1f} kB" if size >= 1e3 else _plural(size, "byte")


def _file(report: Report) -> list[str]:
    """The bag line: its path, format and size, and for a bag nothing reads what it still says."""
    file = report.file
    kind = FORMAT_NAMES.get(file.format or "", "not a bag format rosbags reads")
    if report.readable and report.chunks is not None:
        kind += ", " + CHUNK_NAMES.get(report.chunks, f"{report.chunks} chunks")
    facts = [f"{kind}, {_size(file.size)}"]
    if not report.readable and file.magic:  # what is left to say about a bag nothing reads
        facts[0] += f", magic {file.magic!r}"
    elif report.start is not None and report.duration is not None:
        began = datetime.fromtimestamp(report.start, UTC).strftime("%Y-%m-%d %H:%M")
        count = sum(t.count for t in report.topics)
        facts[0] += f", {report.duration:.1f} s from {began} UTC, {_plural(count, 'message')}"
    if report.readable and "bz2" in (report.chunks or ""):
        facts.append(
            "bz2 chunks are decompressed whole, at tens of MB a second: with ROS 1, "
            f"`rosbag decompress {report.path}` (or `rosbag compress --lz4`) plays it faster"
        )
    header = file.ros1_header
    if not report.readable and header:
        facts.append(
            f"bag header: {_plural(header.get('chunk_count', 0), 'chunk')}, "
            f"{_plural(header.get('conn_count', 0), 'connection')}, index at byte "
            f"{header.get('index_pos', 0):,} of {file.size:,}"
        )
    return [*_wrap("bag", report.path), *_section("", facts)]


def _topics(report: Report) -> list[str]:
    """The topics, those the player may read first when there are too many to list."""

    def rank(topic: TopicFacts) -> int:
        return next((i for i, types in enumerate(TOPIC_RANKS) if topic.type in types), 3)

    ranked = sorted(report.topics, key=lambda t: (rank(t), t.name))
    shown = sorted(ranked[:MOST_TOPICS], key=lambda t: t.name)
    if not shown:
        return _wrap("topics", "none")
    name_width = min(max(len(t.name) for t in shown), 36)
    type_width = max(len(t.type) for t in shown)
    texts = [f"{t.name:<{name_width}}  {t.type:<{type_width}} {t.count:>7}" for t in shown]
    if len(report.topics) > len(shown):
        texts.append(f"... and {len(report.topics) - len(shown)} more topics")
    return _section("topics", texts)


def _sensor(sensor: SensorFacts) -> list[str]:
    """The chosen sensor topic, its frames, and the size and layout a user checks it by."""
    if sensor.topic is None:  # the topics are listed just above, so not again
        return _wrap("sensor", f"none: {sensor.decision.partition('; bag topics: ')[0]}")
    texts = [f"{sensor.topic} ({sensor.type}): {sensor.decision}"]
    rate = f" at {sensor.rate_hz:.1f} Hz" if sensor.rate_hz else ""
    names = ", ".join(name or "(none)" for name in sensor.frame_ids)
    noun = "frame" if len(sensor.frame_ids) == 1 else "frames"
    texts.append(f"{sensor.frames} frames{rate}; sensor {noun} {names}")
    g = sensor.geometry
    short = (sensor.type or "").rpartition("/")[2]
    if "beams" in g:
        size = (
            f"{g['beams']}-beam {short}, {math.degrees(g['angle_min']):.1f} to "
            f"{math.degrees(g['angle_max']):.1f} deg by {math.degrees(g['angle_increment']):.2f}"
            f" deg, range {g['range_min']:.2f}-{g['range_max']:.2f} m"
        )
        what = "returns"
    elif "encoding" in g:
        size, what = f"{g['width']}x{g['height']} {g['encoding']} depth {short}", "pixels"
    else:
        fields = ", ".join(g.get("fields", []))
        size = (
            f"{g.get('width')}x{g.get('height')} organized {short} ({fields}; "
            f"{g.get('point_step')} bytes a point)"
        )
        what = "points"
    if sensor.invalid is not None:
        scope = (
            f"all {sensor.invalid_frames}"
            if sensor.invalid_frames == sensor.frames
            else f"first {sensor.invalid_frames}"
        )
        size += f"; {sensor.invalid:.1%} invalid {what} ({scope} frames)"
    texts.append(size)
    return _section("sensor", texts)


def _tf(report: Report) -> list[str]:
    """The tf tree: its frames, the dynamic links (those the player needs first), the static."""
    tf = report.tf
    if not tf.edges:
        return _wrap("tf", "none (no /tf or /tf_static)")
    texts = [
        textwrap.shorten(
            f"{_plural(len(tf.frames), 'frame')}: {', '.join(tf.frames)}",
            WIDTH - LABEL,
            placeholder=" ...",
        )
    ]
    # The links of the chains the player needs first, then the others (wheels and the like).
    needed = {(a, b) for c in tf.chains for a, b in zip(c.path, c.path[1:], strict=False)}
    dynamic = sorted(
        (e for e in tf.edges if not e.static),
        key=lambda e: not ({(e.parent, e.child), (e.child, e.parent)} & needed),
    )
    if dynamic:
        rows = [("dynamic link", "span", "samples", f"gaps > {GAP_LIMIT:g} s")]
        rows += [
            (f"{e.parent}->{e.child}", _span(e.start, e.end), str(e.samples), _gaps(e.gaps))
            for e in dynamic[:MOST_LINKS]
        ]
        texts += _table(rows)
    if len(dynamic) > MOST_LINKS:
        texts.append(f"... and {len(dynamic) - MOST_LINKS} more dynamic links")
    static = [f"{e.parent}->{e.child}" for e in tf.edges if e.static]
    if static:
        line = f"static: {_plural(len(static), 'link')} ({', '.join(static)})"
        texts.append(textwrap.shorten(line, WIDTH - LABEL, placeholder=" ...)"))
    if tf.refused:
        texts.append(
            f"{_plural(tf.refused, 'invalid transform')} ignored, e.g. {tf.refused_example}"
        )
    return _section("tf", texts)


def _table(rows: list[tuple[str, ...]]) -> list[str]:
    """Rows as aligned columns (numbers right-aligned), the first row the header."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = []
    for row in rows:
        cells = [
            cell.rjust(width) if cell[:1].isdigit() and " " not in cell else cell.ljust(width)
            for cell, width in zip(row, widths, strict=True)
        ]
        lines.append("  ".join(cells).rstrip())
    return lines


def _chain(chain: ChainFacts) -> str:
    """One chain the player needs: through which frames, or why it is missing."""
    name = f"{chain.source} -> {chain.target}"
    if not chain.found:
        return f"{name}: missing ({chain.reason})"
    return f"{name}: {' -> '.join(chain.path)} ({', '.join(chain.kinds)})"


def _poses(report: Report) -> list[str]:
    """The pose sources as a table (what each covers and poses), then the missing, then notes."""
    frames = report.sensor.frames if report.sensor else 0
    header = ("source", "span", "samples", f"gaps > {GAP_LIMIT:g} s")
    rows = [(*header, "frames posed") if frames else header]
    notes, missing, in_gaps = [], [], []
    for pose in report.poses[:MOST_POSES]:
        label = f"{pose.source}{' (default)' if pose.default else ''}"
        if not pose.available:
            played = pose.default and pose.player == "ok" and pose.warnings
            instead = f"; the player plays all the same: {pose.warnings[0]}" if played else ""
            missing.append(f"{label}: missing ({pose.reason}){instead}")
        else:
            row = (label, _span(pose.start, pose.end), str(pose.samples), _gaps(pose.gaps))
            if frames:
                posed = pose.frames_with_pose or 0
                row = (*row, f"{posed}/{frames} ({posed / frames:.0%})")
            rows.append(row)
        if pose.frames_in_gaps:
            in_gaps.append(f"{pose.frames_in_gaps} with {pose.source}")
        if pose.player not in (None, "ok"):
            notes.append(f"player: {pose.player}")
    if in_gaps:
        notes.insert(
            0, f"frames in gaps (poses interpolated over > {GAP_LIMIT:g} s): {', '.join(in_gaps)}"
        )
    texts = [*(_table(rows) if len(rows) > 1 else []), *missing]
    if len(report.poses) > MOST_POSES:
        texts.append(f"... and {len(report.poses) - MOST_POSES} more pose sources")
    if not any(p.source.startswith(("odom:", "pose:")) for p in report.poses):
        texts.append("no odometry or pose topics")
    return _section("poses", [*texts, *notes])


def _duration_words(seconds: float) -> str:
    """A long time in the unit people think of it in."""
    seconds = abs(seconds)
    if seconds >= 86400:
        return f"{seconds / 86400:.1f} days"
    if seconds >= 3600:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds:.1f} s"


def _clock(clock: ClockFacts, *, sensor: bool) -> str:
    """Steps back, jumps (for the sensor; a pose topic's gaps are under poses) and offsets."""
    problems = []
    if clock.backward.largest is not None:
        largest = clock.backward.largest
        problems.append(
            f"{_plural(clock.backward.count, 'step')} back in header stamps "
            f"(largest {largest.length:.2f} s at {largest.start:.1f} s)"
        )
    if sensor and clock.jumps.largest is not None:
        largest = clock.jumps.largest
        problems.append(
            f"{_plural(clock.jumps.count, 'jump')} > {JUMP_LIMIT:g} s in header stamps "
            f"(largest {largest.length:.1f} s at {largest.start:.1f} s)"
        )
    if sensor and clock.receive_jumps.largest is not None:
        largest = clock.receive_jumps.largest
        problems.append(
            f"{_plural(clock.receive_jumps.count, 'jump')} > {JUMP_LIMIT:g} s in receive times "
            f"(largest {largest.length:.1f} s)"
        )
    if clock.zero_stamps:
        problems.append(f"{clock.zero_stamps} zero header stamps (receive time used)")
    if not problems:
        problems.append("in order" + (f", no jump > {JUMP_LIMIT:g} s" if sensor else ""))
    if clock.offset is not None:
        if abs(clock.offset) > JUMP_LIMIT:
            side = "behind" if clock.offset < 0 else "ahead of"
            problems.append(
                f"header stamps {_duration_words(clock.offset)} {side} receive times "
                f"(another clock)"
            )
        else:
            problems.append(
                f"header - receive {clock.offset:+.3f} s (median), spread "
                f"{clock.offset_spread or 0.0:.3f} s"
            )
    return "; ".join(problems)


def _clocks(report: Report) -> list[str]:
    """The sensor's clock, then the pose topics', those that read the same told together."""
    sensor = report.sensor.topic if report.sensor else None
    texts = [f"{c.topic}: {_clock(c, sensor=True)}" for c in report.clock if c.topic == sensor]
    same: dict[str, list[str]] = {}
    for clock in report.clock:
        if clock.topic != sensor:
            same.setdefault(_clock(clock, sensor=False), []).append(clock.topic)
    texts += [f"{', '.join(topics)}: {text}" for text, topics in same.items()]
    if len(texts) > MOST_CLOCKS:
        texts[MOST_CLOCKS - 1 :] = [f"... and {len(texts) - MOST_CLOCKS + 1} more topics"]
    return _section("clock", texts)


def _warnings(warnings: list[str]) -> list[str]:
    """The player's own warnings with the recommended pose source, the first few."""
    texts = [f"warning: {w}" for w in warnings[:MOST_WARNINGS]]
    if len(warnings) > MOST_WARNINGS:
        texts.append(f"... and {len(warnings) - MOST_WARNINGS} more warnings")
    return _section("player", texts)


def _tum_text(report: Report) -> list[str]:
    """A TUM RGB-D folder: its images, its trajectory, how the player places the frames."""
    lines = _wrap("folder", report.path)
    if report.sensor is not None:
        lines += _sensor(report.sensor)
    for pose in report.poses:
        posed = pose.frames_with_pose or 0
        frames = report.sensor.frames if report.sensor else 0
        what = f"{posed}/{frames} frames posed" if pose.available else "no poses"
        lines += _wrap("poses", f"{pose.source}: {what}")
    if report.placement:
        lines += _wrap("level", report.placement)
    return lines + _latency_text(report.latency)


def render_text(report: Report) -> str:
    """The report as one screen of plain text (at most about 40 lines of 100 columns)."""
    if report.file.format == "tum":
        return "\n".join([*_tum_text(report), *_wrap("verdict", report.verdict.text)])
    lines = _file(report)
    if report.readable:
        lines += _topics(report)
        if report.sensor is not None:
            lines += _sensor(report.sensor)
        lines += _tf(report)
        lines += _section("chains", [_chain(c) for c in report.tf.chains])
        lines += _poses(report)
        lines += _clocks(report)
        if report.placement:
            lines += _wrap("level", report.placement)
        lines += _warnings(report.warnings)
    lines += _latency_text(report.latency)
    lines += _wrap("verdict", report.verdict.text)
    return "\n".join(lines)


def _latency_text(latency: LatencyFacts | None) -> list[str]:
    """The pose source's latency, and the flag that fixes it (nothing when not asked for)."""
    if latency is None:
        return []
    if latency.seconds is None:
        return _wrap("latency", latency.note)
    return _wrap(
        "latency",
        f"{latency.seconds:+.3f} s (sd {latency.sd or 0.0:.3f} s) {latency.note}; "
        f"--pose-latency S fixes it",
    )
