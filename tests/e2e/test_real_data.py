"""Real scan-only recordings, mapped end to end with `wallmap odometry` as the pose source.

These bags carry no poses and no ground truth, so the test checks what the data can tell: scans
integrated, scan points (placed with the published poses) lying on mapped walls, no wall mapped
twice, and the corridor of hallway.bag as two long parallel walls. Real services, a real router.
"""

from __future__ import annotations

import numpy as np
import pytest
import zenoh
from conftest import real_bag

from wallmap.common.link_settings import ZenohSettings
from wallmap.common.map_consistency import (
    MappedWall,
    angle_between,
    distance_to_walls,
    duplicates,
)
from wallmap.common.messages import unpack_pose
from wallmap.common.se2 import transform_points
from wallmap.common.transport import Keys, open_session
from wallmap.offline import scan_rows

pytestmark = pytest.mark.e2e

CORRIDOR = {"hallway.bag": True, "eng403_good.bag": False}


PACES = [(name, "--fast") for name in sorted(CORRIDOR)] + [("eng403_good.bag", "--rate=4")]


@pytest.mark.parametrize(("name", "pace"), PACES)
def test_scan_only_bag_maps_with_scan_matching(stack, name: str, pace: str) -> None:
    """``pace``: as fast as the services go, or timed as recorded (4x), as a live robot is."""
    bag = real_bag(name)
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)
    with open_session(settings) as session:
        poses_sub = session.declare_subscriber(
            Keys(stack.prefix).pose, zenoh.handlers.FifoChannel(8192)
        )
        for service in ("mapper", "detector", "odometry"):
            stack.start(service, service, *stack.zenoh_args)
        played = stack.run(
            "player",
            str(bag),
            pace,
            "--pose-source",
            "none",
            "--wait-for",
            "detector,mapper,odometry",
            *stack.zenoh_args,
        )
        assert played.returncode == 0, played.stderr
        poses = {}
        while (sample := poses_sub.handler.try_recv()) is not None:
            pose = unpack_pose(sample.payload.to_bytes())
            poses[pose.stamp] = (pose.x, pose.y, pose.yaw)
    reply = stack.query()
    walls = [MappedWall.from_reply(w) for w in reply["walls"]]
    scans = list(scan_rows(bag))

    assert reply["frames"] >= 0.95 * len(scans), "scans integrated"
    assert len(poses) == len(scans), "one pose per scan"
    distances = np.concatenate(
        [distance_to_walls(transform_points(xy, poses[stamp]), walls) for stamp, xy in scans]
    )
    on_walls = float(np.mean(distances <= 0.05))
    print(f"{name}: {len(walls)} walls, {on_walls:.1%} of scan points within 5 cm of one")
    assert on_walls >= 0.6
    assert duplicates(walls, max_angle_deg=3.0, max_offset=0.10) == []
    if CORRIDOR[name]:
        first, second = sorted(walls, key=lambda w: -w.length)[:2]
        assert min(first.length, second.length) >= 11.0, "the corridor's walls come out whole"
        assert angle_between(first, second) <= 2.0, "and parallel"
