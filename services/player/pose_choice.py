"""Which poses a bag's frames get: a ``--pose-source`` resolved against the bag's contents.

A spec names a tf chain, an odometry or pose topic, a TUM file or none (``pose_sources``). In a
given bag it resolves to a `PoseChoice`: the robot frame the poses describe (the base frame the
sensor is mounted on), where each pose is looked up, and what had to be assumed on the way; or
to a `Refusal` saying why the bag cannot give those poses. The player plays with the choice and
``wallmap doctor`` reports it, from the same contents.
"""

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from wallmap.common.messages import Pose
from wallmap.common.ros_poses import DEFAULT_CHILD, ODOMETRY_TYPE, POSE_TYPES, pose_from_matrix
from wallmap.common.tf_buffer import TfBuffer, TfError, normalize_frame
from wallmap.services.player.bag_contents import TF_TOPICS, BagContents
from wallmap.services.player.bag_file import Topic
from wallmap.services.player.errors import Refusal
from wallmap.services.player.pose_sources import PoseSourceSpec, PoseTrack, resolve_pose_topic

FIXED_FRAMES = ("map", "odom", "world")  # REP-105's fixed frames, most global first
# How far (s) a sensor stamp may lie outside the pose data and still get the end pose.
POSE_TOLERANCE = 0.05


@dataclass(frozen=True, eq=False)
class PoseChoice:
    """How a bag's frames are posed.

    Attributes:
        spec: The pose source as resolved (a plain ``tf`` in a bag without ``base_link``
            names the frame that carries the sensor instead).
        base_frame: Robot frame that the poses describe and ``T_base_sensor`` maps into.
        tf: The bag's tf: a tf source's poses, the bridges and the mounts are looked up in it.
        track: The poses of an odometry or pose topic or of a TUM file; None otherwise.
        bridged: Whether the track's frame reaches the base frame through tf (odometry names
            its own child frame, e.g. ``base_footprint``).
        warnings: What had to be assumed, for the user to read.
    """

    spec: PoseSourceSpec
    base_frame: str
    tf: TfBuffer
    track: PoseTrack | None = None
    bridged: bool = False
    warnings: tuple[str, ...] = ()

    def at(self, stamp: float) -> Pose | None:
        """The base frame's 6-DoF pose at a stamp, or None where the source does not cover it."""
        spec = self.spec
        if spec.kind == "tf":
            try:
                matrix = self.tf.lookup(
                    spec.parent, self.base_frame, stamp, tolerance=POSE_TOLERANCE
                )
            except TfError:
                return None
            return pose_from_matrix(matrix, stamp, spec.parent, self.base_frame)
        if self.track is None:
            return None
        pose = self.track.at(stamp, tolerance=POSE_TOLERANCE)
        if pose is None or not self.bridged:
            return pose
        child_base = self.tf.lookup(pose.child, self.base_frame, stamp, tolerance=math.inf)
        moved = pose_from_matrix(pose.matrix @ child_base, stamp, pose.frame, self.base_frame)
        return dataclasses.replace(moved, cov=pose.cov)

    def matrices_at(self, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """A tf source's poses at many stamps: (n, 4, 4) and which have one; else None.

        The same poses as ``at`` gives one by one (to rounding), a second of a stream at once.
        """
        if self.spec.kind != "tf":
            return None
        return self.tf.lookup_many(
            self.spec.parent, self.base_frame, stamps, tolerance=POSE_TOLERANCE
        )


def pose_topics(spec: PoseSourceSpec, topics: Mapping[str, Topic]) -> list[str]:
    """The topic an odometry or pose source reads, so that only this one is read from the bag.

    Nothing for other sources, nor for a source naming no topic of the bag (``choose_poses``
    then says why).
    """
    if spec.kind not in {"odom", "pose"}:
        return []
    topic = resolve_pose_topic(spec, {name: t.msgtype for name, t in topics.items()})
    return [] if isinstance(topic, Refusal) else [topic]


def default_source(
    spec: PoseSourceSpec, topics: Mapping[str, Topic]
) -> tuple[PoseSourceSpec, str | None]:
    """The default ``tf`` in a bag without any tf: its one pose topic, else its one odometry.

    A robot tracked by motion capture, or a localiser's bag, carries its poses on a topic and
    no tf at all; the default then takes them rather than refusing the bag. A pose topic (a
    tracker's, a localiser's) comes before an odometry one, which drifts. Returns the spec to
    use and what the player says of it (None: the spec as given).
    """
    if spec.kind != "tf" or spec.named or any(n.lstrip("/") in TF_TOPICS for n in topics):
        return spec, None
    for kind, types in (("pose", POSE_TYPES), ("odom", (ODOMETRY_TYPE,))):
        found = sorted(name for name, topic in topics.items() if topic.msgtype in types)
        if len(found) == 1:
            note = (
                f"the bag has no tf: poses from its one {kind} topic {found[0]} "
                f"(--pose-source {kind}:{found[0]})"
            )
            return PoseSourceSpec(kind, topic=found[0]), note
    return spec, None


def choose_poses(
    contents: BagContents,
    sensor_frame: str,
    spec: PoseSourceSpec,
    *,
    base_frame: str | None = None,
    track: PoseTrack | None = None,
) -> PoseChoice | Refusal:
    """Resolve a pose source in a bag.

    Args:
        contents: What the bag holds (an odom/pose source's topic among ``contents.poses``).
        sensor_frame: The frame of the sensor's first message: a plain ``tf`` source follows
            the chain to it when the bag has no ``base_link``.
        spec: The pose source.
        base_frame: The robot frame asked for; None takes the pose source's own (``base_link``
            for tf, pose, tum and none; the odometry's child frame for odom).
        track: The poses of a TUM source, read from its file.

    Returns:
        The choice, or why the bag cannot give these poses: no such (or no unique) pose topic,
        a pose topic without messages, no tf chain for a tf source.
    """
    child = normalize_frame(base_frame) if base_frame else DEFAULT_CHILD
    if spec.kind in {"odom", "pose"}:
        track = _topic_track(contents, spec, child)
        if isinstance(track, Refusal):
            return track
    warnings = []
    if base_frame is None:
        spec, warnings = follow_the_sensor(contents.tf, spec, sensor_frame)
    base = _base_frame(spec, base_frame, track)
    if spec.kind == "tf" and not contents.tf.has_path(spec.parent, base):
        reason = (
            contents.tf.no_path_message(spec.parent, base)
            if contents.tf
            else "the bag has no /tf or /tf_static"
        )
        return Refusal(
            f"pose source tf:{spec.parent}>{base}: {reason}; choose another --pose-source "
            f"(odom, pose, tum:FILE or none)"
        )
    bridged = track is not None and track.child != base and contents.tf.has_path(track.child, base)
    if track is not None and track.child != base and not bridged:
        warnings.append(
            f"no tf between the pose source's frame {track.child!r} and base frame {base!r}: "
            f"its poses are used as {base!r} poses"
        )
        track = dataclasses.replace(track, child=base)
    return PoseChoice(spec, base, contents.tf, track, bridged, tuple(warnings))


def _base_frame(spec: PoseSourceSpec, base_frame: str | None, track: PoseTrack | None) -> str:
    """The frame asked for, else the one the poses describe (``base_link`` without poses)."""
    if base_frame is not None:
        return normalize_frame(base_frame)
    if spec.kind == "tf":
        return spec.child
    return track.child if track is not None else DEFAULT_CHILD


def _topic_track(contents: BagContents, spec: PoseSourceSpec, child: str) -> PoseTrack | Refusal:
    """The poses of an odom/pose source's topic; ``child`` names the frame where they do not."""
    topic = resolve_pose_topic(spec, contents.types())
    if isinstance(topic, Refusal):
        return topic
    poses = contents.poses[topic]
    if not poses:
        return Refusal(f"pose source {spec}: topic {topic!r} has no messages")
    track = PoseTrack.from_poses(poses)
    return track if track.child else dataclasses.replace(track, child=child)


def follow_the_sensor(
    tf: TfBuffer, spec: PoseSourceSpec, sensor_frame: str
) -> tuple[PoseSourceSpec, list[str]]:
    """Without ``base_link`` in tf, the plain ``tf`` source follows the chain to the sensor.

    A handheld camera, a SLAM or a reconstruction system publishes ``map -> camera_link``
    (6-DoF) and no robot frame: the poses are then those of the frame that carries the sensor
    (``TfBuffer.moving_frame``), from the first fixed frame of REP-105 that has one.

    Returns:
        The spec to use, and the warning saying so when it changed.
    """
    if spec.kind != "tf" or spec.named or tf.has_path(spec.parent, spec.child):
        return spec, []
    for fixed in FIXED_FRAMES:
        moving = tf.moving_frame(fixed, sensor_frame) if sensor_frame else None
        if moving is not None:
            warning = (
                f"no tf {spec.parent} -> {spec.child}: the poses are those of {moving!r} in "
                f"{fixed!r}, the chain to the sensor's frame {sensor_frame!r} "
                f"(--pose-source tf:{fixed}>{moving}; name other frames the same way)"
            )
            return dataclasses.replace(spec, parent=fixed, child=moving), [warning]
    return spec, []
