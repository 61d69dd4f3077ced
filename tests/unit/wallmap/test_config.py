"""One configuration: TOML in and out, --set, the environment, precedence, a file that gives the
same map again (offline, on the services' code)."""

from __future__ import annotations

import argparse
import tomllib

import numpy as np
import pytest

from wallmap.cli import ALL, build_parser
from wallmap.common import config_file
from wallmap.common.config_file import ConfigError
from wallmap.common.link_settings import TransportError
from wallmap.config import Config, configured, resolve, to_toml
from wallmap.offline import map_bag, walls


@pytest.fixture(scope="module")
def scene(scene_bags):
    return scene_bags("config.bag", seed=8, n_frames=80, fmt="ros1", sensor="depth16").path


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


def test_every_key_a_flag_sets_wallmap_config_takes_too() -> None:
    """`wallmap config` prints the configuration "with every flag": each key some command's flag
    sets has a flag there (ros2.pose_source and ros2.whole_clouds share the player's flags'
    names, so only --set reaches them there)."""
    taken = {option.key for group in ALL for option in group}
    commands = next(
        a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)
    ).choices
    keys = {o.key for p in commands.values() for o in p.get_default("options") or ()}
    assert keys - taken == {"ros2.pose_source", "ros2.whole_clouds"}
