"""Opening a bag: paths that are not bags are refused in one line that says what to do, and
rosbags is given a typestore only for a bag that carries no types of its own."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader, AnyReaderError

from wallmap.scene import Camera, write_scene_bag
from wallmap.services.player.bag_file import BagFile
from wallmap.services.player.errors import PlayerError


def test_a_folder_holding_a_bag_file_says_to_play_that_file(tmp_path: Path) -> None:
    """A ROS 2 bag's .mcap copied without its metadata.yaml: the file itself can be played."""
    (tmp_path / "run.mcap").write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(PlayerError, match=r"without metadata.yaml \(it holds run.mcap: play the"):
        BagFile(tmp_path)


def test_an_empty_folder_is_no_bag(tmp_path: Path) -> None:
    with pytest.raises(PlayerError, match=r"is a folder without metadata.yaml; expected") as err:
        BagFile(tmp_path)
    assert "it holds" not in str(err.value)


def _scene_bag(tmp_path: Path, fmt: str) -> Path:
    path = tmp_path / ("scene.bag" if fmt == "ros1" else "scene")
    write_scene_bag(
        path, seed=3, n_frames=3, fmt=fmt, sensor="depth16", camera=Camera(width=32, height=24)
    )
    return path


def test_a_ros2_bag_recorded_without_its_types_is_read_with_humbles(tmp_path: Path) -> None:
    """A bag from before Iron (no message definitions in it): its frames decode as before."""
    bag = _scene_bag(tmp_path, "ros2-sqlite3")
    for db3 in bag.glob("*.db3"):
        with sqlite3.connect(db3) as db:
            db.execute("DELETE FROM message_definitions")
    with pytest.raises(AnyReaderError, match="no type definitions"):
        AnyReader([bag]).open()  # what the bag is: unreadable without a typestore
    opened = BagFile(bag)
    assert opened.reader.default_typestore is not None
    images = [t for t in opened.topics.values() if t.msgtype == "sensor_msgs/msg/Image"]
    frames = list(opened.messages(images))
    assert len(frames) == 3
    assert frames[0][2].width == 32


@pytest.mark.parametrize("fmt", ["ros1", "ros2-mcap"])
def test_a_bag_with_its_own_types_is_read_without_building_humbles(
    tmp_path: Path, fmt: str
) -> None:
    """Humble's typestore (a tenth of a second) is built only for a bag that needs it."""
    bag = _scene_bag(tmp_path, fmt)
    probe = (
        "import sys; from wallmap.services.player.bag_file import BagFile; "
        f"bag = BagFile({str(bag)!r}); "
        "print(len(list(bag.messages(bag.topics.values()))), "
        "'rosbags.typesys.stores.ros2_humble' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout.split()
    assert int(out[0]) > 3  # the frames, tf and the rest read with the bag's own types
    assert out[1] == "False"
