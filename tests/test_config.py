"""One configuration: TOML in and out, --set, flags, the environment, and runs that carry it."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib

import numpy as np
import pytest
from conftest import free_port, run_wallmap

from wallmap.common import config_file
from wallmap.common.config_file import ConfigError
from wallmap.common.transport import TransportError
from wallmap.config import Config, configured, resolve, to_toml
from wallmap.offline import map_bag, walls
from wallmap.scene import write_scene_bag


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    bag = tmp_path_factory.mktemp("config") / "s.bag"
    write_scene_bag(bag, seed=8, n_frames=80, fmt="ros1", sensor="depth16")
    return bag


def _wallmap(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "wallmap", *args], capture_output=True, text=True, check=False
    )


def test_the_printed_configuration_reads_back_to_itself() -> None:
    text = to_toml(Config())
    assert config_file.from_tree(Config, tomllib.loads(text)) == Config()
    tree = tomllib.loads(text)
    assert {"zenoh", "history", "player", "detector", "mapper", "odometry", "up"} <= set(tree)
    assert tree["detector"]["ransac"]["noise_k"] == pytest.approx(1.425e-3)


def test_set_reads_values_as_toml_and_names_what_is_wrong() -> None:
    config = configured(
        "detector.seed=3",
        "player.source.pose_source=odom",
        "detector.rows.band=[1.0, 1.8]",
        "mapper.slam.enabled=true",
        "mapper.map.pose_sd=[0.01, 0.01, 0.005]",
    )
    assert config.detector.seed == 3
    assert config.player.source.pose_source == "odom"
    assert config.detector.rows.band == (1.0, 1.8)
    assert config.mapper.slam.enabled is True
    assert np.allclose(np.diag(config.mapper.map.pose_cov), [1e-4, 1e-4, 2.5e-5])
    with pytest.raises(ConfigError, match=r"unknown key 'detector\.sed' \(known here: .*seed"):
        configured("detector.sed=3")
    with pytest.raises(ConfigError, match=r"detector\.seed must be an integer"):
        configured("detector.seed=three")
    with pytest.raises(ConfigError, match=r"detector\.rows\.mode must be one of 'band', 'row'"):
        configured("detector.rows.mode=column")
    with pytest.raises(ConfigError, match=r"detector\.rows\.band must hold 2 values"):
        configured("detector.rows.band=[1.0]")
    with pytest.raises(ConfigError, match=r"expected SECTION\.KEY=VALUE"):
        configured("detector.seed")
    with pytest.raises(TransportError, match="invalid prefix"):
        configured("zenoh.prefix=a/**")


def test_precedence_file_then_environment_then_set_then_flags(tmp_path) -> None:
    file = tmp_path / "run.toml"
    file.write_text('[zenoh]\nprefix = "from-file"\n[detector]\nseed = 1\n[player]\nrate = 2.0\n')
    assert resolve(file, env={}).zenoh.prefix == "from-file"
    env = {
        "WALLMAP_PREFIX": "robot1/run2/",
        "WALLMAP_CONNECT": "tcp/10.0.0.1:7447, tcp/10.0.0.2:7447",
    }
    from_env = resolve(file, env=env)
    assert from_env.zenoh.prefix == "robot1/run2"
    assert from_env.zenoh.connect == ("tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447")
    assert resolve(file, ["zenoh.prefix=set"], env=env).zenoh.prefix == "set"
    flags = {"zenoh": {"prefix": "flag"}, "detector": {"seed": 7}}
    both = resolve(file, ["zenoh.prefix=set", "detector.seed=4"], flags, env=env)
    assert (both.zenoh.prefix, both.detector.seed, both.player.rate) == ("flag", 7, 2.0)
    assert resolve(env={}) == Config(), "nothing given: the defaults"


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


def test_a_configuration_file_reproduces_the_run(scene, tmp_path) -> None:
    """Offline, on the services' code: the map from a file equals the map from its settings."""
    settings = ("detector.seed=9", "detector.rows.band=[1.35, 2.05]", "mapper.map.merge_gap=2.0")
    file = tmp_path / "run.toml"
    file.write_text(to_toml(configured(*settings)))
    direct = walls(map_bag(scene, configured(*settings)))
    from_file = walls(map_bag(scene, resolve(file, env={})))
    default = walls(map_bag(scene))
    assert from_file == direct
    assert direct != default, "the settings change the run, so the equality means something"


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
            "up", str(scene), "--fast", "--exit-when-done", "--json-out", str(out[name]), *how,
            "--connect", f"tcp/127.0.0.1:{free_port()}", timeout=240,
        )  # fmt: skip
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
    mapper = stack.start("mapper", "mapper", "--state", str(state), "--set",
                         "mapper.map.merge_gap=2.5", *stack.zenoh_args)  # fmt: skip
    stack.start("detector", "detector", *stack.zenoh_args)
    assert stack.run("player", str(scene), "--fast", *stack.zenoh_args).returncode == 0
    assert mapper.stop() == 0
    saved = json.loads(state.read_text())
    assert saved["config"]["mapper"]["map"]["merge_gap"] == 2.5
    assert saved["config"]["mapper"]["state"] == str(state)
    assert config_file.from_tree(Config, saved["config"]).mapper.map.merge_gap == 2.5
