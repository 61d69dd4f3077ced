"""ROS 2 out: the map as MarkerArray and Path, CDR by rosbags' typestore, for RViz with no code."""

from __future__ import annotations

import numpy as np

from wallmap.common.map_records import WallRecord
from wallmap.common.ros2_types import ros2_typestore
from wallmap.services.mapper import ros2_out

MARKERS = "visualization_msgs/msg/MarkerArray"
PATH = "nav_msgs/msg/Path"


def _wall(wall_id: int, segments) -> WallRecord:
    cov = ((1e-4, 0.0), (0.0, 1e-4))
    ends = (segments[0][0], segments[-1][1])
    return WallRecord(wall_id, 0.0, 0.0, cov, *ends, segments, 5)


def test_one_line_list_marker_per_wall_with_its_segments() -> None:
    walls = [
        _wall(4, (((0.0, 0.0), (1.0, 0.0)), ((2.0, 0.0), (3.5, 0.0)))),
        _wall(9, (((1.0, 1.0), (1.0, 2.0)),)),
    ]
    array = ros2_out.decode(ros2_out.markers(walls, [], 12.25, "map"), MARKERS)
    assert [m.id for m in array.markers] == [4, 9]
    first = array.markers[0]
    assert first.ns == "walls"
    assert first.type == first.LINE_LIST
    assert first.action == first.ADD
    assert first.header.frame_id == "map"
    assert (first.header.stamp.sec, first.header.stamp.nanosec) == (12, 250_000_000)
    assert [(p.x, p.y) for p in first.points] == [(0, 0), (1, 0), (2, 0), (3.5, 0)]


def test_ids_no_longer_served_get_one_delete() -> None:
    state = ros2_out.MarkerState()
    seg = (((0.0, 0.0), (1.0, 0.0)),)
    state.payload([_wall(1, seg), _wall(2, seg)], 1.0, "map")
    merged = ros2_out.decode(state.payload([_wall(1, seg)], 2.0, "map"), MARKERS)
    actions = {(m.id, m.action) for m in merged.markers}
    delete = merged.markers[0].DELETE
    assert actions == {(1, merged.markers[0].ADD), (2, delete)}
    again = ros2_out.decode(state.payload([_wall(1, seg)], 3.0, "map"), MARKERS)
    assert [m.id for m in again.markers] == [1], "a DELETE is said once"


def test_the_path_goes_through_the_keyframes() -> None:
    path = ros2_out.decode(ros2_out.path([[1.0, 0.0, 0.0, 0.0], [2.0, 1.0, 2.0, 1.2]], 2.0), PATH)
    assert len(path.poses) == 2
    last = path.poses[1].pose
    assert (last.position.x, last.position.y) == (1.0, 2.0)
    assert abs(2 * np.arctan2(last.orientation.z, last.orientation.w) - 1.2) < 1e-9


def test_rooms_are_outlines_labels_and_doors_in_their_namespaces() -> None:
    rooms = {
        "stamp": 3.5,
        "rooms": [
            {
                "id": 2,
                "polygon": [[0, 0], [4, 0], [4, 3], [0, 3]],
                "area": 12.0,
                "centroid": [2.0, 1.5],
                "walls": [1],
                "doors": [0],
                "closed": True,
            },
        ],
        "doors": [
            {
                "id": 0,
                "center": [4.0, 1.5],
                "width": 0.9,
                "p0": [4.0, 1.05],
                "p1": [4.0, 1.95],
                "wall": 1,
                "rooms": [2],
            }
        ],
    }
    array = ros2_out.decode(ros2_out.room_markers(rooms, {"doors": [7]}, 3.5, "map"), MARKERS)
    outline, label, door, gone = array.markers
    assert (outline.ns, outline.id, outline.type) == ("rooms", 2, outline.LINE_STRIP)
    assert [(p.x, p.y) for p in outline.points] == [(0, 0), (4, 0), (4, 3), (0, 3), (0, 0)]
    assert (label.ns, label.type, label.text) == (
        "room_labels",
        label.TEXT_VIEW_FACING,
        "room 2: 12.0 m²",
    )
    assert (label.pose.position.x, label.pose.position.y) == (2.0, 1.5)
    assert (door.ns, door.id, door.type) == ("doors", 0, door.LINE_LIST)
    assert [(p.x, p.y) for p in door.points] == [(4.0, 1.05), (4.0, 1.95)]
    assert (gone.ns, gone.id, gone.action) == ("doors", 7, gone.DELETE)


def test_the_warm_up_makes_every_serializer_the_published_messages_need() -> None:
    """After it, publishing generates no code: the mapper pays that before it says ready."""
    store = ros2_typestore()
    store.cache.clear()  # the serializers other tests made
    ros2_out.warm_up()
    made = set(store.cache)
    wall = _wall(3, (((0.0, 0.0), (1.0, 0.0)),))
    ros2_out.markers([wall], [7], 1.0)
    ros2_out.path([[1.0, 0.0, 0.0, 0.0]], 1.0)
    rooms = {
        "rooms": [{"id": 1, "polygon": [[0, 0], [2, 0], [0, 2]], "area": 2.0, "centroid": [1, 1]}],
        "doors": [{"id": 2, "p0": [0, 0], "p1": [1, 0]}],
    }
    ros2_out.room_markers(rooms, {"rooms": [5]}, 1.0)
    assert set(store.cache) == made
    assert {MARKERS, PATH} <= made
