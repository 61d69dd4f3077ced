"""Where the robot's pose comes from: the ``--pose-source`` spec, pose tracks and TUM files.

Bags carry the robot pose in different ways (a tf chain, an odometry topic, a localizer's pose
topic) and some carry none, so the user picks one with a short spec. Poses keep all six degrees
of freedom here (a handheld camera's trajectory is not planar); the bag source splits each into
the planar pose the map uses and the tilt that goes with the frame's mount.
"""

import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from wallmap.common.messages import Pose
from wallmap.common.pose3d import quaternion_from_matrix, slerp, transform_matrix
from wallmap.common.ros_poses import (
    DEFAULT_CHILD,
    DEFAULT_PARENT,
    ODOMETRY_TYPE,
    POSE_TYPES,
    pose_from_matrix,
)
from wallmap.common.tf_buffer import normalize_frame
from wallmap.services.player.errors import PlayerError, Refusal

ACCEPTED_FORMS = "tf, tf:PARENT>CHILD, odom, odom:TOPIC, pose, pose:TOPIC, tum:FILE, none"
BAG_DEFAULT = "tf"  # a bag's poses when none is asked for: map -> base_link (or the sensor)

PoseSourceKind = Literal["tf", "odom", "pose", "tum", "none"]


@dataclass(frozen=True)
class PoseSourceSpec:
    """A parsed ``--pose-source`` value.

    Attributes:
        kind: Which source: a tf chain, an odometry topic, a pose topic, a TUM file, or none.
        parent: Fixed frame of a tf source.
        child: Robot frame of a tf source.
        topic: Topic of an odom/pose source; None means "detect it in the bag".
        path: File of a tum source.
        named: Whether a tf source named its frames (``tf:PARENT>CHILD``) rather than taking the
            default ``map -> base_link``, which a bag without ``base_link`` may replace.
    """

    kind: PoseSourceKind
    parent: str = DEFAULT_PARENT
    child: str = DEFAULT_CHILD
    topic: str | None = None
    path: Path | None = None
    named: bool = False

    def __str__(self) -> str:
        """The canonical spec, for logs and error messages."""
        if self.kind == "tf":
            return f"tf:{self.parent}>{self.child}"
        if self.kind == "tum":
            return f"tum:{self.path}"
        if self.topic is not None:
            return f"{self.kind}:{self.topic}"
        return self.kind


def parse_pose_source(spec: str) -> PoseSourceSpec:
    """Parse a ``--pose-source`` value.

    Args:
        spec: One of tf, tf:PARENT>CHILD, odom, odom:TOPIC, pose, pose:TOPIC, tum:FILE, none.

    Returns:
        The parsed spec (``tf`` means ``tf:map>base_link``).

    Raises:
        PlayerError: The spec matches none of the accepted forms.
    """
    text = spec.strip()
    kind, colon, argument = text.partition(":")
    argument = argument.strip()
    if kind == "none" and not colon:
        return PoseSourceSpec("none")
    if kind == "tf" and not colon:
        return PoseSourceSpec("tf")
    if kind == "tf" and (match := re.fullmatch(r"([^>\s]+)\s*>\s*([^>\s]+)", argument)):
        parent, child = normalize_frame(match[1]), normalize_frame(match[2])
        if parent and child and parent != child:
            return PoseSourceSpec("tf", parent=parent, child=child, named=True)
    if kind in {"odom", "pose"} and not colon:
        return PoseSourceSpec(kind)
    if kind in {"odom", "pose"} and argument and not any(c.isspace() for c in argument):
        return PoseSourceSpec(kind, topic=argument)
    if kind == "tum" and argument:
        return PoseSourceSpec("tum", path=Path(argument))
    raise PlayerError(f"invalid pose source {spec!r}; accepted forms: {ACCEPTED_FORMS}")


def resolve_pose_topic(spec: PoseSourceSpec, topics: dict[str, str]) -> str | Refusal:
    """Pick the bag topic an odom/pose source reads.

    Args:
        spec: A spec of kind ``odom`` or ``pose``.
        topics: The bag's topic names mapped to their message types.

    Returns:
        The topic name as spelled in the bag (a leading '/' may differ from the spec's), or a
        refusal: the named topic is absent or of the wrong type, or detection finds no suitable
        topic (or, for ``pose``, several).
    """
    wanted = (ODOMETRY_TYPE,) if spec.kind == "odom" else POSE_TYPES
    listing = ", ".join(f"{name} ({kind})" for name, kind in sorted(topics.items())) or "none"
    if spec.topic is not None:
        name = next((t for t in topics if t.lstrip("/") == spec.topic.lstrip("/")), None)
        if name is None:
            return Refusal(
                f"pose source {spec}: the bag has no topic {spec.topic!r} (topics: {listing})"
            )
        if topics[name] not in wanted:
            return Refusal(
                f"pose source {spec}: topic {name!r} is {topics[name]}, expected "
                f"{' or '.join(wanted)}"
            )
        return name
    matches = sorted(name for name, kind in topics.items() if kind in wanted)
    if not matches:
        return Refusal(
            f"pose source {spec}: the bag has no {' or '.join(wanted)} topic (topics: {listing})"
        )
    if spec.kind == "pose" and len(matches) > 1:
        return Refusal(
            f"pose source pose: several pose topics ({', '.join(matches)}); "
            f"choose one with pose:TOPIC"
        )
    return matches[0]


@dataclass(frozen=True, eq=False)
class PoseTrack:
    """A time-sorted 6-DoF trajectory, interpolated at sensor stamps.

    Attributes:
        stamps: Strictly increasing sample times, float seconds.
        positions: (n, 3) positions, metres.
        rotations: (n, 4) unit quaternions (x, y, z, w).
        cov: (n, 3, 3) x/y/yaw covariances, NaN where a sample has none; None if none has one.
        frame: Fixed frame of the poses.
        child: Frame the poses describe (the robot's base, or the sensor itself).
    """

    stamps: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray
    cov: np.ndarray | None
    frame: str = DEFAULT_PARENT
    child: str = DEFAULT_CHILD

    @classmethod
    def from_poses(cls, poses: list[Pose]) -> "PoseTrack":
        """Build a track from poses in any order; a repeated stamp keeps its last pose.

        Raises:
            PlayerError: No poses.
        """
        if not poses:
            raise PlayerError("the pose source holds no poses")
        stamps = np.array([p.stamp for p in poses], dtype=np.float64)
        order = np.argsort(stamps, kind="stable")
        stamps = stamps[order]
        kept = [poses[i] for i in order[np.append(stamps[1:] != stamps[:-1], True)]]
        cov = None
        if any(p.cov is not None for p in kept):
            cov = np.stack([p.cov if p.cov is not None else np.full((3, 3), np.nan) for p in kept])
        return cls(
            stamps=np.array([p.stamp for p in kept]),
            positions=np.array([(p.x, p.y, p.z) for p in kept]),
            rotations=np.array([quaternion_from_matrix(p.matrix[:3, :3]) for p in kept]),
            cov=cov,
            frame=poses[0].frame,
            child=poses[0].child,
        )

    def __len__(self) -> int:
        """Number of samples."""
        return int(self.stamps.size)

    def at(self, stamp: float, *, tolerance: float = 0.05) -> Pose | None:
        """Interpolate the pose at ``stamp``.

        Position and covariance interpolate linearly, the rotation along the shorter arc
        (slerp). Within ``tolerance`` seconds outside the track the end sample is used.

        Args:
            stamp: Query time, float seconds.
            tolerance: How far outside [first, last] a stamp may lie and still get a pose.

        Returns:
            The pose stamped ``stamp``, or None when the track does not cover it.
        """
        stamps = self.stamps
        if not stamps[0] - tolerance <= stamp <= stamps[-1] + tolerance:
            return None
        upper = int(np.searchsorted(stamps, stamp, side="right"))
        lower = max(upper - 1, 0)
        upper = min(upper, stamps.size - 1)
        span = stamps[upper] - stamps[lower]
        weight = min(max((stamp - stamps[lower]) / span, 0.0), 1.0) if span > 0 else 0.0
        position = self.positions[lower] + (self.positions[upper] - self.positions[lower]) * weight
        rotation = slerp(tuple(self.rotations[lower]), tuple(self.rotations[upper]), weight)
        pose = pose_from_matrix(
            transform_matrix(tuple(position), rotation), float(stamp), self.frame, self.child
        )
        if self.cov is None:
            return pose
        mixed = self.cov[lower] + (self.cov[upper] - self.cov[lower]) * weight
        return pose if np.isnan(mixed).any() else dataclasses.replace(pose, cov=mixed)


def load_tum(path: Path, *, frame: str = DEFAULT_PARENT, child: str = DEFAULT_CHILD) -> PoseTrack:
    """Read a TUM trajectory file (``t x y z qx qy qz qw`` per line, ``#`` comments).

    Args:
        path: The file.
        frame: Fixed frame to report the poses in (TUM files do not name one).
        child: Robot frame the poses describe.

    Returns:
        The track (6-DoF: TUM RGB-D ground truth is the camera's optical frame).

    Raises:
        PlayerError: The file is unreadable, a line is malformed (its number is given), or the
            file holds no poses.
    """
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise PlayerError(f"cannot read TUM pose file {path}: {err}") from err
    poses = []
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        try:
            values = [float(v) for v in content.replace(",", " ").split()]
        except ValueError:
            values = []
        if len(values) != 8 or not all(math.isfinite(v) for v in values):
            raise PlayerError(
                f"TUM pose file {path} line {number}: expected 8 numbers "
                f"'t x y z qx qy qz qw', got {content!r}"
            )
        t, x, y, z, qx, qy, qz, qw = values
        norm = math.hypot(qx, qy, qz, qw)
        if not 0.9 < norm < 1.1:
            raise PlayerError(
                f"TUM pose file {path} line {number}: the quaternion (qx qy qz qw) is not unit"
            )
        matrix = transform_matrix((x, y, z), (qx / norm, qy / norm, qz / norm, qw / norm))
        poses.append(pose_from_matrix(matrix, t, frame, child))
    if not poses:
        raise PlayerError(f"TUM pose file {path} holds no poses")
    return PoseTrack.from_poses(poses)
