"""The sensor topic of a bag as ``wallmap doctor`` reports it: the player's choice, its frames.

The topic is the one the player chooses (``choose_sensor``) and its frames are decoded by the
player's own source, so the share of invalid points and the frame names are what the mapper
will see; a user checks a sensor by its size and layout, so those are reported too.
"""

from typing import Any

import numpy as np

from wallmap.doctor_facts import SensorFacts
from wallmap.services.player.bag_contents import (
    IMAGE,
    LASERSCAN,
    POINTCLOUD2,
    BagContents,
    Stamps,
)
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.bag_frames import BagFrames
from wallmap.services.player.choices import SensorChoice, choose_placement, plan_playback
from wallmap.services.player.errors import Refusal, decided
from wallmap.services.player.pose_sources import PoseSourceSpec

# Clouds and images are big: their share of invalid points is measured on the first few.
INVALID_SAMPLE = 5


def _geometry(msgtype: str, first: Any) -> dict[str, Any]:
    """The size and layout of a sensor message, the facts a user checks a sensor by."""
    if msgtype == POINTCLOUD2:
        return {
            "width": int(first.width),
            "height": int(first.height),
            "fields": [f.name for f in first.fields],
            "point_step": int(first.point_step),
        }
    if msgtype == IMAGE:
        return {"width": int(first.width), "height": int(first.height), "encoding": first.encoding}
    return {
        "beams": len(first.ranges),
        "angle_min": float(first.angle_min),
        "angle_max": float(first.angle_max),
        "angle_increment": float(first.angle_increment),
        "range_min": float(first.range_min),
        "range_max": float(first.range_max),
    }


def sensor_facts(
    bag: BagFile, contents: BagContents, sensor: SensorChoice | Refusal, requested: str | None
) -> tuple[SensorFacts, list[str]]:
    """The player's sensor decision, and its warnings when it plays with ``--pose-source none``.

    With no pose source nothing about poses or tf can refuse, so what is said here is about the
    bag itself and its sensor. The share of invalid points is measured on frames as the player
    plays them: every scan, or the first few clouds or images.

    Raises:
        PlayerError: A frame cannot be read or decoded (the player's own message).
    """
    if isinstance(sensor, Refusal):
        return SensorFacts(None, None, sensor.reason), []
    decision = "chosen with --sensor-topic" if requested else "the only usable sensor topic"
    facts = SensorFacts(sensor.topic, sensor.msgtype, decision)
    plan = decided(plan_playback(contents, sensor, PoseSourceSpec("none")))
    source = BagFrames(bag, *decided(choose_placement(plan, [])))
    limit = source.frame_count if sensor.msgtype == LASERSCAN else INVALID_SAMPLE
    invalid = total = 0
    frames = source.frames()
    try:
        for count, (frame, _) in enumerate(frames, start=1):
            invalid += int(np.count_nonzero(np.isnan(frame.points[..., 0])))
            total += frame.points[..., 0].size
            if count == limit:
                break
    finally:
        frames.close()
    facts.invalid_frames = min(limit, source.frame_count)
    facts.invalid = invalid / total if total else None
    return facts, source.warnings


def add_frames(sensor: SensorFacts, contents: BagContents, stamps: Stamps) -> None:
    """The sensor's frames: how many, their rate and frame names, and their size."""
    sensor.frames = len(stamps.stamps)
    steps = np.diff(np.sort(np.asarray(stamps.stamps)))
    steps = steps[steps > 0]
    sensor.rate_hz = round(1.0 / float(np.median(steps)), 3) if steps.size else None
    sensor.frame_ids = dict(stamps.frame_ids.most_common())
    first = contents.firsts.get(sensor.topic or "")
    if first is not None:
        sensor.geometry = _geometry(sensor.type or "", first)
