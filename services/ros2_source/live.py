"""A live robot's messages as the player's frames and poses. Pure: no Zenoh, no clock of its own.

A bag holds every transform before it is played; a live robot's arrive as they come, and a
sensor message often comes before the tf that places it (``odom -> base_link`` at 50 Hz, the
camera at 30 Hz, a localiser's ``map -> odom`` late by a scan). So each sensor message waits, as
a tf2 message filter holds it, until the tree covers its stamp: its mount (base <- sensor) and,
with a tf pose source, the robot's pose (fixed <- robot); a depth image waits for a CameraInfo
too (a camera sends it beside each image, often just after). One that waits longer than
``tf_wait`` seconds of the robot's own time (the newest stamp seen on any topic) is dropped and
counted, so a missing transform never stalls the source. A clock that jumps back (a new session
of the robot, a bag played again) starts over: buffers and waiting frames (the camera's info and
the static transforms, sent once, are kept).

Frames are placed as the player places a bag's: the robot's tilt (roll, pitch, height) goes into
the sensor's mount, and the fixed frame is levelled and the sensor's height band found by a
survey of the first posed depth frames (``live_survey``), which are held, with the poses that
come meanwhile, until it is done.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wallmap.common.messages import Pose
from wallmap.common.pose3d import forward_axis
from wallmap.common.ros_poses import header_stamp, pose_from_matrix, pose_from_message
from wallmap.common.scan_row import RowSelection
from wallmap.common.tf_buffer import TfBuffer, TfError, normalize_frame
from wallmap.services.player.bag_contents import IMAGE, LASERSCAN, POINTCLOUD2
from wallmap.services.player.depth import depth_image_to_xyz
from wallmap.services.player.frames import SensorFrame, hand_out
from wallmap.services.player.laserscan import laserscan_to_xyz
from wallmap.services.player.placement import unlevelled
from wallmap.services.player.pointcloud import pointcloud2_xyz
from wallmap.services.player.pose_choice import follow_the_sensor
from wallmap.services.player.pose_sources import PoseSourceSpec
from wallmap.services.ros2_source.live_survey import LiveSurvey, survey_rows

MAX_WAITING = 64  # sensor messages waiting for their tf at most; the oldest gives way
RECENT_POSES = 64  # an odom/pose topic's newest poses, whose tilt goes with the frames
HELD_POSES = 2000  # poses held for the survey at most (10 s at 200 Hz); the oldest give way
CLOCK_JUMP = 5.0  # s back in the robot's time: a new session, not a late message


Report = Callable[[str, str], None]  # (counter, what happened): the service counts and logs


@dataclass
class _Waiting:
    stamp: float
    frame_id: str
    message: Any


Posed = tuple[Pose | None, np.ndarray]  # a frame's 6-DoF robot pose (None: none) and its mount


@dataclass
class LiveFrames:
    """Sensor messages, tf and poses in; frames placed as the player places them out.

    Attributes:
        sensor_type: The sensor topic's message type (one of ``LIVE_TYPES``).
        pose_source: Where the robot's pose comes from: ``tf`` (a chain of the tree),
            ``odom``/``pose`` (a topic, given to ``add_pose``) or ``none``.
        base_frame: The robot frame the mount is looked up to (the pose source's child).
        tf_wait: Seconds of the robot's time a sensor message waits for its tf.
        rows: The rows the detector asks for (None: whole clouds).
        report: Told of each message dropped (``no_tf``, ``no_camera_info``, ``overflow``),
            of each restart (``restarts``), of the survey (``surveyed``) and of a change of the
            robot frame (``pose_source_changed``), with a line for the log.
    """

    sensor_type: str
    pose_source: PoseSourceSpec
    base_frame: str = "base_link"
    tf_wait: float = 1.0
    rows: RowSelection | None = None
    report: Report = field(default=lambda _counter, _line: None)

    def __post_init__(self) -> None:
        self.tf = TfBuffer()
        self.camera_info: Any = None
        self.newest = -math.inf  # the robot's time: the newest stamp seen
        self._waiting: collections.deque[_Waiting] = collections.deque()
        self._pose_stamps: collections.deque[float] = collections.deque(maxlen=500)
        self._placement = unlevelled(self.base_frame)
        self._statics: dict[tuple[str, ...], Any] = {}
        self._recent: collections.deque[Pose] = collections.deque(maxlen=RECENT_POSES)
        self._poses_out: list[Pose] = []
        surveys = self.sensor_type != LASERSCAN and self.pose_source.kind != "none"
        self._survey: LiveSurvey | None = LiveSurvey() if surveys else None
        self._held: list[tuple[_Waiting, *Posed]] = []
        self._held_poses: collections.deque[Pose] = collections.deque(maxlen=HELD_POSES)

    def add_tf(self, msg: Any, *, static: bool) -> None:
        """A TFMessage; with a tf pose source, the robot's poses its stamps now cover go out."""
        stamps = [header_stamp(t.header, 0) for t in msg.transforms]
        if not static and stamps:
            self._see(max(stamps))
        added, _ = self.tf.add_message(msg, static=static)
        if static:  # kept across a restart (a bridge sends them once), the newest of each
            self._statics[tuple(normalize_frame(t.child_frame_id) for t in msg.transforms)] = msg
        if self.pose_source.kind != "tf" or static:
            return
        self._pose_stamps.extend(s for child, s in added if child == self.pose_source.child)
        self._tf_poses()

    def add_pose(self, msg: Any) -> None:
        """An Odometry or pose message of the robot (an ``odom``/``pose`` source).

        An Odometry names the robot frame it describes (``child_frame_id``); the sensor's mount
        is then looked up to that frame, as the player does for a bag's odometry.
        """
        pose = pose_from_message(msg, 0, self.base_frame)
        self._see(pose.stamp)
        if pose.child != self.base_frame:
            self.report(
                "pose_source_changed",
                f"the robot frame is {pose.child!r} (was "
                f"{self.base_frame!r}): the pose messages' child_frame_id",
            )
            self._robot_frame(pose.child)
        self._recent.append(pose)
        self._emit(pose)

    def take_poses(self) -> list[Pose]:
        """The planar poses to send, in order, since the last call.

        They go out before the frames ``ready`` gives, which they place.
        """
        out, self._poses_out = self._poses_out, []
        return out

    def add_camera_info(self, msg: Any) -> None:
        """The depth camera's intrinsics (the newest are used)."""
        self.camera_info = msg

    def add_sensor(self, msg: Any) -> None:
        """A sensor message, to wait for its tf."""
        stamp = header_stamp(msg.header, 0)
        self._see(stamp)
        if len(self._waiting) >= MAX_WAITING:
            self._waiting.popleft()
            self.report("overflow", f"a frame dropped: {MAX_WAITING} waited for their tf at once")
        self._waiting.append(_Waiting(stamp, normalize_frame(msg.header.frame_id), msg))

    def ready(self) -> list[SensorFrame]:
        """The waiting messages whose tf has come, as frames, in order; the stale dropped."""
        out, still = [], collections.deque()
        for waiting in self._waiting:
            posed = self._posed(waiting)
            if posed is None and self.newest - waiting.stamp > self.tf_wait:
                if self._without_intrinsics():
                    self.report(
                        "no_camera_info",
                        f"an image dropped after {self.tf_wait:g} s without a CameraInfo",
                    )
                    continue
                posed = self._posed(waiting) if self._follow_the_sensor(waiting) else None
                if posed is None:
                    self.report("no_tf", self._missing(waiting))
                    continue
            if posed is None:
                still.append(waiting)
            elif self._survey is not None:
                self._hold(self._survey, waiting, *posed)
            else:
                out.append(self._placed(waiting, *posed))
        self._waiting = still
        if self._survey is not None and self._survey.complete(self.newest):
            return self._end_survey(self._survey)
        return out

    def end_survey(self) -> list[SensorFrame]:
        """The frames held for a survey not yet complete, placed by what it has so far.

        For a robot that goes quiet (or a source stopping) before the survey's frames or
        seconds are in: what it sent is not kept back for ever.
        """
        if self._survey is None or not self._held:
            return []
        return self._end_survey(self._survey)

    def _without_intrinsics(self) -> bool:
        """A depth image cannot be read yet: its CameraInfo (sent beside it) has not come."""
        return self.sensor_type == IMAGE and self.camera_info is None

    def _hold(
        self, survey: LiveSurvey, waiting: _Waiting, pose: Pose | None, mount: np.ndarray
    ) -> None:
        """A frame held for the survey, its points (some rows) surveyed."""
        read, height = self._reader(waiting.message)
        rows = survey_rows(height)
        survey.add(waiting.stamp, read(rows), pose, mount, waiting.frame_id, rows)
        self._held.append((waiting, pose, mount))

    def _end_survey(self, survey: LiveSurvey) -> list[SensorFrame]:
        """The placement the survey finds; the held poses and frames, placed by it."""
        self._placement, self._survey = survey.placement(self.base_frame), None
        self.report(
            "surveyed",
            f"surveyed {len(self._held)} frames: "
            f"{self._placement.describe() or 'nothing to level'}",
        )
        for pose in self._held_poses:
            self._emit(pose)
        frames = [self._placed(*held) for held in self._held]
        self._held.clear()
        self._held_poses.clear()
        return frames

    def _emit(self, pose: Pose) -> None:
        """A 6-DoF pose of the robot: held while the survey runs, else out as a planar pose."""
        if self._survey is not None:
            self._held_poses.append(pose)
        else:
            self._poses_out.append(self._placement.place(pose, np.eye(4))[0] or pose)

    def _robot_frame(self, frame: str) -> None:
        """The frame the poses describe and the mount is looked up to is now ``frame``."""
        self.base_frame = frame
        self._placement = dataclasses.replace(self._placement, forward=forward_axis(frame))

    def _follow_the_sensor(self, waiting: _Waiting) -> bool:
        """Whether the plain ``tf`` source, still without ``map -> base_link``, changed.

        After ``tf_wait``, the poses become those of the frame that carries the sensor, from the
        first of REP-105's fixed frames that has one (``odom`` on a robot without a localiser),
        as the player does for a bag (``follow_the_sensor``).
        """
        spec, warnings = follow_the_sensor(self.tf, self.pose_source, waiting.frame_id)
        if not warnings:
            return False
        self.report("pose_source_changed", warnings[0])
        self.pose_source = spec
        self._robot_frame(spec.child)
        return True

    def _missing(self, waiting: _Waiting) -> str:
        """Why a frame is dropped: the transform that did not come."""
        needed = [(self.base_frame, waiting.frame_id)]
        if self.pose_source.kind == "tf":
            needed.append((self.pose_source.parent, self.pose_source.child))
        for target, source in needed:
            try:
                self.tf.lookup(target, source, waiting.stamp)
            except TfError as err:
                return f"a frame dropped after {self.tf_wait:g} s without its tf: {err}"
        return f"a frame dropped after {self.tf_wait:g} s without its tf"

    def _see(self, stamp: float) -> None:
        """The robot's time moved on; far back is a new session."""
        if stamp < self.newest - CLOCK_JUMP:
            self.report(
                "restarts",
                f"the robot's clock went back {self.newest - stamp:.1f} s: "
                "a new session, started over",
            )
            self.tf = TfBuffer()
            for msg in self._statics.values():
                self.tf.add_message(msg, static=True)
            self._waiting.clear()
            self._pose_stamps.clear()
            self._recent.clear()
            if self._survey is not None:  # what was held is of the old session
                self._survey = LiveSurvey()
                self._held.clear()
                self._held_poses.clear()
            self.newest = stamp
        self.newest = max(self.newest, stamp)

    def _posed(self, waiting: _Waiting) -> Posed | None:
        """A waiting message's robot pose and mount, or None while its tf is missing.

        With a tf source, the pose is the chain's at the frame's stamp; with a pose topic, the
        message nearest in time (never waited for); else none.
        """
        spec = self.pose_source
        if self._without_intrinsics():
            return None
        try:
            mount = self.tf.lookup(self.base_frame, waiting.frame_id, waiting.stamp)
            if spec.kind == "tf":
                matrix = self.tf.lookup(spec.parent, spec.child, waiting.stamp)
                return pose_from_matrix(matrix, waiting.stamp, spec.parent, spec.child), mount
        except TfError:
            return None
        if self._recent:
            return min(self._recent, key=lambda p: abs(p.stamp - waiting.stamp)), mount
        return None, mount

    def _placed(self, waiting: _Waiting, pose: Pose | None, mount: np.ndarray) -> SensorFrame:
        """A frame as the player sends it: the robot's tilt in its mount, its band's rows."""
        mount = self._placement.place(pose, mount)[1]
        read, height = self._reader(waiting.message)
        points, band = hand_out(read, height, self.rows, mount, self._placement)
        return SensorFrame(waiting.stamp, waiting.frame_id, points, mount, band=band)

    def _reader(self, msg: Any) -> tuple[Callable[[slice], np.ndarray], int]:
        if self.sensor_type == POINTCLOUD2:
            return (lambda rows: pointcloud2_xyz(msg, rows)), int(msg.height)
        if self.sensor_type == LASERSCAN:
            return (lambda _rows: laserscan_to_xyz(msg)), 1
        info = self.camera_info
        return (lambda rows: depth_image_to_xyz(msg, info, rows)), int(msg.height)

    def _tf_poses(self) -> None:
        """Poses of the robot at the stamps of its own transform that the tree now covers."""
        spec, still = self.pose_source, collections.deque(maxlen=500)
        for stamp in self._pose_stamps:
            try:
                matrix = self.tf.lookup(spec.parent, spec.child, stamp)
            except TfError:
                if self.newest - stamp <= self.tf_wait:
                    still.append(stamp)
                continue
            self._emit(pose_from_matrix(matrix, stamp, spec.parent, spec.child))
        self._pose_stamps = still
