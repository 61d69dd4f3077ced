"""ROS 2 out through the services: markers of a mapped bag, and a late subscriber gets them."""

from __future__ import annotations

import time

import numpy as np
import pytest

from wallmap.common.link_settings import ZenohSettings
from wallmap.common.map_query import MapQuery
from wallmap.common.map_requests import fetch_map
from wallmap.common.transport import Keys, open_session
from wallmap.scene import write_scene_bag
from wallmap.services.mapper import ros2_out

MARKERS = "visualization_msgs/msg/MarkerArray"
PATH = "nav_msgs/msg/Path"


@pytest.mark.e2e
def test_a_mapped_bag_comes_out_as_markers_and_a_late_subscriber_gets_them(stack, tmp_path) -> None:
    scene = write_scene_bag(tmp_path / "s.bag", seed=7, n_frames=200, fmt="ros1", sensor="depth16")
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    keys = Keys(stack.prefix)
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)
    live: list[bytes] = []
    with open_session(settings) as session:  # there from the start: gets them as they change
        subscriber = session.declare_subscriber(
            keys.markers, lambda sample: live.append(sample.payload.to_bytes())
        )
        # At 4x the 200 frames take over 3 s: several map updates (every 0.5 s) while it plays.
        played = stack.run(
            "player",
            str(scene.path),
            "--rate",
            "4",
            "--wait-for",
            "detector,mapper",
            *stack.zenoh_args,
        )
        assert played.returncode == 0, played.stderr
        time.sleep(1.5)  # the markers go out with the next map update (every 0.5 s)
        subscriber.undeclare()
    assert len(live) >= 2, "published as the map grew"
    assert ros2_out.decode(live[-1], MARKERS).markers
    with open_session(settings) as session:  # comes after the map was published: late
        reply = fetch_map(session, keys, MapQuery(trajectory=True))
        got = {}
        for key, msgtype in ((keys.markers, MARKERS), (keys.trajectory, PATH)):
            for answer in session.get(key, timeout=5.0):
                if answer.ok is not None:
                    got[msgtype] = ros2_out.decode(answer.ok.payload.to_bytes(), msgtype)
    array = got[MARKERS]
    added = {m.id: m for m in array.markers if m.action == m.ADD}
    served = {w.id: w for w in reply.walls}
    assert set(added) == set(served), "one ADD marker per confirmed wall, by id"
    for wall_id, wall in served.items():
        points = np.array([(p.x, p.y) for p in added[wall_id].points])
        assert np.allclose(points, np.array(wall.segments).reshape(-1, 2), atol=1e-3)
        assert added[wall_id].header.frame_id == "map"
    assert len(got[PATH].poses) == len(reply.trajectory or ()) > 0
