"""Inspect a recording for ``wallmap doctor``: gather its facts, then conclude.

The doctor reads a bag once, through the player's own reader (``BagFile``, ``read_contents``),
and makes the player's choices with the player's own functions (``choices``: the sensor topic,
each candidate pose source, the mounts, the levelled fixed frame), so the doctor and the player
cannot disagree. The facts are gathered by topic (``doctor_file``, ``doctor_sensor``,
``doctor_tf``, ``doctor_poses``, ``doctor_times``) and the verdict drawn from them alone
(``doctor_verdict``); this module only reads the recording and hands each part what it needs.
"""

from pathlib import Path

import numpy as np

from wallmap.config import Config
from wallmap.doctor_facts import (
    FileFacts,
    LatencyFacts,
    PoseFacts,
    Report,
    SensorFacts,
    TopicFacts,
)
from wallmap.doctor_file import file_facts
from wallmap.doctor_poses import judge_poses, pose_facts
from wallmap.doctor_sensor import add_frames, sensor_facts
from wallmap.doctor_tf import tf_facts
from wallmap.doctor_times import clock_facts
from wallmap.doctor_verdict import bag_verdict, refusal, tum_verdict
from wallmap.offline import judged_source
from wallmap.services.player.bag_contents import BagContents, Stamps, read_contents, read_stamps
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.choices import SensorChoice, SensorRefusal, choose_sensor
from wallmap.services.player.errors import PlayerError
from wallmap.services.player.placement import LevelMode
from wallmap.services.player.sources import SourceSettings
from wallmap.services.player.tum_folder import OPTICAL_FRAME, SENSOR_TYPE, TumFolder


def inspect_bag(
    path: Path,
    sensor_topic: str | None = None,
    pose_source: str | None = None,
    *,
    level: LevelMode = "auto",
    floor_z: float | None = None,
) -> Report:
    """Inspect a bag as the player would open it, and say what it would use.

    Args:
        path: ROS 1 .bag file, ROS 2 bag folder, or ROS 2 .mcap file.
        sensor_topic: The ``--sensor-topic`` the player would be given, if any.
        pose_source: The ``--pose-source`` it would be given, if any: the verdict is for it.
        level: The ``--level`` it would be given: each pose source's placement is made so.
        floor_z: The ``--floor-z`` it would be given, if any.

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
            report = Report(path=str(path), file=file, chunks=bag.chunk_compression)
            return _inspect(report, bag, sensor_topic, pose_source, (level, floor_z))
    except PlayerError as err:  # the player's reason: a file it cannot read, a damaged chunk
        return _refuse(Report(path=str(path), file=file), str(err))


def _refuse(report: Report, reason: str) -> Report:
    """The report of a recording the player cannot read at all: its file facts and why."""
    report.readable = False
    report.verdict = refusal(reason)
    return report


def _inspect(
    report: Report,
    bag: BagFile,
    requested: str | None,
    asked: str | None,
    placing: tuple[LevelMode, float | None],
) -> Report:
    """Read the bag's contents once, make the player's choices and report them.

    ``placing``: the ``--level`` and ``--floor-z`` the player would be given.

    Raises:
        PlayerError: A damaged chunk or sensor frame, where the player would stop too.
    """
    contents = read_contents(bag)
    sensor = choose_sensor(contents, requested)
    facts, player_warnings = sensor_facts(bag, contents, sensor, requested)
    stamps = None
    if isinstance(sensor, SensorChoice):
        stamps = read_stamps(bag, bag.topics[sensor.topic])
    report.readable = True
    _fill(report, contents, facts, stamps)
    if isinstance(sensor, SensorChoice):
        judge_poses(report.poses, bag, contents, sensor, *placing)
    several = isinstance(sensor, SensorRefusal) and bool(sensor.candidates)
    report.verdict, chosen = bag_verdict(report, requested, several=several, asked=asked)
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
        add_frames(sensor, contents, stamps)
    report.tf = tf_facts(contents, sensor.frame_ids, t0)
    report.poses = pose_facts(contents, sensor.frame_ids, sensor_stamps, t0)
    streams = {sensor.topic: stamps} if sensor.topic is not None and stamps is not None else {}
    streams.update(contents.pose_stamps)  # the sensor first, then the pose topics
    bag_start = report.start or 0.0
    report.clock = [clock_facts(topic, s, t0, bag_start) for topic, s in streams.items()]


def inspect_tum(path: Path, source: SourceSettings) -> Report:
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
    _fill_tum(report, folder, given=source.pose_source is not None)
    level = folder.placement.level
    report.verdict = tum_verdict(report, source.intrinsics, folder.depth_scale, level)
    return report


def _fill_tum(report: Report, folder: TumFolder, *, given: bool) -> None:
    """A TUM folder's facts: its depth images as the sensor, its trajectory as the pose source.

    ``given``: the pose source was asked for (``--pose-source``), not the folder's default, so
    the command the verdict recommends must say it too.
    """
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
    pose = PoseFacts(spec, default=not given, available=folder.pose_spec.kind == "tum", player="ok")
    if pose.available:
        posed = sum(folder.pose_at(float(s)) is not None for s in stamps)
        pose.frames_with_pose, pose.placement = posed, folder.placement.describe() or None
    report.poses, report.placement = [pose], pose.placement


def inspect_latency(path: Path, config: Config, frames: int) -> LatencyFacts:
    """The latency the mapper would estimate, from the first ``frames`` run as it runs them."""
    try:
        found = judged_source(path, config, frames)
    except PlayerError as err:
        return LatencyFacts(None, None, 0, f"not estimated: {err}")
    if found is None:
        return LatencyFacts(None, None, 0, "not estimated: the poses are taken as they come")
    if found["latency_fixed"]:
        note = f"{found['latency_s']:+.3f} s, as given (--pose-latency)"
        return LatencyFacts(None, None, 0, note)
    judged = found["frames_judged"] + found["frames_unjudged"]
    if not found["settled"]:
        note = (
            f"not estimated: the first {judged} frames do not say it (the sensor hardly "
            "turns, sees few walls, or its turns fit several latencies); the mapper estimates "
            "it as it goes"
        )
        return LatencyFacts(None, None, judged, note)
    note = f"estimated from how the first {judged} frames' walls turn against the poses"
    return LatencyFacts(found["latency_s"], found["latency_sd_s"], judged, note)
