"""The configuration in real runs: bad files in one line, `wallmap config` back into `--config`,
`wallmap up` with a file as with its flags, the state file saying how its map was made."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib

import pytest
from conftest import free_port, run_wallmap

from wallmap.common import config_file
from wallmap.config import Config


@pytest.fixture(scope="module")
def scene(scene_bags):
    return scene_bags("config.bag", seed=8, n_frames=80, fmt="ros1", sensor="depth16").path


def _wallmap(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "wallmap", *args], capture_output=True, text=True, check=False
    )


def test_bad_files_are_one_line_and_exit_1(tmp_path) -> None:
    missing = _wallmap("config", "--config", str(tmp_path / "nope.toml"))
    broken = tmp_path / "broken.toml"
    broken.write_text("[detector\nseed = 1\n")
    unreadable = _wallmap("config", "--config", str(broken))
    typo = _wallmap("config", "--set", "mapper.map.merge_gapp=2")
    for done in (missing, unreadable, typo):
        assert done.returncode == 1
        assert "Traceback" not in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "cannot read the configuration" in missing.stderr
    assert "is not TOML" in unreadable.stderr
    assert "unknown key 'mapper.map.merge_gapp'" in typo.stderr


def test_wallmap_config_takes_every_flag_and_prints_it(tmp_path) -> None:
    done = _wallmap("config", "--band", "1.2,2.0", "--slam", "--fast", "--set", "detector.seed=5")
    assert done.returncode == 0, done.stderr
    tree = tomllib.loads(done.stdout)
    assert tree["detector"]["rows"]["band"] == [1.2, 2.0]
    assert tree["mapper"]["slam"]["enabled"] is True
    assert tree["player"]["fast"] is True
    assert tree["detector"]["seed"] == 5
    file = tmp_path / "run.toml"
    file.write_text(done.stdout)
    again = _wallmap("config", "--config", str(file))
    assert again.stdout == done.stdout, "a printed file gives the same configuration back"


@pytest.mark.e2e
def test_up_with_a_file_is_the_run_with_its_flags_and_writes_it_out(scene, tmp_path) -> None:
    """Real processes: `wallmap up` with flags, and again with the file `wallmap config` wrote."""
    flags = ("--band", "1.35,2.05", "--set", "detector.seed=9", "--set", "mapper.map.merge_gap=2.0")
    file = tmp_path / "run.toml"
    file.write_text(_wallmap("config", *flags).stdout)
    out = {}
    for name, how in (("flags", flags), ("file", ("--config", str(file)))):
        out[name] = tmp_path / f"{name}.json"
        run_wallmap(
            "up",
            str(scene),
            "--fast",
            "--exit-when-done",
            "--json-out",
            str(out[name]),
            *how,
            "--connect",
            f"tcp/127.0.0.1:{free_port()}",
            timeout=240,
        )
    by_flags, by_file = (json.loads(out[n].read_text()) for n in ("flags", "file"))
    assert by_flags["walls"] == by_file["walls"]
    assert by_flags["frames"] == by_file["frames"] > 0
    written = by_file["config"]
    assert written["detector"]["seed"] == 9
    assert written["detector"]["rows"]["band"] == [1.35, 2.05]
    assert written["player"]["wait_for"] == ["detector", "mapper"]
    run_only = ("zenoh", "up")  # the port and the JSON file differ between the two runs
    assert {k: v for k, v in by_flags["config"].items() if k not in run_only} == {
        k: v for k, v in written.items() if k not in run_only
    }


@pytest.mark.e2e
def test_the_state_file_says_how_its_map_was_made(stack, scene, tmp_path) -> None:
    state = tmp_path / "map.json"
    mapper = stack.start(
        "mapper",
        "mapper",
        "--state",
        str(state),
        "--set",
        "mapper.map.merge_gap=2.5",
        *stack.zenoh_args,
    )
    stack.start("detector", "detector", *stack.zenoh_args)
    assert stack.run("player", str(scene), "--fast", *stack.zenoh_args).returncode == 0
    assert mapper.stop() == 0
    saved = json.loads(state.read_text())
    assert saved["config"]["mapper"]["map"]["merge_gap"] == 2.5
    assert saved["config"]["mapper"]["state"] == str(state)
    assert config_file.from_tree(Config, saved["config"]).mapper.map.merge_gap == 2.5
