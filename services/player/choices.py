"""The player's choices about a bag, as pure functions of what the bag holds.

The player (``BagSource``) and ``wallmap doctor`` make the same choices from the same
`BagContents`, in this order; each returns what it chose or a `Refusal` with the one line the
user sees:

1. ``select_topics``: the topics ``--topics`` names.
2. ``choose_sensor``: the sensor topic, the one asked for or the only usable one.
3. ``plan_playback``: the pose source (``pose_choice.choose_poses``) and how the sensor's first
   frame is mounted (``choose_mount``).
4. ``choose_placement``: the levelled fixed frame and the band the sensor sees, from frames
   spread over the bag (``placement.survey``).
"""

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wallmap.common.tf_buffer import TfBuffer, normalize_frame
from wallmap.services.player.bag_contents import (
    CAMERA_INFO,
    IMAGE,
    LASERSCAN,
    POINTCLOUD2,
    SENSOR_TYPES,
    BagContents,
    topic_listing,
)
from wallmap.services.player.bag_file import Topic
from wallmap.services.player.depth import SUPPORTED_ENCODINGS
from wallmap.services.player.errors import Refusal
from wallmap.services.player.placement import LevelMode, Placement, Sample, survey, unlevelled
from wallmap.services.player.pose_choice import PoseChoice, choose_poses
from wallmap.services.player.pose_sources import PoseSourceSpec, PoseTrack

SUPPORTED_SENSORS = (
    f"organized {POINTCLOUD2}, {IMAGE} depth ({'/'.join(SUPPORTED_ENCODINGS)}) with a "
    f"{CAMERA_INFO} topic in the same namespace, {LASERSCAN}"
)


def select_topics(
    topics: dict[str, Topic], wanted: Iterable[str] | None, path: Path
) -> dict[str, Topic] | Refusal:
    """The topics to read: those ``--topics`` names (leading '/' optional), or all of them."""
    if wanted is None:
        return topics
    names = {t.lstrip("/") for t in wanted}
    unknown = names - {name.lstrip("/") for name in topics}
    if unknown:
        return Refusal(
            f"--topics names {', '.join(sorted(unknown))}, not in {path} "
            f"(topics: {topic_listing(topics)})"
        )
    return {name: topic for name, topic in topics.items() if name.lstrip("/") in names}


# --- the sensor topic ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class SensorChoice:
    """The sensor topic the player plays.

    Attributes:
        topic: As spelled in the bag.
        msgtype: Its message type, e.g. ``sensor_msgs/msg/PointCloud2``.
        frame_id: The frame of its first message, without a leading '/'.
        camera_info: The first CameraInfo beside a depth image topic; None for other sensors.
    """

    topic: str
    msgtype: str
    frame_id: str
    camera_info: Any = None


@dataclass(frozen=True)
class SensorRefusal(Refusal):
    """No sensor topic to play.

    Attributes:
        candidates: The usable sensor topics when there are several to choose from.
    """

    candidates: tuple[str, ...] = ()


def _namespace(topic: str) -> str:
    """Topic namespace without leading '/': '/camera/depth/image_raw' -> 'camera/depth'."""
    return topic.lstrip("/").rpartition("/")[0]


def camera_info_topic(contents: BagContents, image_topic: str) -> str | None:
    """The CameraInfo topic beside a depth image topic (same namespace), if any."""
    namespace = _namespace(image_topic)
    return next(
        (
            name
            for name, topic in sorted(contents.topics.items())
            if topic.msgtype == CAMERA_INFO and _namespace(name) == namespace
        ),
        None,
    )


def rejection(contents: BagContents, topic: str) -> str | None:
    """Why a topic cannot be the sensor, or None if it can."""
    msgtype = contents.topics[topic].msgtype
    if msgtype not in SENSOR_TYPES:
        return f"{msgtype} is not a supported sensor type"
    first = contents.firsts[topic]
    if first is None:
        return "it has no messages"
    if msgtype == POINTCLOUD2 and first.height <= 1:
        return (
            f"it is an unorganized PointCloud2 (height {first.height}, width {first.width}); "
            f"the detector needs organized rows"
        )
    if msgtype == IMAGE:
        if first.encoding not in SUPPORTED_ENCODINGS:
            return (
                f"its encoding {first.encoding!r} is not a depth encoding "
                f"({'/'.join(SUPPORTED_ENCODINGS)})"
            )
        if camera_info_topic(contents, topic) is None:
            return f"no {CAMERA_INFO} topic in its namespace '/{_namespace(topic)}'"
    return None


def choose_sensor(contents: BagContents, requested: str | None) -> SensorChoice | Refusal:
    """The sensor topic: the requested one if usable, else the only usable one.

    Returns:
        The choice; a `SensorRefusal` when no topic (or more than one) can be chosen; a
        `Refusal` when the chosen depth images have no camera info to back-project them with.
    """
    topic = _sensor_topic(contents, requested)
    if isinstance(topic, Refusal):
        return topic
    msgtype = contents.topics[topic].msgtype
    camera_info = None
    if msgtype == IMAGE:
        info_topic = camera_info_topic(contents, topic)
        camera_info = contents.firsts[info_topic]
        if camera_info is None:
            return Refusal(f"camera info topic {info_topic!r} has no messages")
    frame_id = normalize_frame(contents.firsts[topic].header.frame_id)
    return SensorChoice(topic, msgtype, frame_id, camera_info)


def _sensor_topic(contents: BagContents, requested: str | None) -> str | SensorRefusal:
    """The requested topic if usable, else the only candidate, else why not."""
    path = contents.path
    if requested is not None:
        topic = contents.find(requested)
        if topic is None:
            return SensorRefusal(
                f"sensor topic {requested!r} is not in {path} (topics: {contents.listing()})"
            )
        if (reason := rejection(contents, topic)) is not None:
            return SensorRefusal(f"sensor topic {topic!r} cannot be used: {reason}")
        return topic
    considered = [n for n, t in sorted(contents.topics.items()) if t.msgtype in SENSOR_TYPES]
    reasons = {topic: rejection(contents, topic) for topic in considered}
    candidates = tuple(topic for topic, reason in reasons.items() if reason is None)
    if len(candidates) == 1:
        return candidates[0]
    if candidates:
        listed = ", ".join(f"{t} ({contents.topics[t].msgtype})" for t in candidates)
        return SensorRefusal(
            f"several sensor topics in {path}: {listed}; choose one with --sensor-topic",
            candidates,
        )
    rejected = "".join(f"; {t} rejected: {r}" for t, r in reasons.items())
    return SensorRefusal(
        f"no usable sensor topic in {path} (supported: {SUPPORTED_SENSORS}){rejected}; "
        f"bag topics: {contents.listing()}"
    )


# --- the sensor's mount -------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Mount:
    """How a sensor frame's T_base_sensor is obtained: fixed, or from tf at each stamp.

    Attributes:
        frame_id: The sensor frame.
        base_frame: The frame it is mounted on.
        tf: The bag's tf.
        T_base_sensor: The fixed mount; None to look it up in tf.
        warning: What was assumed to fix it, for the user to read.
    """

    frame_id: str
    base_frame: str
    tf: TfBuffer
    T_base_sensor: np.ndarray | None = None
    warning: str | None = None

    def at(self, stamp: float) -> np.ndarray:
        """T_base_sensor at a stamp (a copy: the caller may change it)."""
        if self.T_base_sensor is not None:
            return self.T_base_sensor.copy()
        # Mounting chains are rigid in practice even when published on /tf, so clamp to the
        # nearest sample rather than fail at the ends of the recording.
        return self.tf.lookup(self.base_frame, self.frame_id, stamp, tolerance=math.inf)


def choose_mount(poses: PoseChoice, sensor_topic: str, frame_id: str) -> Mount | Refusal:
    """How a sensor frame is mounted on the base frame.

    Identity when no tf is needed (the sensor frame is the base frame) or none can be had (no
    frame name, no tf at all, no poses to place it with), saying so; tf when it links the two;
    else a refusal naming the missing link.
    """
    base, tf = poses.base_frame, poses.tf
    if frame_id == base:
        return Mount(frame_id, base, tf, np.eye(4))
    if not frame_id:
        warning = (
            f"sensor messages on {sensor_topic} have no frame_id; assuming they are in base "
            f"frame {base!r}"
        )
        return Mount(frame_id, base, tf, np.eye(4), warning)
    if tf.has_path(base, frame_id):
        return Mount(frame_id, base, tf)
    if poses.spec.kind == "none" or not tf:
        why = "the bag has no tf" if not tf else "pose source is none"
        warning = (
            f"no tf from sensor frame {frame_id!r} to base frame {base!r} ({why}): using an "
            f"identity sensor mounting"
        )
        return Mount(frame_id, base, tf, np.eye(4), warning)
    return Refusal(
        f"no tf chain from sensor frame {frame_id!r} to base frame {base!r}: "
        f"{tf.no_path_message(base, frame_id)}"
    )


# --- the plan: poses and mounts -----------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Plan:
    """What the player plays a bag with, decided before its first frame.

    Attributes:
        sensor: The sensor topic.
        poses: The pose source.
        mounts: The mounts decided so far, by sensor frame (the first frame's first).
        tf_warning: Transforms tf2 would refuse, if any, said once.
    """

    sensor: SensorChoice
    poses: PoseChoice
    mounts: dict[str, Mount]
    tf_warning: str | None = None

    @property
    def warnings(self) -> list[str]:
        """What was assumed, in the order it was decided."""
        mounted = [m.warning for m in self.mounts.values() if m.warning is not None]
        return [*filter(None, [self.tf_warning]), *self.poses.warnings, *mounted]

    @property
    def surveys(self) -> bool:
        """Whether the placement looks at frames spread over the bag: posed depth data only."""
        return self.poses.spec.kind != "none" and self.sensor.msgtype != LASERSCAN


def plan_playback(
    contents: BagContents,
    sensor: SensorChoice,
    spec: PoseSourceSpec,
    *,
    base_frame: str | None = None,
    track: PoseTrack | None = None,
) -> Plan | Refusal:
    """Resolve the pose source and mount the sensor's first frame, so a bag fails up front.

    Args are those of ``pose_choice.choose_poses``.
    """
    poses = choose_poses(contents, sensor.frame_id, spec, base_frame=base_frame, track=track)
    if isinstance(poses, Refusal):
        return poses
    mount = choose_mount(poses, sensor.topic, sensor.frame_id)
    if isinstance(mount, Refusal):
        return mount
    refused = contents.tf_refused
    tf_warning = (
        f"ignored {len(refused)} invalid tf transforms, e.g. {refused[0]}" if refused else None
    )
    return Plan(sensor, poses, {sensor.frame_id: mount}, tf_warning)


# --- placement: levelling and the band ----------------------------------------------------------


@dataclass(frozen=True, eq=False)
class SurveyFrame:
    """One of the frames spread over a bag that the survey may look at.

    Attributes:
        stamp: Its header stamp, s.
        frame_id: Its sensor frame.
        points: Its whole (h, w, 3) grid, NaN where there is no return; or why it cannot be
            decoded, which refuses the bag only if the survey needs this frame (it has a pose).
    """

    stamp: float
    frame_id: str
    points: np.ndarray | Refusal


def choose_placement(
    plan: Plan,
    frames: list[SurveyFrame],
    level: LevelMode = "auto",
    floor_z: float | None = None,
) -> tuple[Plan, Placement] | Refusal:
    """Level the fixed frame and find the band from the posed frames among ``frames``.

    Args:
        plan: The plan; ``frames`` matter only when it ``surveys``.
        frames: Frames spread over the bag (``bag_frames.read_survey_frames``).
        level: ``auto`` levels a fixed frame that is not level; ``none`` takes it as it is.
        floor_z: The floor's height in the fixed frame, instead of the one found.

    Returns:
        The plan with the mounts of the frames surveyed, and the placement; or a refusal: a
        surveyed frame cannot be mounted or decoded.
    """
    base = plan.poses.base_frame
    if plan.poses.spec.kind == "none":
        return plan, unlevelled(base)
    mounts = dict(plan.mounts)
    samples = []
    for frame in frames if plan.surveys else []:
        pose = plan.poses.at(frame.stamp)
        if pose is None:
            continue
        if frame.frame_id not in mounts:
            mount = choose_mount(plan.poses, plan.sensor.topic, frame.frame_id)
            if isinstance(mount, Refusal):
                return mount
            mounts[frame.frame_id] = mount
        if isinstance(frame.points, Refusal):
            return frame.points
        sensor_pose = pose.matrix @ mounts[frame.frame_id].at(frame.stamp)  # T_fixed_sensor
        samples.append(Sample(frame.points, sensor_pose, frame.frame_id or base))
    placement = survey(samples, base, mode=level, floor_z=floor_z)
    return dataclasses.replace(plan, mounts=mounts), placement
