"""The sensor topic found from what a bridge or rmw_zenoh announces, or the user told why not."""

from __future__ import annotations

import json

import pytest

from wallmap.services.player.errors import PlayerError
from wallmap.services.ros2_source.discovery import (
    Announced,
    choose_sensor,
    from_bridge_routes,
    from_rmw_tokens,
)
from wallmap.services.ros2_source.settings import Ros2Settings, dds_type_name, ros_type_name

IMAGE, INFO = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo"


def _route(key: str, msgtype: str) -> bytes:
    """A zenoh-bridge-ros2dds admin-space route entry, with the fields its 1.x releases give."""
    return json.dumps(
        {
            "ros2_name": "/" + key.split("/", 1)[-1],
            "ros2_type": msgtype,
            "zenoh_key_expr": key,
            "publication_cache_size": 0,
            "dds_reader": "",
            "priority": 5,
            "remote_routes": [],
            "local_nodes": [],
        }
    ).encode()


def test_the_bridge_s_routes_of_the_namespace_are_read_and_others_skipped() -> None:
    values = [
        _route("robot1/camera/depth/image_rect_raw", IMAGE),
        _route("robot1/camera/depth/camera_info", INFO),
        _route("robot2/camera/depth/image_rect_raw", IMAGE),
        b"not json",
        b'{"ros2_type": 3}',
    ]
    found = from_bridge_routes(values, "/robot1/")
    assert found == [
        Announced("camera/depth/image_rect_raw", IMAGE),
        Announced("camera/depth/camera_info", INFO),
    ]
    assert len(from_bridge_routes(values, "")) == 3  # no namespace: every robot's topic


def test_rmw_zenoh_s_publisher_tokens_are_read_whatever_comes_before_the_topic() -> None:
    image = dds_type_name(IMAGE)
    keys = [
        f"@ros2_lv/0/aa11/0/10/MP/%/%robot1/cam/%robot1%camera%depth%image_raw/{image}/RIHS01_x/q",
        f"@ros2_lv/0/aa11/0/11/MS/%/%robot1/cam/%robot1%cmd_vel/{image}/RIHS01_x/q",  # a reader
        "@ros2_lv/0/aa11/0/NN/%/%/cam",  # a node
        f"@ros2_lv/0/bb22/7/MP/%/cam/%scan/{dds_type_name('sensor_msgs/msg/LaserScan')}/H/q",
    ]
    assert from_rmw_tokens(keys, "robot1") == [Announced("camera/depth/image_raw", IMAGE)]
    assert [a.topic for a in from_rmw_tokens(keys, "")] == ["robot1/camera/depth/image_raw", "scan"]


def test_dds_type_names_go_both_ways() -> None:
    assert dds_type_name(IMAGE) == "sensor_msgs::msg::dds_::Image_"
    assert ros_type_name(dds_type_name(IMAGE)) == IMAGE
    assert ros_type_name("RIHS01_abc") is None
    assert ros_type_name("a::b::c::D_") is None


def test_one_candidate_is_the_sensor_none_is_none_several_are_listed() -> None:
    depth = Announced("camera/depth/image_rect_raw", IMAGE)
    info = Announced("camera/depth/camera_info", INFO)
    assert choose_sensor([depth, info, depth], "here") == f"camera/depth/image_rect_raw:{IMAGE}"
    assert choose_sensor([info], "here") is None
    color = Announced("camera/color/image_raw", IMAGE)
    with pytest.raises(PlayerError, match="2 sensor topics here; choose one: --sensor camera/col"):
        choose_sensor([depth, color, info], "here")


def test_rmw_zenoh_keys_carry_domain_type_and_any_hash() -> None:
    bridge = Ros2Settings(namespace="robot1")
    rmw = Ros2Settings(namespace="robot1", rmw_zenoh=3)
    assert bridge.key("/scan", "sensor_msgs/msg/LaserScan") == "robot1/scan"
    assert rmw.key("/scan", "sensor_msgs/msg/LaserScan") == (
        "3/robot1/scan/sensor_msgs::msg::dds_::LaserScan_/*"
    )
    assert rmw.key("pose") == "3/robot1/pose/*/*"  # a pose topic: either of two types
    assert Ros2Settings(sensor="").sensor is None  # a compose file's unset variable
    with pytest.raises(ValueError, match="rmw_zenoh must be a ROS domain id"):
        Ros2Settings(rmw_zenoh=300)
