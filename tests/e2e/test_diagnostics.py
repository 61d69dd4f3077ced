"""The detector says per frame, on its diagnostics key, why it found the walls it found, or none."""

from __future__ import annotations

import time

import numpy as np
import pytest
import zenoh
from rows import wall_stub_strays

from wallmap.common.codec import decode
from wallmap.common.link_settings import ZenohSettings
from wallmap.common.messages import Frame, pack
from wallmap.common.transport import Keys, open_session


@pytest.mark.e2e
def test_detector_publishes_diagnostics_per_frame(stack) -> None:
    keys = Keys(stack.prefix)
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)
    stack.start("detector", "detector", *stack.zenoh_args)
    row = wall_stub_strays()
    points = np.column_stack([row, np.zeros(len(row))]).astype(np.float32)[None]
    with open_session(settings) as session:
        diagnostics = session.declare_subscriber(
            keys.detector_diagnostics, zenoh.handlers.FifoChannel(16)
        )
        frames = session.declare_publisher(keys.frames)
        received = None
        for seq in range(200):  # until the detector is up and listening
            frames.put(pack(Frame("diag", seq, 1.0 + seq, "camera", points, np.eye(4), "depth")))
            time.sleep(0.1)
            if (received := diagnostics.handler.try_recv()) is not None:
                break
    assert received is not None, "no diagnostics"
    message = decode(received.payload.to_bytes())
    assert message["run"] == "diag"
    assert message["sensor"] == "depth"
    assert message["walls"] == 1
    assert message["clusters"] == [150, 15, 5]
    assert message["rejected"]["cluster below min_points"] == 1
