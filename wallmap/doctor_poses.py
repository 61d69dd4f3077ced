"""Every pose source a bag offers, what it covers, and whether the player plays with it.

A pose source is judged as the player uses it: tf through the player's lookups with its
tolerance, an odometry or pose topic interpolated as its `PoseTrack` does, and the choice of
mounting and levelling made by the player's own functions (``choices``), so the frames the
doctor counts as posed are the frames the player will pose.
"""

import numpy as np

from wallmap.common.ros_poses import DEFAULT_CHILD, DEFAULT_PARENT, ODOMETRY_TYPE
from wallmap.common.tf_buffer import TfError
from wallmap.doctor_facts import PoseFacts
from wallmap.doctor_tf import chain, dynamic_links
from wallmap.doctor_times import Spans, gap_spans, inside, span_summary, union
from wallmap.services.player.bag_contents import BagContents
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.bag_frames import read_survey_frames
from wallmap.services.player.choices import (
    SensorChoice,
    SurveyFrame,
    choose_placement,
    plan_playback,
)
from wallmap.services.player.errors import Refusal
from wallmap.services.player.placement import LevelMode
from wallmap.services.player.pose_choice import FIXED_FRAMES, POSE_TOLERANCE, default_source
from wallmap.services.player.pose_sources import BAG_DEFAULT, PoseTrack, parse_pose_source


def _tf_pose(
    contents: BagContents, parent: str, stamps: np.ndarray, t0: float, child: str = DEFAULT_CHILD
) -> PoseFacts:
    """Coverage of a tf pose source, as the player's lookups with its tolerance answer it.

    The span and gaps are those of the chain's dynamic links: where any link has no sample, the
    pose is interpolated (or, at the ends, not there).
    """
    default = parent == DEFAULT_PARENT and child == DEFAULT_CHILD
    facts = PoseFacts(f"tf:{parent}>{child}", default, available=False)
    found = chain(contents, parent, child)
    if not found.found:
        facts.reason = found.reason
        return facts
    facts.available = True
    dynamic = [np.asarray(link.stamps) for link in dynamic_links(contents, found)]
    gaps: Spans = []
    if dynamic:
        facts.samples = min(s.size for s in dynamic)
        facts.start = round(max(float(s.min()) for s in dynamic) - t0, 3)
        facts.end = round(min(float(s.max()) for s in dynamic) - t0, 3)
        gaps = union([g for s in dynamic for g in gap_spans(s)])
        facts.gaps = span_summary(gaps, t0)
    if stamps.size:
        answered = 0
        for stamp in stamps:
            try:
                contents.tf.lookup(parent, child, float(stamp), tolerance=POSE_TOLERANCE)
            except TfError:
                continue
            answered += 1
        facts.frames_with_pose, facts.frames_in_gaps = answered, inside(stamps, gaps)
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
    gaps = gap_spans(track.stamps)
    facts.gaps = span_summary(gaps, t0)
    if stamps.size:
        facts.frames_with_pose = sum(
            track.at(float(s), tolerance=POSE_TOLERANCE) is not None for s in stamps
        )
        facts.frames_in_gaps = inside(stamps, gaps)
    return facts


def pose_facts(
    contents: BagContents, sensor_frames: dict[str, int], stamps: np.ndarray, t0: float
) -> list[PoseFacts]:
    """Every candidate pose source and what it covers, the default first.

    Args:
        contents: The bag's contents.
        sensor_frames: The sensor's frame names, the most used first.
        stamps: The sensor's header stamps (s), the times a pose is needed at.
        t0: The report's time origin (s).
    """
    poses = [_tf_pose(contents, DEFAULT_PARENT, stamps, t0)]
    if "odom" in contents.tf.frames:
        poses.append(_tf_pose(contents, "odom", stamps, t0))
    # A handheld camera or a SLAM: the fixed frame straight to the frame carrying the sensor.
    sensor_frame = next(iter(sensor_frames), None)
    tf = contents.tf
    for fixed in FIXED_FRAMES:
        moving = tf.moving_frame(fixed, sensor_frame) if sensor_frame else None
        if moving is not None and moving != DEFAULT_CHILD and not tf.has_path(fixed, DEFAULT_CHILD):
            poses.append(_tf_pose(contents, fixed, stamps, t0, moving))
    topics = sorted(contents.poses, key=lambda t: contents.topics[t].msgtype != ODOMETRY_TYPE)
    return poses + [_topic_pose(contents, topic, stamps, t0) for topic in topics]


def judge_poses(
    poses: list[PoseFacts],
    bag: BagFile,
    contents: BagContents,
    sensor: SensorChoice,
    level: LevelMode = "auto",
    floor_z: float | None = None,
) -> None:
    """Whether the player plays with each pose source ("ok") or its refusal, and what it says.

    The player's warnings with a source and how it places the frames (the level of the fixed
    frame, its floor, the band the sensor sees; with ``level`` and ``floor_z`` as the player
    is given them) are kept. The frames the survey looks at are the same for every source, so
    they are read once.

    Raises:
        PlayerError: The surveyed frames cannot be read (a damaged chunk).
    """
    surveyed: list[SurveyFrame] | None = None
    for pose in poses:
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
        placed = choose_placement(plan, surveyed or [], level, floor_z)
        if isinstance(placed, Refusal):
            pose.player = placed.reason
            continue
        plan, placement = placed
        pose.player, pose.warnings = "ok", [*filter(None, [note]), *plan.warnings]
        pose.placement = placement.describe() or None
