"""Gather the facts ``wallmap doctor`` reports about a bag, before any service runs.

The doctor reads the bag once, through the player's own reader (``BagFile``, ``read_contents``),
and makes the player's choices with the player's own functions (``choices``: the sensor topic,
each candidate pose source, the mounts, the levelled fixed frame), so the doctor and the player
cannot disagree. Everything else (counts, the tf tree, pose coverage, clocks) is computed from
the same contents with the player's helpers where it is what the player would compute: header
stamps, tf lookups and pose tracks with the player's tolerance.
"""

import shlex
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wallmap.common.ros_poses import DEFAULT_CHILD, DEFAULT_PARENT, ODOMETRY_TYPE
from wallmap.common.tf_buffer import TfError
from wallmap.doctor_facts import (
    GAP_LIMIT,
    JUMP_LIMIT,
    LISTED,
    ChainFacts,
    ClockFacts,
    EdgeFacts,
    FileFacts,
    Gap,
    Intervals,
    PoseFacts,
    Report,
    SensorFacts,
    TopicFacts,
    Verdict,
)
from wallmap.services.player.bag_contents import (
    IMAGE,
    LASERSCAN,
    POINTCLOUD2,
    BagContents,
    Stamps,
    TfLink,
    read_contents,
    read_stamps,
)
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.bag_frames import BagFrames, read_survey_frames
from wallmap.services.player.choices import (
    SensorChoice,
    SensorRefusal,
    SurveyFrame,
    choose_placement,
    choose_sensor,
    plan_playback,
)
from wallmap.services.player.errors import PlayerError, Refusal, decided
from wallmap.services.player.pose_choice import FIXED_FRAMES, POSE_TOLERANCE, default_source
from wallmap.services.player.pose_sources import (
    BAG_DEFAULT,
    PoseSourceSpec,
    PoseTrack,
    parse_pose_source,
)
from wallmap.services.player.sources import SourceOptions
from wallmap.services.player.tum_folder import (
    OPTICAL_FRAME,
    SENSOR_TYPE,
    TUM_INTRINSICS,
    TumFolder,
)

# Clouds and images are big: their share of invalid points is measured on the first few.
INVALID_SAMPLE = 5
# At least this share of sensor frames must get a pose for a pose source to count as complete.
READY_SHARE = 0.95
MOST_SENSOR_FRAMES = 2  # sensor frames whose tf chain to base_link is reported
FORMATS = {
    b"#ROSBAG V2.0": "ros1",
    b"\x89MCAP": "ros2-mcap",
    b"SQLite format 3\x00": "ros2-sqlite3",
}
SUFFIXES = {"ros1": ".bag", "ros2-mcap": ".mcap", "ros2-sqlite3": ".db3"}


# --- the file -----------------------------------------------------------------------------------


def _ros1_header(head: bytes) -> dict[str, int] | None:
    """The header record of a ROS 1 bag 2.0 (index position, chunk and connection counts).

    It is the one part of a damaged bag that still says what the recorder meant to write.
    """
    pos = head.find(b"\n") + 1
    if pos == 0 or len(head) < pos + 4:
        return None
    length = int.from_bytes(head[pos : pos + 4], "little")
    pos += 4
    end = pos + length
    if end > len(head):
        return None
    fields: dict[str, int] = {}
    while pos + 4 <= end:
        size = int.from_bytes(head[pos : pos + 4], "little")
        name, _, value = head[pos + 4 : pos + 4 + size].partition(b"=")
        if name in {b"index_pos", b"conn_count", b"chunk_count"}:
            fields[name.decode()] = int.from_bytes(value, "little")
        pos += 4 + size
    return fields or None


def file_facts(path: Path) -> FileFacts:
    """What the bag's file (or folder) says about itself, without rosbags.

    Raises:
        PlayerError: The path does not exist (the player's own message).
        OSError: The file cannot be read.
    """
    if not path.exists():
        raise PlayerError(f"bag not found: {path}")
    data = path
    if path.is_dir():
        files = [f for f in sorted(path.iterdir()) if f.is_file()]
        size = sum(f.stat().st_size for f in files)
        data = next((f for f in files if f.suffix in {".mcap", ".db3"}), path)
        if data == path:
            return FileFacts(size, "", None, name_matches=False)
    else:
        size = path.stat().st_size
    with data.open("rb") as file:
        head = file.read(4096)
    fmt = next((name for magic, name in FORMATS.items() if head.startswith(magic)), None)
    first_line = head.split(b"\n", 1)[0][:40]
    magic = "".join(chr(b) if 32 <= b < 127 else "." for b in first_line)
    if fmt is None:
        matches = False
    elif path.is_dir():  # rosbags finds a folder's storage through its metadata.yaml
        matches = fmt != "ros1" and (path / "metadata.yaml").is_file()
    else:  # and a file's format through its name
        matches = path.suffix == SUFFIXES[fmt]
    return FileFacts(size, magic, fmt, matches, _ros1_header(head) if fmt == "ros1" else None)


# --- time spans ---------------------------------------------------------------------------------

Spans = list[tuple[float, float]]  # (start, end) in absolute seconds, sorted


def _gap_spans(stamps: np.ndarray) -> Spans:
    """Stretches longer than GAP_LIMIT between consecutive sample times."""
    stamps = np.unique(stamps)
    steps = np.diff(stamps)
    return [(float(stamps[i]), float(stamps[i + 1])) for i in np.nonzero(steps > GAP_LIMIT)[0]]


def _union(spans: Spans) -> Spans:
    """Merge overlapping spans: a tf chain has no fresh sample where any of its links has none."""
    merged: Spans = []
    for start, end in sorted(spans):
        if merged and start <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], end))
        else:
            merged.append((start, end))
    return merged


def _summary(starts: Sequence[float], lengths: Sequence[float], t0: float) -> Intervals:
    """Intervals relative to t0, rounded to the millisecond for people and scripts alike."""
    gaps = [Gap(round(s - t0, 3), round(n, 3)) for s, n in zip(starts, lengths, strict=True)]
    if not gaps:
        return Intervals()
    return Intervals(len(gaps), max(gaps, key=lambda g: abs(g.length)), gaps[:LISTED])


def _span_summary(spans: Spans, t0: float) -> Intervals:
    return _summary([s for s, _ in spans], [e - s for s, e in spans], t0)


def _inside(stamps: np.ndarray, spans: Spans) -> int:
    """How many stamps fall strictly inside one of the spans."""
    return sum(int(np.count_nonzero((stamps > s) & (stamps < e))) for s, e in spans)


# --- tf chains ----------------------------------------------------------------------------------


def _chain(contents: BagContents, source: str, target: str) -> ChainFacts:
    """The shortest chain of links between two frames, whichever way each link points."""
    neighbours: dict[str, list[tuple[str, TfLink]]] = {}
    for link in contents.tf_links.values():
        neighbours.setdefault(link.parent, []).append((link.child, link))
        neighbours.setdefault(link.child, []).append((link.parent, link))
    facts = ChainFacts(source, target, found=False)
    if not neighbours:
        facts.reason = "the bag has no tf"
        return facts
    absent = [repr(f) for f in (source, target) if f not in neighbours]
    if absent:
        facts.reason = f"{' and '.join(absent)} {'is' if len(absent) == 1 else 'are'} not in tf"
        return facts
    previous: dict[str, tuple[str, TfLink] | None] = {source: None}
    queue = deque([source])
    while queue and target not in previous:
        frame = queue.popleft()
        for neighbour, link in neighbours[frame]:
            if neighbour not in previous:
                previous[neighbour] = (frame, link)
                queue.append(neighbour)
    if target not in previous:
        facts.reason = f"{source!r} and {target!r} are in separate tf trees"
        return facts
    path, kinds, frame = [target], [], target
    while (step := previous[frame]) is not None:
        frame, link = step
        path.append(frame)
        kinds.append("static" if link.static else "dynamic")
    facts.found, facts.path, facts.kinds = True, path[::-1], kinds[::-1]
    return facts


def _dynamic_links(contents: BagContents, chain: ChainFacts) -> list[TfLink]:
    """The dynamic links along a found chain."""
    pairs = zip(chain.path, chain.path[1:], strict=False)
    links = [contents.tf_links.get((a, b)) or contents.tf_links[(b, a)] for a, b in pairs]
    return [link for link in links if not link.static]


# --- the sensor ---------------------------------------------------------------------------------


def _geometry(msgtype: str, first: Any) -> dict[str, Any]:
    """The size and layout of a sensor message, the facts a user checks a sensor by."""
    if msgtype == POINTCLOUD2:
        return {
            "width": int(first.width),
            "height": int(first.height),
            "fields": [f.name for f in first.fields],
            "point_step": int(first.point_step),
        }
    if msgtype == IMAGE:
        return {"width": int(first.width), "height": int(first.height), "encoding": first.encoding}
    return {
        "beams": len(first.ranges),
        "angle_min": float(first.angle_min),
        "angle_max": float(first.angle_max),
        "angle_increment": float(first.angle_increment),
        "range_min": float(first.range_min),
        "range_max": float(first.range_max),
    }


def _sensor_facts(
    bag: BagFile, contents: BagContents, sensor: SensorChoice | Refusal, requested: str | None
) -> tuple[SensorFacts, list[str]]:
    """The player's sensor decision, and its warnings when it plays with ``--pose-source none``.

    With no pose source nothing about poses or tf can refuse, so what is said here is about the
    bag itself and its sensor. The share of invalid points is measured on frames as the player
    plays them: every scan, or the first few clouds or images.

    Raises:
        PlayerError: A frame cannot be read or decoded (the player's own message).
    """
    if isinstance(sensor, Refusal):
        return SensorFacts(None, None, sensor.reason), []
    decision = "chosen with --sensor-topic" if requested else "the only usable sensor topic"
    facts = SensorFacts(sensor.topic, sensor.msgtype, decision)
    plan = decided(plan_playback(contents, sensor, PoseSourceSpec("none")))
    source = BagFrames(bag, *decided(choose_placement(plan, [])))
    limit = source.frame_count if sensor.msgtype == LASERSCAN else INVALID_SAMPLE
    invalid = total = 0
    frames = source.frames()
    try:
        for count, (frame, _) in enumerate(frames, start=1):
            invalid += int(np.count_nonzero(np.isnan(frame.points[..., 0])))
            total += frame.points[..., 0].size
            if count == limit:
                break
    finally:
        frames.close()
    facts.invalid_frames = min(limit, source.frame_count)
    facts.invalid = invalid / total if total else None
    return facts, source.warnings


# --- pose sources -------------------------------------------------------------------------------


def _tf_pose(
    contents: BagContents, parent: str, stamps: np.ndarray, t0: float, child: str = DEFAULT_CHILD
) -> PoseFacts:
    """Coverage of a tf pose source, as the player's lookups with its tolerance answer it.

    The span and gaps are those of the chain's dynamic links: where any link has no sample, the
    pose is interpolated (or, at the ends, not there).
    """
    default = parent == DEFAULT_PARENT and child == DEFAULT_CHILD
    facts = PoseFacts(f"tf:{parent}>{child}", default, available=False)
    chain = _chain(contents, parent, child)
    if not chain.found:
        facts.reason = chain.reason
        return facts
    facts.available = True
    dynamic = [np.asarray(link.stamps) for link in _dynamic_links(contents, chain)]
    gaps: Spans = []
    if dynamic:
        facts.samples = min(s.size for s in dynamic)
        facts.start = round(max(float(s.min()) for s in dynamic) - t0, 3)
        facts.end = round(min(float(s.max()) for s in dynamic) - t0, 3)
        gaps = _union([g for s in dynamic for g in _gap_spans(s)])
        facts.gaps = _span_summary(gaps, t0)
    if stamps.size:
        answered = 0
        for stamp in stamps:
            try:
                contents.tf.lookup(parent, child, float(stamp), tolerance=POSE_TOLERANCE)
            except TfError:
                continue
            answered += 1
        facts.frames_with_pose, facts.frames_in_gaps = answered, _inside(stamps, gaps)
    return facts


def _topic_pose(contents: BagContents, topic: str, stamps: np.ndarray, t0: float) -> PoseFacts:
    """Coverage of an odometry or pose topic, interpolated as the player's PoseTrack does."""
    kind = "odom" if contents.topics[topic].msgtype == ODOMETRY_TYPE else "pose"
    poses = contents.poses[topic]
    facts = PoseFacts(f"{kind}:{topic}", default=False, available=bool(poses))
    if not poses:
        facts.reason = f"topic {topic} has no messages"
        return facts
    track = PoseTrack.from_poses(poses)
    facts.samples = len(track)
    facts.start = round(float(track.stamps[0]) - t0, 3)
    facts.end = round(float(track.stamps[-1]) - t0, 3)
    gaps = _gap_spans(track.stamps)
    facts.gaps = _span_summary(gaps, t0)
    if stamps.size:
        facts.frames_with_pose = sum(
            track.at(float(s), tolerance=POSE_TOLERANCE) is not None for s in stamps
        )
        facts.frames_in_gaps = _inside(stamps, gaps)
    return facts


def _judge_poses(report: Report, bag: BagFile, contents: BagContents, sensor: SensorChoice) -> None:
    """Whether the player plays with each pose source ("ok") or its refusal, and what it says.

    The player's warnings with a source and how it places the frames (the level of the fixed
    frame, its floor, the band the sensor sees) are kept. The frames the survey looks at are
    the same for every source, so they are read once.

    Raises:
        PlayerError: The surveyed frames cannot be read (a damaged chunk).
    """
    surveyed: list[SurveyFrame] | None = None
    for pose in report.poses:
        if not (pose.available or pose.default):  # the default's refusal is what `up` says
            continue
        # The default is judged as the player takes it: map -> base_link, or the chain to the
        # frame that carries the sensor when the bag has no base_link (a handheld camera).
        spec, note = parse_pose_source(BAG_DEFAULT if pose.default else pose.source), None
        if pose.default:
            spec, note = default_source(spec, bag.topics)
        plan = plan_playback(contents, sensor, spec)
        if isinstance(plan, Refusal):
            pose.player = plan.reason
            continue
        if surveyed is None and plan.surveys:
            surveyed = read_survey_frames(bag, sensor)
        placed = choose_placement(plan, surveyed or [])
        if isinstance(placed, Refusal):
            pose.player = placed.reason
            continue
        plan, placement = placed
        pose.player, pose.warnings = "ok", [*filter(None, [note]), *plan.warnings]
        pose.placement = placement.describe() or None


# --- clocks -------------------------------------------------------------------------------------


def _clock(topic: str, stream: Stamps, t0: float, bag_start: float) -> ClockFacts:
    """Steps back and jumps between consecutive messages, and header stamps vs receive times."""
    stamps, receive = np.asarray(stream.stamps), np.asarray(stream.receive)
    facts = ClockFacts(topic, int(stamps.size), zero_stamps=stream.zero)
    if stamps.size == 0:
        return facts
    steps, receive_steps = np.diff(stamps), np.diff(receive)
    back = np.nonzero(steps < 0)[0]
    jump = np.nonzero(steps > JUMP_LIMIT)[0]
    late = np.nonzero(receive_steps > JUMP_LIMIT)[0]
    facts.backward = _summary(stamps[back], steps[back], t0)
    facts.jumps = _summary(stamps[jump], steps[jump], t0)
    facts.receive_jumps = _summary(receive[late], receive_steps[late], bag_start)
    offsets = stamps - receive
    median = float(np.median(offsets))
    facts.offset = round(median, 6)
    facts.offset_spread = round(float(np.max(np.abs(offsets - median))), 6)
    return facts


# --- the whole report ---------------------------------------------------------------------------


def _up(path: str, *options: str) -> str:
    """The ``wallmap up`` command line for this bag."""
    return " ".join(["wallmap", "up", shlex.quote(path), "--fast", *options])


def _verdict(
    report: Report, requested: str | None, *, several: bool, asked: str | None = None
) -> tuple[Verdict, PoseFacts | None]:
    """Conclude: which command maps this bag (and with which pose source), or why none does.

    ``several``: the player refused to choose among several usable sensor topics.
    ``asked``: the ``--pose-source`` given, judged as the player would take it.
    """
    sensor = report.sensor
    assert sensor is not None  # set for every readable bag
    topic_option = ("--sensor-topic", shlex.quote(requested)) if requested else ()
    if sensor.topic is None:
        if several:
            command = _up(report.path, "--sensor-topic", "TOPIC")
            text = f"choose a sensor topic: `{command}` (check it first with doctor --sensor-topic)"
            return Verdict("choose-sensor", text), None
        if requested:  # the player's own reason for refusing that topic
            return Verdict("no-sensor", f"cannot be played: {sensor.decision}"), None
        poses = [p.source for p in report.poses if p.available]
        also = f"; it holds poses only ({', '.join(poses)})" if poses else ""
        return Verdict("no-sensor", f"cannot be played: no usable sensor topic{also}"), None
    if asked is not None:
        return _asked_verdict(report, asked, topic_option)
    accepted = [p for p in report.poses if p.player == "ok" and p.frames_with_pose]
    odometry = _up(report.path, *topic_option, "--odometry")
    if not accepted or not sensor.frames:
        text = f"no poses: use `--pose-source none` with `wallmap odometry` (`{odometry}`)"
        return Verdict("no-poses", text, odometry), None
    # The default (map -> base_link, localised) when it poses enough frames; else the source
    # posing most frames, the first listed on a tie.
    best = max(accepted, key=lambda p: p.frames_with_pose or 0)
    default = next((p for p in accepted if p.default), None)
    if default is not None and (default.frames_with_pose or 0) >= READY_SHARE * sensor.frames:
        best = default
    pose_option = () if best.default else ("--pose-source", shlex.quote(best.source))
    command = _up(report.path, *topic_option, *pose_option)
    share = (best.frames_with_pose or 0) / sensor.frames
    if share >= READY_SHARE:
        return Verdict("ready", f"ready: `{command}`", command), best
    text = (
        f"partly posed: {share:.0%} of frames get a pose from {best.source} (`{command}`); "
        f"or estimate them all from the scans (`{odometry}`)"
    )
    return Verdict("partial-poses", text, command), best


def _asked_verdict(
    report: Report, asked: str, topic_option: tuple[str, ...]
) -> tuple[Verdict, PoseFacts | None]:
    """The verdict with the ``--pose-source`` given: the player's answer for it, no other."""
    try:
        spec = parse_pose_source(asked)
    except PlayerError as err:
        return Verdict("refused", f"cannot be played: {err}"), None
    command = _up(report.path, *topic_option, "--pose-source", shlex.quote(asked))
    if spec.kind == "none":
        text = f"ready, the poses sent by another program (the mapper waits for them): `{command}`"
        return Verdict("ready", text, command), None
    named = [p for p in report.poses if p.source == str(spec)]
    if spec.kind in ("odom", "pose") and spec.topic is None:  # the one topic of that kind
        named = [p for p in report.poses if p.source.startswith(f"{spec.kind}:") and p.available]
        named = named if len(named) == 1 else []
    pose = named[0] if named else None
    with_it = f"cannot be played with --pose-source {asked}"
    if pose is None or not pose.available:
        held = ", ".join(p.source for p in report.poses if p.available) or "none"
        return Verdict("refused", f"{with_it}: the bag has no such poses (it has: {held})"), None
    if pose.player != "ok" or not pose.frames_with_pose or report.sensor is None:
        return Verdict("refused", f"{with_it}: {pose.player or 'no frame gets a pose'}"), None
    share = pose.frames_with_pose / max(report.sensor.frames, 1)
    if share >= READY_SHARE:
        return Verdict("ready", f"ready: `{command}`", command), pose
    text = f"partly posed: {share:.0%} of frames get a pose from {pose.source} (`{command}`)"
    return Verdict("partial-poses", text, command), pose


def _refuse(report: Report, reason: str) -> Report:
    report.readable = False
    report.verdict = Verdict("refused", f"cannot be played: {reason}")
    return report


def inspect_bag(
    path: Path, sensor_topic: str | None = None, pose_source: str | None = None
) -> Report:
    """Inspect a bag as the player would open it, and say what it would use.

    Args:
        path: ROS 1 .bag file, ROS 2 bag folder, or ROS 2 .mcap file.
        sensor_topic: The ``--sensor-topic`` the player would be given, if any.
        pose_source: The ``--pose-source`` it would be given, if any: the verdict is for it.

    Returns:
        The report; ``readable`` is False (and the verdict gives the player's reason) when the
        player cannot read the bag at all.

    Raises:
        PlayerError: The path does not exist.
        OSError: The file cannot be read.
    """
    file = file_facts(path)
    try:
        with BagFile(path) as bag:
            return _inspect(Report(path=str(path), file=file), bag, sensor_topic, pose_source)
    except PlayerError as err:  # the player's reason: a file it cannot read, a damaged chunk
        return _refuse(Report(path=str(path), file=file), str(err))


def _inspect(
    report: Report, bag: BagFile, requested: str | None, asked: str | None = None
) -> Report:
    """Read the bag's contents once, make the player's choices and report them.

    Raises:
        PlayerError: A damaged chunk or sensor frame, where the player would stop too.
    """
    contents = read_contents(bag)
    sensor = choose_sensor(contents, requested)
    facts, player_warnings = _sensor_facts(bag, contents, sensor, requested)
    stamps = None
    if isinstance(sensor, SensorChoice):
        stamps = read_stamps(bag, bag.topics[sensor.topic])
    report.readable = True
    _fill(report, contents, facts, stamps)
    if isinstance(sensor, SensorChoice):
        _judge_poses(report, bag, contents, sensor)
    several = isinstance(sensor, SensorRefusal) and bool(sensor.candidates)
    report.verdict, chosen = _verdict(report, requested, several=several, asked=asked)
    # What the player would warn about when run as recommended (with no poses: as `none`).
    report.warnings = chosen.warnings if chosen is not None else player_warnings
    report.placement = chosen.placement if chosen is not None else None
    return report


def _fill(
    report: Report, contents: BagContents, sensor: SensorFacts, stamps: Stamps | None
) -> None:
    """Turn what was read into the report's facts."""
    report.start = contents.start_ns * 1e-9 if contents.message_count else None
    report.duration = contents.duration_ns * 1e-9 if contents.message_count else 0.0
    report.topics = [
        TopicFacts(name, topic.msgtype, topic.count)
        for name, topic in sorted(contents.topics.items())
    ]
    report.sensor = sensor
    sensor_stamps = np.asarray(stamps.stamps if stamps is not None else [])
    # Times are told from the first sensor stamp, or from the first pose without a sensor.
    firsts = [min(s.stamps) for s in contents.pose_stamps.values() if s.stamps]
    firsts += [min(link.stamps) for link in contents.tf_links.values() if not link.static]
    if sensor_stamps.size:
        firsts = [float(sensor_stamps.min())]
    t0 = report.t0 = min(firsts) if firsts else report.start or 0.0
    if stamps is not None:
        _fill_sensor(sensor, contents, stamps)
    _fill_tf(report, contents, t0)
    _fill_poses(report, contents, sensor_stamps, t0)
    streams = {sensor.topic: stamps} if sensor.topic is not None and stamps is not None else {}
    streams.update(contents.pose_stamps)  # the sensor first, then the pose topics
    bag_start = report.start or 0.0
    report.clock = [_clock(topic, s, t0, bag_start) for topic, s in streams.items()]


def _fill_sensor(sensor: SensorFacts, contents: BagContents, stamps: Stamps) -> None:
    """The sensor's frames: how many, their rate and frame names, and their size."""
    sensor.frames = len(stamps.stamps)
    steps = np.diff(np.sort(np.asarray(stamps.stamps)))
    steps = steps[steps > 0]
    sensor.rate_hz = round(1.0 / float(np.median(steps)), 3) if steps.size else None
    sensor.frame_ids = dict(stamps.frame_ids.most_common())
    first = contents.firsts.get(sensor.topic or "")
    if first is not None:
        sensor.geometry = _geometry(sensor.type or "", first)


def _fill_tf(report: Report, contents: BagContents, t0: float) -> None:
    """The tf tree: frames, links, and the chains the player needs."""
    tf = report.tf
    tf.frames = contents.tf.frames
    tf.refused = len(contents.tf_refused)
    tf.refused_example = next(iter(contents.tf_refused), None)
    links = sorted(contents.tf_links.values(), key=lambda e: (e.static, e.parent, e.child))
    for link in links:
        facts = EdgeFacts(link.parent, link.child, link.static, len(link.stamps))
        if not link.static:
            facts.start = round(min(link.stamps) - t0, 3)
            facts.end = round(max(link.stamps) - t0, 3)
            facts.gaps = _span_summary(_gap_spans(np.asarray(link.stamps)), t0)
        tf.edges.append(facts)
    # The sensor's mounting (its most used frames; a frame already base_link needs none).
    sensor_frames = report.sensor.frame_ids if report.sensor is not None else {}
    mounts = [f for f in sensor_frames if f and f != DEFAULT_CHILD][:MOST_SENSOR_FRAMES]
    pairs = [(frame, DEFAULT_CHILD) for frame in mounts]
    pairs += [(DEFAULT_PARENT, DEFAULT_CHILD), ("odom", DEFAULT_CHILD)]
    tf.chains = [_chain(contents, source, target) for source, target in pairs]


def _fill_poses(report: Report, contents: BagContents, stamps: np.ndarray, t0: float) -> None:
    """Every candidate pose source and what it covers, the default first."""
    report.poses = [_tf_pose(contents, DEFAULT_PARENT, stamps, t0)]
    if "odom" in contents.tf.frames:
        report.poses.append(_tf_pose(contents, "odom", stamps, t0))
    # A handheld camera or a SLAM: the fixed frame straight to the frame carrying the sensor.
    sensor_frames = report.sensor.frame_ids if report.sensor is not None else {}
    sensor_frame = next(iter(sensor_frames), None)
    tf = contents.tf
    for fixed in FIXED_FRAMES:
        moving = tf.moving_frame(fixed, sensor_frame) if sensor_frame else None
        if moving is not None and moving != DEFAULT_CHILD and not tf.has_path(fixed, DEFAULT_CHILD):
            report.poses.append(_tf_pose(contents, fixed, stamps, t0, moving))
    topics = sorted(contents.poses, key=lambda t: contents.topics[t].msgtype != ODOMETRY_TYPE)
    report.poses += [_topic_pose(contents, topic, stamps, t0) for topic in topics]


def inspect_tum(path: Path, source: SourceOptions) -> Report:
    """Inspect a TUM RGB-D folder as the player would open it (``source``: its camera, poses)."""
    files = [f for f in path.rglob("*") if f.is_file()]
    report = Report(
        path=str(path),
        file=FileFacts(sum(f.stat().st_size for f in files), "", "tum", name_matches=True),
    )
    try:
        folder = TumFolder(
            path,
            pose_source=source.pose_source,
            intrinsics=source.intrinsics,
            depth_scale=source.depth_scale,
            level=source.level,
            floor_z=source.floor_z,
        )
    except PlayerError as err:
        return _refuse(report, str(err))
    report.readable = True
    stamps = np.array([stamp for stamp, _ in folder.entries])
    report.start, report.duration = float(stamps[0]), folder.duration
    report.t0 = float(stamps[0])
    steps = np.diff(stamps)
    height, width = folder.size
    report.sensor = SensorFacts(
        "depth.txt",
        SENSOR_TYPE,
        "the folder's depth images",
        frames=len(stamps),
        rate_hz=round(1.0 / float(np.median(steps)), 3) if steps.size else None,
        frame_ids={OPTICAL_FRAME: len(stamps)},
        geometry={"width": width, "height": height, "encoding": f"PNG / {folder.depth_scale:g}"},
    )
    spec = str(folder.pose_spec)
    pose = PoseFacts(spec, default=True, available=folder.pose_spec.kind == "tum", player="ok")
    if pose.available:
        posed = sum(folder.pose_at(float(s)) is not None for s in stamps)
        pose.frames_with_pose, pose.placement = posed, folder.placement.describe() or None
    report.poses, report.placement = [pose], pose.placement
    camera = ["--intrinsics", ",".join(f"{v:g}" for v in source.intrinsics)]
    camera += ["--depth-scale", f"{folder.depth_scale:g}"]
    command = _up(str(path), *camera, *(() if pose.default else ("--pose-source", spec)))
    level = folder.placement.level
    if not pose.available or not pose.frames_with_pose:
        report.verdict = Verdict("no-poses", f"no poses: give --pose-source tum:FILE (`{command}`)")
    elif source.intrinsics == TUM_INTRINSICS and level and level.frames and level.floor is None:
        # A carried camera sees the floor: with none in any frame, the guessed camera is wrong.
        text = (
            f"check the camera: no floor seen in {level.frames} frames with TUM's intrinsics; "
            f"give the recording's own (`{_up(str(path), '--intrinsics', 'FX,FY,CX,CY')}`)"
        )
        report.verdict = Verdict("check-camera", text)
    elif pose.frames_with_pose >= READY_SHARE * len(stamps):
        report.verdict = Verdict("ready", f"ready: `{command}`", command)
    else:
        share = pose.frames_with_pose / len(stamps)
        text = f"partly posed: {share:.0%} of frames get a pose from {spec} (`{command}`)"
        report.verdict = Verdict("partial-poses", text, command)
    return report
