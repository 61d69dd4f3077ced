"""Handheld recordings through the services: `wallmap up` on a TUM folder, and a broken one."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest
from conftest import free_port, run_wallmap
from handheld_scenes import TUM, score
from PIL import Image

from wallmap.services.player.tum_folder import read_depth_png


@pytest.mark.e2e
def test_up_plays_a_tum_folder_through_the_services(handheld_recordings, tmp_path):
    info = handheld_recordings["tum"]
    out = tmp_path / "map.json"
    fx, fy, cx, cy = TUM.player.source.intrinsics
    done = run_wallmap(
        "up",
        str(info.path),
        "--fast",
        "--exit-when-done",
        "--json-out",
        str(out),
        "--intrinsics",
        f"{fx},{fy},{cx},{cy}",
        "--depth-scale",
        "1000",
        "--connect",
        f"tcp/127.0.0.1:{free_port()}",
        timeout=240,
    )
    reply = json.loads(out.read_text())
    assert reply["frames"] == info.n_frames
    assert score(info, reply["walls"]).recall >= 0.9
    assert re.search(r"\d+ walls? from", done.stdout)


def test_a_broken_tum_folder_is_one_line(handheld_recordings, tmp_path):
    good = handheld_recordings["tum"].path
    broken = tmp_path / "broken"
    shutil.copytree(good, broken)
    (broken / "depth.txt").write_text("1.0 depth/a.png\nnot-a-stamp depth/b.png\n")
    out = run_wallmap("player", str(broken), "--connect", "tcp/127.0.0.1:1", expect=1)
    assert out.stderr.strip().splitlines() == [
        f"wallmap player: error: {broken / 'depth.txt'} line 2: expected 'timestamp filename', "
        "got 'not-a-stamp depth/b.png'"
    ]
    first = sorted((good / "depth").iterdir())[0]
    eight_bit = broken / "depth" / "eight.png"
    Image.fromarray(np.zeros((4, 4), np.uint8)).save(eight_bit)
    (broken / "depth.txt").write_text(f"1.0 depth/eight.png\n2.0 depth/{first.name}\n")
    out = run_wallmap("player", str(broken), "--connect", "tcp/127.0.0.1:1", expect=1)
    assert "not a 16-bit grayscale depth map" in out.stderr
    (broken / "groundtruth.txt").unlink()
    (broken / "depth.txt").write_text(f"1.0 depth/{first.name}\n")
    out = run_wallmap("player", str(broken), "--connect", "tcp/127.0.0.1:1", expect=1)
    assert "groundtruth.txt not found" in out.stderr
    assert read_depth_png(first, 1000).dtype == np.float32
