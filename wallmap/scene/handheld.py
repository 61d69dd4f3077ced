"""Recordings of a handheld depth camera: 6-DoF, in a fixed frame that need not be level.

What people record with a Kinect in their hand, or get from a SLAM or reconstruction system: the
camera 1.4 m up, pitched down, rolling and pitching as it is carried and rising and falling with
the steps, and a trajectory in a frame whose "up" is not z and whose floor is not at z = 0. The
scene is the same generated building (its truth is in the level map frame); the recording comes
three ways, as users have it:

- ``camera``: a bag with a 6-DoF tf ``map -> camera_link`` in the recorded (tilted) frame;
- ``robot``: a bag with a planar ``map -> base_link`` (level) and ``base_link -> camera_link``
  on /tf carrying the camera's height, roll and pitch;
- ``tum``: a TUM RGB-D folder (``depth.txt``, 16-bit PNGs in millimetres, ``groundtruth.txt``
  of the optical frame in the recorded frame).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from PIL import Image

from wallmap.common.pose3d import (
    invert,
    planar_matrix,
    pose_matrix,
    quaternion_from_matrix,
    rotation_matrix,
)
from wallmap.scene.bags import (
    CAMERA_INFO_TOPIC,
    CAMERA_LINK_FRAME,
    IMAGE_TOPIC,
    OPTICAL_FRAME,
    OPTICAL_QUATERNION,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    BagSink,
    SceneInfo,
    camera_info,
    depth_image,
    stamp_to_ns,
    sub_seeds,
    tf_message,
    transform_stamped,
    truth_path_for,
)
from wallmap.scene.floorplan import FloorPlan
from wallmap.scene.render import Camera, render_depth, walls_seen
from wallmap.scene.trajectory import Trajectory, generate_trajectory

HandheldStyle = Literal["camera", "robot", "tum"]
MAP_FRAME, BASE_FRAME = "map", "base_link"
SEEN_BAND = (0.9, 1.6)  # m: where a handheld camera's walls are looked for (the truth's counts)
LINK_OPTICAL = np.eye(4)  # T_camera_link_optical: the optical frame's axes (z forward)
LINK_OPTICAL[:3, :3] = rotation_matrix(OPTICAL_QUATERNION)


@dataclass(frozen=True)
class Handheld:
    """How the camera is carried, and the frame the trajectory is recorded in.

    Attributes:
        height: Mean height of the camera above the floor (m).
        pitch_deg: Mean pitch (negative: looking down).
        roll_amplitude_deg: Roll swings this far either way...
        pitch_amplitude_deg: ...and pitch this far around its mean...
        height_amplitude: ...and the height this far (m), each at its own slow pace.
        frame_tilt_deg: The recorded frame is the level map turned this far about a horizontal
            axis (a SLAM's first camera frame, a reconstruction's own frame).
        frame_tilt_axis_deg: Heading of that axis in the map.
        floor_z: Height of the map's floor in the recorded frame, along its up.
    """

    height: float = 1.4
    pitch_deg: float = -25.0
    roll_amplitude_deg: float = 10.0
    pitch_amplitude_deg: float = 10.0
    height_amplitude: float = 0.2
    frame_tilt_deg: float = 0.0
    frame_tilt_axis_deg: float = 30.0
    floor_z: float = 0.0

    def frame_from_map(self) -> np.ndarray:
        """T_recorded_map: the tilt about the horizontal axis, then the floor's offset."""
        axis = math.radians(self.frame_tilt_axis_deg)
        half = math.radians(self.frame_tilt_deg) / 2
        q = (math.cos(axis) * math.sin(half), math.sin(axis) * math.sin(half), 0.0, math.cos(half))
        out = np.eye(4)
        out[:3, :3] = rotation_matrix(q)
        out[:3, 3] = out[:3, :3] @ np.array([0.0, 0.0, self.floor_z])
        return out

    def mount(self, t: float, phase: np.ndarray) -> np.ndarray:
        """T_base_camera_link at time t: height, roll and pitch as the camera is carried."""
        roll = math.radians(self.roll_amplitude_deg) * math.sin(0.7 * t + phase[0])
        pitch = math.radians(self.pitch_deg) + math.radians(self.pitch_amplitude_deg) * math.sin(
            0.45 * t + phase[1]
        )
        height = self.height + self.height_amplitude * math.sin(1.1 * t + phase[2])
        # ROS pitch is positive nose down: a camera looking down has a positive pitch.
        return pose_matrix(0.0, 0.0, height, roll, -pitch, 0.0)


Frames = list[tuple[float, np.ndarray, np.ndarray, np.ndarray]]  # stamp, depth, mount, pose


@dataclass(frozen=True)
class HandheldTake:
    """A camera carried through a scene and rendered once: each style writes the same frames.

    Attributes:
        seed: The scene's seed.
        plan: The scene.
        hand: How the camera was carried.
        camera: The camera.
        rate_hz: Frames per second.
        truth: The floor poses under the camera, one per frame.
        frames: Per frame: stamp, depth, T_base_camera_link, the camera link in the recorded frame.
        seen_counts: Per wall, the frames in which it was seen in ``SEEN_BAND``.
    """

    seed: int
    plan: FloorPlan
    hand: Handheld
    camera: Camera
    rate_hz: float
    truth: Trajectory
    frames: Frames
    seen_counts: dict[int, int]


def carry_camera(
    *,
    seed: int,
    n_frames: int,
    plan: FloorPlan,
    handheld: Handheld | None = None,
    camera: Camera | None = None,
    rate_hz: float = 15.0,
) -> HandheldTake:
    """Carry a camera through a scene and render what it sees (``write_handheld_recording``)."""
    hand = handheld or Handheld()
    camera = camera or Camera()
    traj_seed, noise_seed, phase_seed = sub_seeds(seed, 3)
    route = generate_trajectory(plan, traj_seed, rate_hz=rate_hz)
    truth = route.sliced(slice(0, min(n_frames, len(route))))
    rng = np.random.default_rng(noise_seed)
    phase = np.random.default_rng(phase_seed).uniform(0, 2 * math.pi, 3)
    recorded_from_map = hand.frame_from_map()
    seen_counts = {w.id: 0 for w in plan.walls}
    frames = []
    for k in range(len(truth.stamps)):
        t = float(truth.stamps[k] - truth.stamps[0])
        mount = hand.mount(t, phase)
        depth, hit_wall = render_depth(plan, *truth.pose_at(k), camera, rng, mount @ LINK_OPTICAL)
        for wall_id in walls_seen(
            hit_wall, depth, camera, z_band=SEEN_BAND, mount=mount @ LINK_OPTICAL
        ):
            seen_counts[wall_id] += 1
        map_link = planar_matrix(*truth.pose_at(k)) @ mount
        frames.append((float(truth.stamps[k]), depth, mount, recorded_from_map @ map_link))
    return HandheldTake(seed, plan, hand, camera, rate_hz, truth, frames, seen_counts)


def write_handheld_recording(
    path: str | Path, take: HandheldTake, style: HandheldStyle
) -> SceneInfo:
    """Record a take the ``style`` way, with the truth beside it.

    The truth (``<path>.truth.json``) has the plan in the level map frame, the floor poses
    under the camera and, per wall, the frames in which it was seen in ``SEEN_BAND``.
    """
    path = Path(path)
    if style == "tum":
        _write_tum(path, take.frames)
    else:
        _write_bag(path, take.frames, take.camera, style)
    truth_path = truth_path_for(path)
    n_frames = len(take.frames)
    truth_path.write_text(
        json.dumps(
            {
                "seed": take.seed,
                "format": style,
                "sensor": "depth16",
                "rate_hz": take.rate_hz,
                "n_frames": n_frames,
                "camera": take.camera.to_json(),
                "handheld": asdict(take.hand),
                "plan": take.plan.to_json(),
                "trajectory": take.truth.to_json(),
                "stamps_ns": [stamp_to_ns(s) for s in take.truth.stamps],
                "seen_counts": {str(k): v for k, v in take.seen_counts.items()},
            }
        )
    )
    return SceneInfo(path, truth_path, n_frames, take.plan, take.truth, dict(take.seen_counts))


def _write_bag(path: Path, frames: Frames, camera: Camera, style: HandheldStyle) -> None:
    with BagSink(path, "ros1", compress=True) as sink:
        static = sink.topic(TF_STATIC_TOPIC, "tf2_msgs/msg/TFMessage", latched=True)
        tf = sink.topic(TF_TOPIC, "tf2_msgs/msg/TFMessage")
        image_topic = sink.topic(IMAGE_TOPIC, "sensor_msgs/msg/Image")
        info_topic = sink.topic(CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo")
        first_ns = stamp_to_ns(frames[0][0])
        optical = transform_stamped(
            sink,
            TF_STATIC_TOPIC,
            first_ns,
            CAMERA_LINK_FRAME,
            OPTICAL_FRAME,
            (0.0, 0.0, 0.0),
            OPTICAL_QUATERNION,
        )
        sink.write(static, first_ns, tf_message(sink, optical))
        for stamp, depth, mount, recorded_link in frames:
            stamp_ns = stamp_to_ns(stamp)
            if style == "camera":
                edges = [_edge(sink, stamp_ns, MAP_FRAME, CAMERA_LINK_FRAME, recorded_link)]
            else:
                base = recorded_link @ invert(mount)
                edges = [
                    _edge(sink, stamp_ns, MAP_FRAME, BASE_FRAME, base),
                    _edge(sink, stamp_ns, BASE_FRAME, CAMERA_LINK_FRAME, mount),
                ]
            sink.write(tf, stamp_ns, tf_message(sink, *edges))
            sink.write(image_topic, stamp_ns, depth_image(sink, stamp_ns, depth, camera, "depth16"))
            sink.write(info_topic, stamp_ns, camera_info(sink, stamp_ns, camera))


def _edge(sink: BagSink, stamp_ns: int, parent: str, child: str, matrix: np.ndarray) -> object:
    xyz = (float(matrix[0, 3]), float(matrix[1, 3]), float(matrix[2, 3]))
    rotation = quaternion_from_matrix(matrix[:3, :3])
    return transform_stamped(sink, TF_TOPIC, stamp_ns, parent, child, xyz, rotation)


def _write_tum(path: Path, frames: Frames) -> None:
    (path / "depth").mkdir(parents=True)
    listing = ["# depth maps (16-bit PNG, millimetres)", "# timestamp filename"]
    trajectory = ["# the optical frame in the recorded frame", "# timestamp tx ty tz qx qy qz qw"]
    for stamp, depth, _, recorded_link in frames:
        name = f"depth/{stamp:.6f}.png"
        millimetres = np.clip(np.nan_to_num(np.round(depth * 1000.0)), 0, 65535).astype(np.uint16)
        Image.fromarray(millimetres).save(path / name)
        listing.append(f"{stamp:.6f} {name}")
        pose = recorded_link @ LINK_OPTICAL
        qx, qy, qz, qw = quaternion_from_matrix(pose[:3, :3])
        x, y, z = pose[:3, 3]
        trajectory.append(
            f"{stamp:.6f} {x:.6f} {y:.6f} {z:.6f} {qx:.8f} {qy:.8f} {qz:.8f} {qw:.8f}"
        )
    (path / "depth.txt").write_text("\n".join(listing) + "\n")
    (path / "groundtruth.txt").write_text("\n".join(trajectory) + "\n")
