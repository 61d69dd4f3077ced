"""Zenoh settings: the json5 file first, the settings over it, multicast off unless asked."""

from __future__ import annotations

from wallmap.common.link_settings import ZenohSettings
from wallmap.common.transport import make_config


def test_config_file_first_flags_over_it_multicast_off_unless_asked(tmp_path):
    plain = make_config(ZenohSettings(connect=("tcp/127.0.0.1:9",)))
    assert plain.get_json("scouting/multicast/enabled") == "false"
    assert plain.get_json("connect/endpoints") == '["tcp/127.0.0.1:9"]'
    file = tmp_path / "z.json5"
    file.write_text(
        "{ connect: { endpoints: ['tcp/127.0.0.1:1'] }, adminspace: { enabled: true } }"
    )
    conf = make_config(ZenohSettings(connect=("tcp/127.0.0.1:9",), config_file=file))
    assert conf.get_json("adminspace/enabled") == "true"
    assert conf.get_json("connect/endpoints") == '["tcp/127.0.0.1:9"]'
    assert conf.get_json("scouting/multicast/enabled") == "false"
    file.write_text("{ scouting: { multicast: { enabled: true } } }")
    asked = make_config(ZenohSettings(config_file=file))
    assert asked.get_json("scouting/multicast/enabled") == "true"
    waiting = make_config(ZenohSettings(wait_for_router=float("inf")))
    assert waiting.get_json("connect/timeout_ms") == "-1"


def test_a_session_that_comes_and_goes_sends_without_shared_memory_unless_its_file_asks(tmp_path):
    assert make_config(ZenohSettings()).get_json("transport/shared_memory/enabled") == "true"
    passing = make_config(ZenohSettings(), shared_memory=False)
    assert passing.get_json("transport/shared_memory/enabled") == "false"
    file = tmp_path / "z.json5"
    file.write_text("{ transport: { shared_memory: { enabled: true } } }")
    asked = make_config(ZenohSettings(config_file=file), shared_memory=False)
    assert asked.get_json("transport/shared_memory/enabled") == "true"
    file.write_text("{ adminspace: { enabled: true } }")
    other = make_config(ZenohSettings(config_file=file), shared_memory=False)
    assert other.get_json("transport/shared_memory/enabled") == "false"
