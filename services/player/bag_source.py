"""Read a ROS 1 or ROS 2 bag into sensor frames and robot poses for the player to publish.

Opening a bag does everything that can fail up front, so a user sees one clear error before
any frame is published: it reads what the bag holds (``bag_contents``), makes the player's
choices from that (``choices``: the sensor topic, the pose source, the sensor's mount, the
levelled fixed frame), then plays its frames as planned (``bag_frames``).
"""

from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

from wallmap.common.ros_poses import DEFAULT_CHILD
from wallmap.common.tf_buffer import normalize_frame
from wallmap.services.player.bag_contents import read_contents
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.bag_frames import BagFrames, read_survey_frames
from wallmap.services.player.choices import (
    Plan,
    choose_placement,
    choose_sensor,
    plan_playback,
    select_topics,
)
from wallmap.services.player.errors import decided
from wallmap.services.player.frames import SensorFrame
from wallmap.services.player.placement import LevelMode, Placement
from wallmap.services.player.pose_choice import default_source, pose_topics
from wallmap.services.player.pose_sources import (
    BAG_DEFAULT,
    PoseSourceSpec,
    load_tum,
    parse_pose_source,
)

__all__ = ["BagSource", "SensorFrame"]


class BagSource(BagFrames):
    """Sensor frames and robot poses from one bag, checked and ready when constructed.

    The attributes are those of `BagFrames`.
    """

    def __init__(
        self,
        path: Path,
        *,
        sensor_topic: str | None = None,
        pose_source: str = BAG_DEFAULT,
        base_frame: str | None = None,
        topics: Iterable[str] | None = None,
        level: LevelMode = "auto",
        floor_z: float | None = None,
    ) -> None:
        """Open the bag and resolve the sensor topic, pose source and sensor mounting.

        Args:
            path: ROS 1 .bag file, ROS 2 bag folder, or ROS 2 .mcap file.
            sensor_topic: Sensor topic (leading '/' optional); None detects the only candidate.
            pose_source: A ``--pose-source`` spec (see ``parse_pose_source``).
            base_frame: Robot frame; defaults to the pose source's child frame (``base_link``
                for tf, pose, tum and none; the odometry's child frame for odom).
            topics: Read only these topics (leading '/' optional), as ``ros2 bag play --topics``:
                the sensor topic, tf and pose topics are looked for among them.
            level: ``auto`` levels a fixed frame that is not level, from the depth data;
                ``none`` takes it as it is.
            floor_z: The floor's height in the fixed frame, instead of the one found.

        Raises:
            PlayerError: Unreadable bag, no usable (or an ambiguous) sensor topic, a bad pose
                source, or no tf chain from the sensor to the base frame when one is required.
        """
        spec = parse_pose_source(pose_source)
        bag = BagFile(Path(path))
        try:
            plan, placement = _decide(bag, spec, sensor_topic, base_frame, topics, level, floor_z)
        except BaseException:
            bag.close()
            raise
        super().__init__(bag, plan, placement)


def _decide(
    bag: BagFile,
    spec: PoseSourceSpec,
    sensor_topic: str | None,
    base_frame: str | None,
    topics: Iterable[str] | None,
    level: LevelMode,
    floor_z: float | None,
) -> tuple[Plan, Placement]:
    """Read what the bag holds and make the player's choices, in order (see ``choices``).

    Raises:
        PlayerError: The first choice refused, or a damaged chunk.
    """
    selected = decided(select_topics(bag.topics, topics, bag.path))
    spec, note = default_source(spec, selected)
    contents = read_contents(bag, selected, pose_topics=pose_topics(spec, selected))
    sensor = decided(choose_sensor(contents, sensor_topic))
    track = None
    if spec.path is not None:  # a TUM file's poses describe the base frame
        track = load_tum(spec.path, child=normalize_frame(base_frame or DEFAULT_CHILD))
    plan = decided(plan_playback(contents, sensor, spec, base_frame=base_frame, track=track))
    if note is not None:
        plan = replace(plan, poses=replace(plan.poses, warnings=(note, *plan.poses.warnings)))
    frames = read_survey_frames(bag, sensor) if plan.surveys else []
    return decided(choose_placement(plan, frames, level, floor_z))
