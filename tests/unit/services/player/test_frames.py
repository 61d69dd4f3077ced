"""A player's frame as it goes on the wire: the same whoever sends it."""

from __future__ import annotations

import numpy as np

from wallmap.common.messages import pack, unpack_frame
from wallmap.common.scan_row import RowSelection
from wallmap.services.player.frames import SensorFrame, hand_out
from wallmap.services.player.placement import unlevelled


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


def _message(rows: int) -> np.ndarray:
    """A cloud's bytes as a source reads them: read-only, with a partial return in row 0."""
    points = np.zeros((rows, 8, 3), dtype=np.float32)
    points[..., 2] = 2.0  # 2 m ahead of a sensor looking along z
    points[..., 1] = np.linspace(-1.5, 0.5, rows)[:, None]  # its heights, down the image
    points[0, 3, 1] = np.nan  # y lost, x and z kept: a driver's partial return
    points[0, 5, 0] = np.inf
    points.flags.writeable = False
    return points


def test_a_row_is_handed_out_as_the_callers_own_with_partial_points_blanked() -> None:
    """Every source (a bag, a TUM folder, a live ROS 2 topic) gets the same points from it."""
    message = _message(1)
    for rows in (None, RowSelection()):
        points, band = hand_out(
            lambda wanted: message[wanted], 1, rows, np.eye(4), unlevelled("base_link")
        )
        assert band is None
        assert points.dtype == np.float32
        assert points.base is None  # not a view over the message
        expected = np.array(message)
        expected[0, [3, 5]] = np.nan
        np.testing.assert_array_equal(points, expected)
    assert np.isfinite(message[0, 3, [0, 2]]).all(), "the message itself is left as it was"


def test_a_band_stack_is_handed_out_as_it_was_picked() -> None:
    message = _message(64)
    mount = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0.6], [0, 0, 0, 1.0]])
    points, band = hand_out(
        lambda wanted: message[wanted], 64, RowSelection(), mount, unlevelled("base_link")
    )
    assert band is not None
    assert points.shape[0] > 1
    finite = np.isfinite(points)
    assert finite.all(axis=-1).any()
    np.testing.assert_array_equal(finite.all(axis=-1), finite.any(axis=-1))
