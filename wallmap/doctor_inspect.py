"""Gather the facts ``wallmap doctor`` reports about a bag, before any service runs.

The player's decisions (which sensor topic, whether a pose source is accepted, how the sensor is
mounted, what it warns about) come from opening ``BagSource`` exactly as ``wallmap player``
does, so the doctor and the player cannot disagree. Everything else (counts, the tf tree, pose
coverage, clocks) is read here with rosbags, computed with the player's own helpers where it is
what the player would compute: header stamps, tf lookups and pose tracks with the player's
tolerance.
"""

import shlex
from collections import Counter, deque
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection
from rosbags.typesys import Stores, get_typestore

from wallmap.common.ros_poses import (
    DEFAULT_CHILD,
    DEFAULT_PARENT,
    ODOMETRY_TYPE,
    POSE_TYPES,
    header_stamp,
    pose_from_message,
)
from wallmap.common.tf_buffer import TfBuffer, TfError, normalize_frame
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
    TF_TOPICS,
    TF_TYPES,
)
from wallmap.services.player.bag_source import BagSource
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.mapped_bag import mapped_messages
from wallmap.services.player.pose_choice import FIXED_FRAMES, POSE_TOLERANCE
from wallmap.services.player.pose_sources import PoseTrack
from wallmap.services.player.sources import SourceOptions
from wallmap.services.player.tum_folder import OPTICAL_FRAME, SENSOR_TYPE, TumFolder

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


def _one_line(err: BaseException) -> str:
    """A library error as one line (some rosbags errors have no text)."""
    return " ".join(str(err).split()) or type(err).__name__


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


# --- reading the bag ----------------------------------------------------------------------------


class _Stream:
    """Header stamps (as the player reads them) and receive times of one topic, in bag order."""

    def __init__(self) -> None:
        self.stamps: list[float] = []
        self.receive: list[float] = []
        self.zero = 0

    def add(self, header: Any, receive_ns: int) -> None:
        self.zero += header.stamp.sec == 0 and header.stamp.nanosec == 0
        self.stamps.append(header_stamp(header, receive_ns))
        self.receive.append(receive_ns * 1e-9)


class _Edge:
    """One tf link as published: static or not (its first sample decides, as in TfBuffer)."""

    def __init__(self, parent: str, child: str, *, static: bool) -> None:
        self.parent, self.child, self.static = parent, child, static
        self.stamps: list[float] = []


class _Contents:
    """What one read of the bag holds: tf, pose messages, and the sensor topic's stamps."""

    def __init__(self, reader: AnyReader) -> None:
        self.reader = reader
        self.topics = {n: i for n, i in reader.topics.items() if i.msgtype is not None}
        self.tf = TfBuffer()
        self.edges: dict[tuple[str, str], _Edge] = {}
        self.refused: list[str] = []
        self.poses: dict[str, list[Any]] = {}  # pose topic -> planar poses
        self.streams: dict[str, _Stream] = {}
        self.sensor_first: Any = None
        self.frame_ids: Counter[str] = Counter()

    def _messages(
        self, connections: list[Connection], *, mapped: bool = False
    ) -> Iterator[tuple[Connection, int, Any]]:
        """Deserialized messages of some connections in bag order.

        With ``mapped``, an uncompressed ROS 1 bag is read as the player reads it, as views over
        the mapped file, so only the headers of big clouds are paged in.
        """
        if not connections:
            return
        raws = mapped_messages(self.reader, connections) if mapped else None
        if raws is None:
            raws = self.reader.messages(connections=connections)
        for connection, receive_ns, raw in raws:
            yield connection, receive_ns, self.reader.deserialize(raw, connection.msgtype)

    def read_poses(self) -> None:
        """Read /tf, /tf_static (the topics BagSource reads) and every odometry or pose topic."""
        tf_topics = {
            name: TF_TOPICS[name.lstrip("/")]
            for name, info in self.topics.items()
            if name.lstrip("/") in TF_TOPICS and info.msgtype in TF_TYPES
        }
        pose_types = {ODOMETRY_TYPE, *POSE_TYPES}
        pose_topics = [n for n, i in sorted(self.topics.items()) if i.msgtype in pose_types]
        wanted = [*tf_topics, *pose_topics]
        connections = [c for name in wanted for c in self.topics[name].connections]
        for name in pose_topics:
            self.poses[name], self.streams[name] = [], _Stream()
        for connection, receive_ns, msg in self._messages(connections):
            topic = connection.topic
            if topic in tf_topics:
                self._add_tf(msg, static=tf_topics[topic])
            else:
                self.streams[topic].add(msg.header, receive_ns)
                self.poses[topic].append(pose_from_message(msg, receive_ns, DEFAULT_CHILD))

    def _add_tf(self, msg: Any, *, static: bool) -> None:
        for transform in msg.transforms:
            parent = normalize_frame(transform.header.frame_id)
            child = normalize_frame(transform.child_frame_id)
            stamp = transform.header.stamp.sec + transform.header.stamp.nanosec * 1e-9
            t, q = transform.transform.translation, transform.transform.rotation
            try:
                self.tf.add_transform(
                    parent, child, stamp, (t.x, t.y, t.z), (q.x, q.y, q.z, q.w), static=static
                )
            except TfError as err:
                self.refused.append(str(err))
                continue
            edge = self.edges.setdefault((parent, child), _Edge(parent, child, static=static))
            edge.stamps.append(stamp)

    def read_sensor(self, topic: str) -> None:
        """Read the sensor topic's stamps and frame names, keeping its first message."""
        stream = self.streams.setdefault(topic, _Stream())
        for _, receive_ns, msg in self._messages(self.topics[topic].connections, mapped=True):
            stream.add(msg.header, receive_ns)
            self.frame_ids[normalize_frame(msg.header.frame_id)] += 1
            if self.sensor_first is None:
                self.sensor_first = msg

    # --- tf chains ----------------------------------------------------------------------------

    def chain(self, source: str, target: str) -> ChainFacts:
        """The shortest chain of links between two frames, whichever way each link points."""
        neighbours: dict[str, list[tuple[str, _Edge]]] = {}
        for edge in self.edges.values():
            neighbours.setdefault(edge.parent, []).append((edge.child, edge))
            neighbours.setdefault(edge.child, []).append((edge.parent, edge))
        facts = ChainFacts(source, target, found=False)
        if not neighbours:
            facts.reason = "the bag has no tf"
            return facts
        absent = [repr(f) for f in (source, target) if f not in neighbours]
        if absent:
            facts.reason = f"{' and '.join(absent)} {'is' if len(absent) == 1 else 'are'} not in tf"
            return facts
        previous: dict[str, tuple[str, _Edge] | None] = {source: None}
        queue = deque([source])
        while queue and target not in previous:
            frame = queue.popleft()
            for neighbour, edge in neighbours[frame]:
                if neighbour not in previous:
                    previous[neighbour] = (frame, edge)
                    queue.append(neighbour)
        if target not in previous:
            facts.reason = f"{source!r} and {target!r} are in separate tf trees"
            return facts
        path, kinds, frame = [target], [], target
        while (link := previous[frame]) is not None:
            frame, edge = link
            path.append(frame)
            kinds.append("static" if edge.static else "dynamic")
        facts.found, facts.path, facts.kinds = True, path[::-1], kinds[::-1]
        return facts

    def chain_edges(self, chain: ChainFacts) -> list[_Edge]:
        """The dynamic links along a found chain."""
        links = zip(chain.path, chain.path[1:], strict=False)
        edges = [self.edges.get((a, b)) or self.edges[(b, a)] for a, b in links]
        return [e for e in edges if not e.static]


def _open(path: Path) -> AnyReader:
    """Open the bag the way BagSource does (ROS 2 bags without type definitions included)."""
    reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    reader.open()
    return reader


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


class _DamagedError(Exception):
    """The player opened the bag but could not decode its sensor frames: a damaged bag."""


def _player_sensor(path: Path, requested: str | None) -> tuple[SensorFacts, list[str]] | str:
    """BagSource's sensor decision and warnings with no pose source, or its error.

    With ``--pose-source none`` nothing about poses or tf can fail, so an error here is about
    the bag itself or its sensor topics. The share of invalid points is measured on frames as
    the player decodes them: every scan, or the first few clouds or images.

    Raises:
        _DamagedError: A frame cannot be decoded (the player's own message).
    """
    try:
        source = BagSource(path, sensor_topic=requested, pose_source="none")
    except PlayerError as err:
        return str(err)
    with source:
        decision = "chosen with --sensor-topic" if requested else "the only usable sensor topic"
        facts = SensorFacts(source.sensor_topic, source.sensor_type, decision)
        limit = source.frame_count if source.sensor_type == LASERSCAN else INVALID_SAMPLE
        invalid = total = 0
        frames = source.frames()
        try:
            for count, (frame, _) in enumerate(frames, start=1):
                invalid += int(np.count_nonzero(np.isnan(frame.points[..., 0])))
                total += frame.points[..., 0].size
                if count == limit:
                    break
        except PlayerError as err:
            raise _DamagedError(str(err)) from err
        finally:
            frames.close()
        facts.invalid_frames = min(limit, source.frame_count)
        facts.invalid = invalid / total if total else None
        return facts, list(source.warnings)


# --- pose sources -------------------------------------------------------------------------------


def _player_accepts(path: Path, sensor: str, spec: str) -> tuple[str, list[str], str | None]:
    """Whether BagSource opens the bag with this pose source ("ok"), and what it says.

    Returns the acceptance, the warnings, and how the player places the frames (the level of
    the fixed frame, its floor, the band the sensor sees).
    """
    try:
        with BagSource(path, sensor_topic=sensor, pose_source=spec) as source:
            return "ok", list(source.warnings), source.placement.describe() or None
    except PlayerError as err:
        return str(err), [], None


def _tf_pose(
    bag: _Contents, parent: str, stamps: np.ndarray, t0: float, child: str = DEFAULT_CHILD
) -> PoseFacts:
    """Coverage of a tf pose source, as the player's lookups with its tolerance answer it.

    The span and gaps are those of the chain's dynamic links: where any link has no sample, the
    pose is interpolated (or, at the ends, not there).
    """
    default = parent == DEFAULT_PARENT and child == DEFAULT_CHILD
    facts = PoseFacts(f"tf:{parent}>{child}", default, available=False)
    chain = bag.chain(parent, child)
    if not chain.found:
        facts.reason = chain.reason
        return facts
    facts.available = True
    dynamic = [np.asarray(e.stamps) for e in bag.chain_edges(chain)]
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
                bag.tf.lookup(parent, child, float(stamp), tolerance=POSE_TOLERANCE)
            except TfError:
                continue
            answered += 1
        facts.frames_with_pose, facts.frames_in_gaps = answered, _inside(stamps, gaps)
    return facts


def _topic_pose(bag: _Contents, topic: str, stamps: np.ndarray, t0: float) -> PoseFacts:
    """Coverage of an odometry or pose topic, interpolated as the player's PoseTrack does."""
    kind = "odom" if bag.topics[topic].msgtype == ODOMETRY_TYPE else "pose"
    facts = PoseFacts(f"{kind}:{topic}", default=False, available=bool(bag.poses[topic]))
    if not facts.available:
        facts.reason = f"topic {topic} has no messages"
        return facts
    track = PoseTrack.from_poses(bag.poses[topic])
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


# --- clocks -------------------------------------------------------------------------------------


def _clock(topic: str, stream: _Stream, t0: float, bag_start: float) -> ClockFacts:
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


def _verdict(report: Report, requested: str | None) -> tuple[Verdict, PoseFacts | None]:
    """Conclude: which command maps this bag (and with which pose source), or why none does."""
    sensor = report.sensor
    assert sensor is not None  # set for every readable bag
    topic_option = ("--sensor-topic", shlex.quote(requested)) if requested else ()
    if sensor.topic is None:
        if sensor.decision.startswith("several sensor topics"):
            command = _up(report.path, "--sensor-topic", "TOPIC")
            text = f"choose a sensor topic: `{command}` (check it first with doctor --sensor-topic)"
            return Verdict("choose-sensor", text), None
        if requested:  # the player's own reason for refusing that topic
            return Verdict("no-sensor", f"cannot be played: {sensor.decision}"), None
        poses = [p.source for p in report.poses if p.available]
        also = f"; it holds poses only ({', '.join(poses)})" if poses else ""
        return Verdict("no-sensor", f"cannot be played: no usable sensor topic{also}"), None
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


def _refuse(report: Report, reason: str) -> Report:
    report.readable = False
    report.verdict = Verdict("refused", f"cannot be played: {reason}")
    return report


def inspect_bag(path: Path, sensor_topic: str | None = None) -> Report:
    """Inspect a bag as the player would open it, and say what it would use.

    Args:
        path: ROS 1 .bag file, ROS 2 bag folder, or ROS 2 .mcap file.
        sensor_topic: The ``--sensor-topic`` the player would be given, if any.

    Returns:
        The report; ``readable`` is False (and the verdict gives the player's reason) when the
        player cannot read the bag at all.

    Raises:
        PlayerError: The path does not exist.
        OSError: The file cannot be read.
    """
    report = Report(path=str(path), file=file_facts(path))
    try:
        decided = _player_sensor(path, sensor_topic)
    except _DamagedError as err:
        return _refuse(report, str(err))
    error = decided if isinstance(decided, str) else None
    try:
        reader = _open(path)
    except Exception as err:  # rosbags fails on damaged bags in many ways
        return _refuse(report, error or f"cannot read bag {path}: {_one_line(err)}")
    try:
        if error is not None and not report.file.name_matches:
            return _refuse(report, error)  # BagSource refused the file before reading it
        sensor, player_warnings = (
            (SensorFacts(None, None, error), []) if isinstance(decided, str) else decided
        )
        bag = _Contents(reader)
        try:
            bag.read_poses()
            if sensor.topic is not None:
                bag.read_sensor(sensor.topic)
        except Exception as err:  # a damaged chunk the player would stop at as well
            return _refuse(report, error or f"cannot read bag {path}: {_one_line(err)}")
        report.readable = True
        _fill(report, bag, sensor, reader)
    finally:
        reader.close()
    if sensor.topic is not None:
        for pose in report.poses:
            if pose.available or pose.default:  # the default's refusal is what `up` would say
                pose.player, pose.warnings, pose.placement = _player_accepts(
                    path, sensor.topic, pose.source
                )
    report.verdict, chosen = _verdict(report, sensor_topic)
    # What the player would warn about when run as recommended (with no poses: as `none`).
    report.warnings = chosen.warnings if chosen is not None else player_warnings
    report.placement = chosen.placement if chosen is not None else None
    return report


def _fill(report: Report, bag: _Contents, sensor: SensorFacts, reader: AnyReader) -> None:
    """Turn what was read into the report's facts."""
    report.start = reader.start_time * 1e-9 if reader.message_count else None
    report.duration = reader.duration * 1e-9 if reader.message_count else 0.0
    report.topics = [
        TopicFacts(name, info.msgtype or "", info.msgcount)
        for name, info in sorted(bag.topics.items())
    ]
    report.sensor = sensor
    stamps = np.asarray(bag.streams[sensor.topic].stamps) if sensor.topic else np.empty(0)
    # Times are told from the first sensor stamp, or from the first pose without a sensor.
    firsts = [min(s.stamps) for s in bag.streams.values() if s.stamps]
    firsts += [min(e.stamps) for e in bag.edges.values() if not e.static]
    if stamps.size:
        firsts = [float(stamps.min())]
    t0 = report.t0 = min(firsts) if firsts else report.start or 0.0

    if sensor.topic is not None:
        sensor.frames = int(stamps.size)
        steps = np.diff(np.sort(stamps))
        steps = steps[steps > 0]
        sensor.rate_hz = round(1.0 / float(np.median(steps)), 3) if steps.size else None
        sensor.frame_ids = dict(bag.frame_ids.most_common())
        if bag.sensor_first is not None:
            sensor.geometry = _geometry(sensor.type or "", bag.sensor_first)

    tf = report.tf
    tf.frames = bag.tf.frames
    tf.refused, tf.refused_example = len(bag.refused), next(iter(bag.refused), None)
    for edge in sorted(bag.edges.values(), key=lambda e: (e.static, e.parent, e.child)):
        facts = EdgeFacts(edge.parent, edge.child, edge.static, len(edge.stamps))
        if not edge.static:
            facts.start = round(min(edge.stamps) - t0, 3)
            facts.end = round(max(edge.stamps) - t0, 3)
            facts.gaps = _span_summary(_gap_spans(np.asarray(edge.stamps)), t0)
        tf.edges.append(facts)
    # The sensor's mounting (its most used frames; a frame already base_link needs none).
    mounts = [f for f in sensor.frame_ids if f and f != DEFAULT_CHILD][:MOST_SENSOR_FRAMES]
    pairs = [(frame, DEFAULT_CHILD) for frame in mounts]
    pairs += [(DEFAULT_PARENT, DEFAULT_CHILD), ("odom", DEFAULT_CHILD)]
    tf.chains = [bag.chain(source, target) for source, target in pairs]

    report.poses = [_tf_pose(bag, DEFAULT_PARENT, stamps, t0)]
    if "odom" in bag.tf.frames:
        report.poses.append(_tf_pose(bag, "odom", stamps, t0))
    # A handheld camera or a SLAM: the fixed frame straight to the frame carrying the sensor.
    sensor_frame = next(iter(sensor.frame_ids), None)
    for fixed in FIXED_FRAMES:
        moving = bag.tf.moving_frame(fixed, sensor_frame) if sensor_frame else None
        if (
            moving is not None
            and moving != DEFAULT_CHILD
            and not bag.tf.has_path(fixed, DEFAULT_CHILD)
        ):
            report.poses.append(_tf_pose(bag, fixed, stamps, t0, moving))
    topics = sorted(bag.poses, key=lambda topic: bag.topics[topic].msgtype != ODOMETRY_TYPE)
    report.poses += [_topic_pose(bag, topic, stamps, t0) for topic in topics]

    bag_start = report.start or 0.0
    report.clock = [_clock(topic, s, t0, bag_start) for topic, s in bag.streams.items()]
    if sensor.topic is not None:  # the sensor first
        report.clock.sort(key=lambda c: c.topic != sensor.topic)


def inspect_tum(path: Path, source: SourceOptions) -> Report:
    """Inspect a TUM RGB-D folder as the player would open it (``source``: its camera, poses)."""
    files = [f for f in path.rglob("*") if f.is_file()]
    report = Report(path=str(path), file=FileFacts(sum(f.stat().st_size for f in files), "",
                                                    "tum", name_matches=True))  # fmt: skip
    try:
        folder = TumFolder(
            path, pose_source=source.pose_source, intrinsics=source.intrinsics,
            depth_scale=source.depth_scale, level=source.level, floor_z=source.floor_z,
        )  # fmt: skip
    except PlayerError as err:
        return _refuse(report, str(err))
    report.readable = True
    stamps = np.array([stamp for stamp, _ in folder.entries])
    report.start, report.duration = float(stamps[0]), folder.duration
    report.t0 = float(stamps[0])
    steps = np.diff(stamps)
    height, width = folder.size
    report.sensor = SensorFacts(
        "depth.txt", SENSOR_TYPE, "the folder's depth images", frames=len(stamps),
        rate_hz=round(1.0 / float(np.median(steps)), 3) if steps.size else None,
        frame_ids={OPTICAL_FRAME: len(stamps)},
        geometry={"width": width, "height": height, "encoding": f"PNG / {source.depth_scale:g}"},
    )  # fmt: skip
    spec = str(folder.pose_spec)
    pose = PoseFacts(spec, default=True, available=folder.pose_spec.kind == "tum", player="ok")
    if pose.available:
        posed = sum(folder.pose_at(float(s)) is not None for s in stamps)
        pose.frames_with_pose, pose.placement = posed, folder.placement.describe() or None
    report.poses, report.placement = [pose], pose.placement
    camera = ["--intrinsics", ",".join(f"{v:g}" for v in source.intrinsics)]
    camera += ["--depth-scale", f"{source.depth_scale:g}"]
    command = _up(str(path), *camera, *(() if pose.default else ("--pose-source", spec)))
    if not pose.available or not pose.frames_with_pose:
        report.verdict = Verdict("no-poses", f"no poses: give --pose-source tum:FILE (`{command}`)")
    elif pose.frames_with_pose >= READY_SHARE * len(stamps):
        report.verdict = Verdict("ready", f"ready: `{command}`", command)
    else:
        share = pose.frames_with_pose / len(stamps)
        text = f"partly posed: {share:.0%} of frames get a pose from {spec} (`{command}`)"
        report.verdict = Verdict("partial-poses", text, command)
    return report
