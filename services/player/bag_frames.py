"""A bag's sensor messages as frames: decoded, mounted and posed as planned (``choices``).

Decoding turns each message into an organized xyz grid; a few frames spread over the bag are
decoded before playing, for the survey that levels the fixed frame (``read_survey_frames``);
`BagFrames` then streams every message in bag order with its mount and its pose.
"""

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from wallmap.common import se2
from wallmap.common.messages import Pose
from wallmap.common.ros_poses import header_stamp
from wallmap.common.scan_row import RowSelection
from wallmap.common.tf_buffer import TfError, normalize_frame
from wallmap.services.player.bag_contents import LASERSCAN, POINTCLOUD2
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.choices import Plan, SensorChoice, SurveyFrame, choose_mount
from wallmap.services.player.depth import depth_image_to_xyz
from wallmap.services.player.errors import PlayerError, Refusal, decided
from wallmap.services.player.frames import ClosingSource, SensorFrame, hand_out
from wallmap.services.player.laserscan import beam_times, deskew, laserscan_to_xyz
from wallmap.services.player.lz4_chunks import Reveal
from wallmap.services.player.placement import SURVEY_FRAMES, Placement
from wallmap.services.player.pointcloud import invalid_to_nan, pointcloud2_xyz

Decoder = Callable[[Any, slice], np.ndarray]  # a message and the rows to decode


def decoder(sensor: SensorChoice) -> Decoder:
    """The function turning one sensor message into an (h, w, 3) grid.

    A cloud's grid is a view over the message with non-finite points left as they are, so a
    scan row is picked without copying the cloud; ``BagFrames.frames`` cleans what it hands out.
    """
    if sensor.msgtype == POINTCLOUD2:
        return pointcloud2_xyz
    if sensor.msgtype == LASERSCAN:
        return lambda scan, _rows: laserscan_to_xyz(scan)
    return lambda image, rows: depth_image_to_xyz(image, sensor.camera_info, rows)


def read_survey_frames(bag: BagFile, sensor: SensorChoice) -> list[SurveyFrame]:
    """The first frame of each of SURVEY_FRAMES stretches of the bag, decoded whole.

    Raises:
        PlayerError: A damaged chunk (a frame that cannot be decoded is kept as its refusal).
    """
    decode = decoder(sensor)
    topic = bag.topics[sensor.topic]
    begin, length = bag.start_ns, max(bag.duration_ns, 1)
    step = length // SURVEY_FRAMES + 1
    frames = []
    for start in range(begin, begin + length, step):
        first = bag.first(topic, mapped=True, start=start, stop=start + step)
        if first is None:
            continue
        receive_ns, msg = first
        try:
            points = invalid_to_nan(np.array(decode(msg, slice(None)), dtype=np.float32))
        except PlayerError as err:
            points = Refusal(str(err))
        stamp = header_stamp(msg.header, receive_ns)
        frames.append(SurveyFrame(stamp, normalize_frame(msg.header.frame_id), points))
    return frames


def _revealed(msg: Any, rows: slice, reveal: Reveal) -> slice:
    """``rows``, once the part of the message's data they lie in is readable (``Reveal``).

    An image's or organized cloud's rows are ``row_step`` (a cloud) or ``step`` (an image)
    bytes each; any other message is revealed whole.
    """
    data = getattr(msg, "data", None)
    if data is None:
        return rows
    height = int(getattr(msg, "height", 1))
    step = int(getattr(msg, "row_step", getattr(msg, "step", 0)))
    picked = range(height)[rows]
    whole = len(data)
    last = max(picked[0], picked[-1]) if picked else 0  # a range's ends: max() would walk it
    reveal(min((last + 1) * step, whole) if picked and step > 0 and height > 1 else whole)
    return rows


class BagFrames(ClosingSource):
    """Sensor frames and robot poses of an open bag, played as a plan says.

    Attributes:
        path: The bag.
        sensor_topic: Sensor topic as spelled in the bag.
        sensor_type: Its message type, e.g. ``sensor_msgs/msg/PointCloud2``.
        pose_spec: The pose source, as resolved.
        base_frame: Robot frame that poses describe and ``T_base_sensor`` maps into.
        warnings: Assumptions made (e.g. an identity sensor mounting) for the CLI to log; a
            sensor frame first seen while playing adds its own.
        placement: How frames are placed: the levelled fixed frame, the band the sensor sees.
    """

    def __init__(self, bag: BagFile, plan: Plan, placement: Placement) -> None:
        """Play ``bag`` as ``plan`` says, placing frames with ``placement``; ``close`` closes it."""
        self.path = bag.path
        self.sensor_topic = plan.sensor.topic
        self.sensor_type = plan.sensor.msgtype
        self.pose_spec = plan.poses.spec
        self.base_frame = plan.poses.base_frame
        self.warnings = plan.warnings
        self.placement = placement
        self._bag, self._plan = bag, plan
        self._mounts = dict(plan.mounts)
        self._decode = decoder(plan.sensor)

    def pose_at(self, stamp: float) -> Pose | None:
        """The base frame's 6-DoF pose at a stamp, or None where the source does not cover it."""
        return self._plan.poses.at(stamp)

    def planar_poses_at(self, stamps: np.ndarray) -> list[Pose | None]:
        """The planar poses at some stamps: a tf chain's all at once, others one by one."""
        poses = self._plan.poses
        try:
            found = poses.matrices_at(stamps)
        except TfError:  # as ``at`` finds it: no pose at any stamp
            return [None] * len(stamps)
        if found is None:
            return self.placement.planar_each(self.pose_at, stamps)
        return self.placement.planar_many(stamps, *found, poses.spec.parent, poses.base_frame)

    @property
    def pose_stamps(self) -> np.ndarray | None:
        """The pose topic's own stamps (None for tf and none): where its dropouts are."""
        track = self._plan.poses.track
        return None if track is None else track.stamps

    def _mount(self, frame_id: str, stamp: float) -> np.ndarray:
        """T_base_sensor for a sensor frame, deciding once per frame name how to obtain it.

        Raises:
            PlayerError: A new sensor frame that tf does not link to the base frame.
        """
        if frame_id not in self._mounts:
            mount = decided(choose_mount(self._plan.poses, self.sensor_topic, frame_id))
            self._mounts[frame_id] = mount
            if mount.warning is not None:
                self.warnings.append(mount.warning)
        return self._mounts[frame_id].at(stamp)

    def frames(
        self,
        rows: RowSelection | None = None,
        start: float | None = None,
        stop: float | None = None,
    ) -> Iterator[tuple[SensorFrame, Pose | None]]:
        """Yield every sensor message as (SensorFrame, pose at its stamp or None), in bag order.

        Args:
            rows: Hand out only what this selection picks (``pick_points``: the band's stack
                of points, or one row), reading only the image rows it searches
                (``rows_to_search``): decoding whole clouds is most of a player's time. The band
                is the selection's, or the one the sensor sees (``placement.band``). None hands
                out every row.
            start: Seconds from the bag's start: the first message received then or later.
            stop: Seconds from the bag's start: messages received before it only.

        Raises:
            PlayerError: A message cannot be read or decoded (its index is named).
        """
        begin = self._bag.start_ns
        window = {
            "start": None if start is None else begin + round(start * 1e9),
            "stop": None if stop is None else begin + round(stop * 1e9),
        }
        topic = self._bag.topics[self.sensor_topic]
        messages = self._bag.sensor_messages(topic, **window)
        for index, (receive_ns, msg, reveal) in enumerate(messages):
            stamp = header_stamp(msg.header, receive_ns)
            frame_id = normalize_frame(msg.header.frame_id)
            try:
                mount = self._mount(frame_id, stamp)
                pose, mount = self.placement.place(self.pose_at(stamp), mount)
                points, stacked = hand_out(  # a LaserScan has no height: it is one row
                    lambda rows_read, m=msg, r=reveal: self._decode(m, _revealed(m, rows_read, r)),
                    getattr(msg, "height", 1),
                    rows,
                    mount,
                    self.placement,
                )
            except PlayerError as err:
                raise PlayerError(f"{self.sensor_topic} message {index}: {err}") from err
            sweep = 0.0
            if self.sensor_type == LASERSCAN:
                points, sweep = self._deskewed(msg, stamp, points, mount)
            bag_time = (receive_ns - begin) * 1e-9
            yield SensorFrame(stamp, frame_id, points, mount, bag_time, stacked, sweep), pose

    def _deskewed(
        self, msg: Any, stamp: float, points: np.ndarray, mount: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """A scan deskewed with the poses where its beams are timed, and the sweep left over.

        Returns the points and how long the sweep they were not deskewed over took (0 once
        deskewed): a scan without beam times, or without poses, is widened by the mapper.
        """
        period = self.duration / max(self.frame_count - 1, 1)
        timed, span = beam_times(msg, period)
        first = self._planar(stamp) if timed else None
        last = self._planar(stamp + span) if first is not None else None
        if first is None or last is None:
            return points, span
        return deskew(points, mount, se2.between(first.vector, last.vector)), 0.0

    def _planar(self, stamp: float) -> Pose | None:
        return self.placement.place(self.pose_at(stamp), np.eye(4))[0]

    @property
    def frame_count(self) -> int:
        """Number of sensor messages, for progress reporting."""
        return self._bag.topics[self.sensor_topic].count

    def __len__(self) -> int:
        """Number of sensor messages (``frame_count``)."""
        return self.frame_count

    @property
    def duration(self) -> float:
        """Time between the bag's first and last message, seconds."""
        return self._bag.duration_ns * 1e-9

    def close(self) -> None:
        """Close the bag; safe to call twice."""
        self._bag.close()
