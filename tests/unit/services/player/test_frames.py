"""A player's frame as it goes on the wire: the same whoever sends it."""

from __future__ import annotations

import numpy as np

from wallmap.common.messages import pack, unpack_frame
from wallmap.services.player.frames import SensorFrame


def test_a_sensor_frame_goes_on_the_wire_with_all_it_carries() -> None:
    points = np.arange(2 * 4 * 3, dtype=np.float32).reshape(2, 4, 3)
    mount = np.eye(4)
    mount[:3, 3] = (0.1, 0.0, 0.4)
    frame = SensorFrame(12.5, "laser", points, mount, bag_time=3.0, band=(1.3, 2.1), sweep=0.05)
    sent = unpack_frame(pack(frame.to_frame(run="r1", seq=7, sensor="scan", lossless=True)))
    assert (sent.run, sent.seq, sent.stamp, sent.frame_id) == ("r1", 7, 12.5, "laser")
    assert (sent.sensor, sent.lossless, sent.band, sent.sweep) == ("scan", True, (1.3, 2.1), 0.05)
    np.testing.assert_array_equal(sent.points, points)
    np.testing.assert_array_equal(sent.T_base_sensor, mount)


def test_a_frame_is_not_lossless_unless_asked() -> None:
    frame = SensorFrame(1.0, "camera", np.zeros((1, 2, 3), np.float32), np.eye(4))
    wire = frame.to_frame(run="r", seq=0, sensor="depth")
    assert not wire.lossless
    assert wire.band is None
    assert wire.sweep == 0.0
