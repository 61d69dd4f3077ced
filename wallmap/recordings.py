"""The real RGB-D recordings beside the project, and the bags users would make of them.

A depth camera's recording reaches wallmap in one of three ways: a TUM RGB-D folder (a camera
trajectory, often in a frame that is not level), a bag whose tf gives the camera's 6-DoF pose
(``map -> camera_link``, as a SLAM or a reconstruction system publishes it), or a bag from a robot
(a planar ``map -> base_link`` and the camera on a tilting mount, ``base_link -> camera_link`` on
/tf). ``tum_as_bag`` writes the two bags from a folder, so that the three can be compared on the
same frames (``benchmarks/real_rgbd.py``, ``tests/e2e/test_real_rgbd.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from wallmap.common.pose3d import (
    invert,
    planar_matrix,
    quaternion_from_matrix,
    split_planar,
    transform_matrix,
)
from wallmap.scene import Camera
from wallmap.scene.bags import (
    CAMERA_INFO_TOPIC,
    IMAGE_TOPIC,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    BagSink,
    camera_info,
    depth_image,
    stamp_to_ns,
    tf_message,
    transform_stamped,
)
from wallmap.services.player.placement import survey
from wallmap.services.player.tum_folder import TumFolder, read_depth_list, read_depth_png

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
# REP-103: an optical frame (z forward, y down) in its camera link (x forward, z up).
OPTICAL_IN_LINK = transform_matrix((0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5))
LINK, OPTICAL, BASE, MAP = "camera_link", "camera_depth_optical_frame", "base_link", "map"


@dataclass(frozen=True)
class DepthCamera:
    """A recording's depth camera: pinhole (fx, fy, cx, cy) in pixels, depth units per metre."""

    intrinsics: tuple[float, float, float, float]
    depth_scale: float


RGBD: dict[str, tuple[Path, DepthCamera]] = {
    "redkitchen": (
        REAL / "rgbd" / "redkitchen_150_199",
        DepthCamera((585.0, 585.0, 320.0, 240.0), 1000.0),
    ),
    "tum_fr3_cabinet": (
        REAL / "rgbd" / "tum_fr3_cabinet",
        DepthCamera((535.4, 539.2, 320.1, 247.6), 5000.0),
    ),
}

Way = Literal["tf-6dof", "planar-base"]


def tum_as_bag(folder: Path, out: Path, camera: DepthCamera, *, way: Way) -> Path:
    """Write a TUM folder as a ROS 1 bag: depth images (16UC1), camera info and tf.

    ``tf-6dof``: /tf ``map -> camera_link`` (the trajectory, in its own frame, level or not).
    ``planar-base``: /tf ``map -> base_link`` on the floor (the trajectory levelled as the
    player levels the folder) and ``base_link -> camera_link``, the camera's height and tilt.
    Both have /tf_static ``camera_link -> camera_depth_optical_frame``.
    """
    recording = TumFolder(
        folder, intrinsics=camera.intrinsics, depth_scale=camera.depth_scale, level="none"
    )
    levelling = np.eye(4)
    if way == "planar-base":
        levelling = survey(list(recording.samples()), OPTICAL).levelling
    fx, fy, cx, cy = camera.intrinsics
    with BagSink(out, "ros1", compress=True) as sink:
        static = sink.topic(TF_STATIC_TOPIC, "tf2_msgs/msg/TFMessage", latched=True)
        tf = sink.topic(TF_TOPIC, "tf2_msgs/msg/TFMessage")
        image_topic = sink.topic(IMAGE_TOPIC, "sensor_msgs/msg/Image")
        info_topic = sink.topic(CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo")
        entries = read_depth_list(folder / "depth.txt")
        first_ns = stamp_to_ns(entries[0][0])
        link_optical = _transform(sink, TF_STATIC_TOPIC, first_ns, LINK, OPTICAL, OPTICAL_IN_LINK)
        sink.write(static, first_ns, tf_message(sink, link_optical))
        for stamp, image_path in entries:
            pose = recording.pose_at(stamp)
            if pose is None:
                continue
            stamp_ns = stamp_to_ns(stamp)
            map_link = levelling @ pose.matrix @ invert(OPTICAL_IN_LINK)
            if way == "tf-6dof":
                edges = [_transform(sink, TF_TOPIC, stamp_ns, MAP, LINK, map_link)]
            else:
                x, y, yaw, tilt = split_planar(map_link)
                planar = planar_matrix(x, y, yaw)
                edges = [
                    _transform(sink, TF_TOPIC, stamp_ns, MAP, BASE, planar),
                    _transform(sink, TF_TOPIC, stamp_ns, BASE, LINK, tilt),
                ]
            sink.write(tf, stamp_ns, tf_message(sink, *edges))
            depth = read_depth_png(image_path, camera.depth_scale)
            height, width = depth.shape
            scene_camera = Camera(width=width, height=height, fx=fx, fy=fy, cx=cx, cy=cy)
            image = depth_image(sink, stamp_ns, depth, scene_camera, "depth16", OPTICAL)
            sink.write(image_topic, stamp_ns, image)
            sink.write(info_topic, stamp_ns, camera_info(sink, stamp_ns, scene_camera, OPTICAL))
    return out


def _transform(
    sink: BagSink, topic: str, stamp_ns: int, parent: str, child: str, matrix: np.ndarray
) -> object:
    xyz = (float(matrix[0, 3]), float(matrix[1, 3]), float(matrix[2, 3]))
    rotation = quaternion_from_matrix(matrix[:3, :3])
    return transform_stamped(sink, topic, stamp_ns, parent, child, xyz, rotation)
