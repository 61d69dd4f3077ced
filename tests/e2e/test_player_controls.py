"""Playback controls over Zenoh and the player's flags (start, duration, topics, loop), as a real
player process against a real router."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
import zenoh

from wallmap.common.codec import decode
from wallmap.common.link_settings import ZenohSettings
from wallmap.common.transport import Keys, open_session
from wallmap.scene import write_scene_bag

N_FRAMES = 60  # 4 s of bag at 15 Hz


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("playback") / "s.bag"
    write_scene_bag(path, seed=11, n_frames=N_FRAMES, fmt="ros1", sensor="depth16")
    return path


def _control(session: zenoh.Session, keys: Keys, **params: object) -> dict:
    selector = keys.player_control + "?" + ";".join(f"{k}={v}" for k, v in params.items())
    for reply in session.get(selector, timeout=5.0):
        if reply.ok is None:
            raise ValueError(reply.err.payload.to_string())
        return decode(reply.ok.payload.to_bytes())
    raise TimeoutError("no player answered")


def _until(check, timeout: float = 20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if (value := check()) is not None:
            return value
        time.sleep(0.05)
    raise TimeoutError


@pytest.mark.e2e
def test_player_is_paused_stepped_sought_and_sped_up_over_zenoh(stack, bag) -> None:
    keys = Keys(stack.prefix)
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    with open_session(settings) as session:
        progress = session.declare_subscriber(keys.player_progress, zenoh.handlers.FifoChannel(512))
        player = stack.start(
            "player",
            "player",
            str(bag),
            "--paused",
            "--wait-for",
            "detector,mapper",
            *stack.zenoh_args,
        )

        def status() -> dict | None:
            try:
                return _control(session, keys, cmd="status")
            except (TimeoutError, zenoh.ZError):
                return None

        first = _until(status)
        assert first["state"] == "paused"
        assert first["published"] == 0
        assert first["frames"] == N_FRAMES
        _control(session, keys, cmd="step")
        assert _until(lambda: (s := status()) and s["published"] == 1 and s) is not None
        time.sleep(0.5)
        assert status()["published"] == 1, "one step is one frame"
        with pytest.raises(ValueError, match="unknown cmd"):
            _control(session, keys, cmd="jump")
        with pytest.raises(ValueError, match="rate must be within"):
            _control(session, keys, cmd="rate", x=0)
        _control(session, keys, cmd="seek", t=3.0)  # the last second of the bag
        assert _control(session, keys, cmd="rate", x=4)["rate"] == 4.0
        _control(session, keys, cmd="resume")
        assert player.proc.wait(timeout=60) == 0, player.output()
        messages = []
        while (sample := progress.handler.try_recv()) is not None:
            messages.append(decode(sample.payload.to_bytes()))
    assert messages[-1]["state"] == "done"
    published = messages[-1]["published"]
    assert 1 + 10 <= published <= 1 + 20, "the step, then the last second's 15 frames"
    assert [m["published"] for m in messages] == sorted(m["published"] for m in messages)
    assert f"published {published} frames" in player.output()


@pytest.mark.e2e
def test_start_duration_topics_and_loop(stack, bag) -> None:
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    window = stack.run(
        "player", str(bag), "--fast", "--start", "1", "--duration", "2", *stack.zenoh_args
    )
    assert window.returncode == 0, window.stderr
    assert "published 30 frames" in window.stdout, window.stdout  # 2 s at 15 Hz
    wrong = stack.run(
        "player", str(bag), "--topics", "/nope", *stack.zenoh_args, timeout=30, expect=1
    )
    assert "--topics names nope, not in" in wrong.stderr
    only = stack.run(
        "player",
        str(bag),
        "--fast",
        "--duration",
        "1",
        "--topics",
        "/camera/depth/image_raw,/camera/depth/camera_info,/tf,/tf_static",
        *stack.zenoh_args,
    )
    assert only.returncode == 0, only.stderr
    looping = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "wallmap",
            "player",
            str(bag),
            "--fast",
            "--loop",
            "--duration",
            "1",
            *stack.zenoh_args,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(8)
    looping.terminate()
    out, err = looping.communicate(timeout=30)
    assert looping.returncode == 0, err
    frames = int(out.split("published ")[1].split(" frames")[0])
    assert frames > 2 * 15, "it went round more than twice"
