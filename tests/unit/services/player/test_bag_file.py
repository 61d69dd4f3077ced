"""Paths that are not bags are refused in one line that says what to do."""

from __future__ import annotations

from pathlib import Path

import pytest

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
