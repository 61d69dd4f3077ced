"""`wallmap view` end to end: real services, the view as a process, the page in headless Chromium.

Chromium is driven over the DevTools protocol on a pipe (``--remote-debugging-pipe``: JSON
messages ended by NUL on fds 3 and 4), so the test needs no WebSocket client and no driver. The
page lists the ids of the walls it drew in ``<ul id="drawn">`` and its draw time in
``data-render-ms`` on the canvas; the tests compare those with the mapper's own map.
"""

from __future__ import annotations

import base64
import fcntl
import importlib.util
import json
import os
import select
import shutil
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import ROOT, Service, Stack, free_port, wait_for_port

from wallmap.common.codec import MessageError
from wallmap.common.link_settings import ZenohSettings
from wallmap.common.map_query import MapQuery
from wallmap.common.map_records import MapReply, MapUpdate
from wallmap.common.map_requests import fetch_map
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.common.transport import Keys, open_session
from wallmap.scene import write_scene_bag
from wallmap.services.mapper import state_file
from wallmap.view.live import LiveMap

pytestmark = pytest.mark.e2e

WIDTH, HEIGHT = 1200, 800


# --- Chromium -----------------------------------------------------------------------------------


@pytest.fixture(scope="session")
def chromium() -> str:
    """Debian's Chromium, installed with apt-get on a fresh machine (which needs root)."""
    found = shutil.which("chromium")
    if found:
        return found
    if os.geteuid() != 0:
        pytest.skip("chromium is absent and installing it needs root: apt-get install chromium")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    install = ["apt-get", "install", "-y", "--no-install-recommends", "chromium"]
    for attempt in ([install], [["apt-get", "update"], install]):  # the lists may be stale
        for cmd in attempt:
            done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
            if done.returncode != 0:
                break
        found = shutil.which("chromium")
        if found:
            return found
    pytest.skip(f"cannot install chromium with apt-get: {done.stderr.strip()[-300:]}")


# Puts the pipe ends where Chromium looks for them (fds 3 and 4), then becomes Chromium.
PIPE_TRAMPOLINE = (
    "import os, sys; os.dup2(int(sys.argv[1]), 3); os.dup2(int(sys.argv[2]), 4);"
    " os.close(int(sys.argv[1])); os.close(int(sys.argv[2])); os.execv(sys.argv[3], sys.argv[3:])"
)


def _high_fd(fd: int) -> int:
    """The same pipe end on a descriptor above 4, so placing one on 3 or 4 cannot clobber it."""
    high = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return high


class Browser:
    """One headless Chromium page, driven over the DevTools protocol on a pipe."""

    def __init__(self, chromium: str, profile: Path, log: Path) -> None:
        commands_in, self._commands = map(_high_fd, os.pipe())
        self._events, events_out = map(_high_fd, os.pipe())
        flags = [
            "--headless=new",
            "--disable-gpu",
            "--no-sandbox",
            "--remote-debugging-pipe",
            f"--user-data-dir={profile}",
            f"--window-size={WIDTH},{HEIGHT}",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "about:blank",
        ]
        fds = (str(commands_in), str(events_out))
        self.proc = subprocess.Popen(
            [sys.executable, "-c", PIPE_TRAMPOLINE, *fds, chromium, *flags],
            pass_fds=(commands_in, events_out),
            stdout=log.open("wb"),
            stderr=subprocess.STDOUT,
        )
        os.close(commands_in)
        os.close(events_out)
        self._buffer = b""
        self._id = 0
        self._session: str | None = None
        self.errors: list[str] = []  # exceptions and console errors of the page
        target = self.call("Target.createTarget", url="about:blank")["targetId"]
        self._session = self.call("Target.attachToTarget", targetId=target, flatten=True)[
            "sessionId"
        ]
        self.call("Runtime.enable")
        self.call("Page.enable")
        self.call(
            "Emulation.setDeviceMetricsOverride",
            width=WIDTH,
            height=HEIGHT,
            deviceScaleFactor=1,
            mobile=False,
        )

    def call(self, method: str, timeout: float = 30.0, **params: Any) -> dict[str, Any]:
        self._id += 1
        message: dict[str, Any] = {"id": self._id, "method": method, "params": params}
        if self._session and not method.startswith("Target."):
            message["sessionId"] = self._session
        os.write(self._commands, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            reply = self._read(deadline)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]
            self._note(reply)

    def _read(self, deadline: float) -> dict[str, Any]:
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._events], [], [], left)[0]:
                raise TimeoutError("Chromium did not answer in time")
            chunk = os.read(self._events, 1 << 20)
            if not chunk:
                raise RuntimeError(f"Chromium exited ({self.proc.poll()})")
            self._buffer += chunk
        message, _, self._buffer = self._buffer.partition(b"\0")
        return json.loads(message)

    def _note(self, event: dict[str, Any]) -> None:
        params = event.get("params", {})
        if event.get("method") == "Runtime.exceptionThrown":
            details = params["exceptionDetails"]
            self.errors.append(details.get("exception", {}).get("description", details["text"]))
        elif event.get("method") == "Runtime.consoleAPICalled" and params["type"] == "error":
            self.errors.append(" ".join(str(a.get("value")) for a in params["args"]))

    def evaluate(self, expression: str) -> Any:
        result = self.call(
            "Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True
        )
        if "exceptionDetails" in result:
            raise AssertionError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout: float = 20.0) -> Any:
        deadline = time.monotonic() + timeout
        while not (value := self.evaluate(expression)):
            assert time.monotonic() < deadline, f"timed out waiting for {expression}"
            time.sleep(0.1)
        return value

    def next_frame(self) -> dict[str, Any]:
        """Wait for the page's next two animation frames; then its canvas's data attributes."""
        return self.evaluate(
            "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))"
            ".then(() => ({...document.getElementById('map').dataset}))"
        )

    def mouse(self, kind: str, x: float, y: float, **extra: Any) -> None:
        self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, **extra)

    def close(self) -> None:
        try:
            self.call("Browser.close", timeout=5.0)
            self.proc.wait(timeout=10)
        except (OSError, RuntimeError, TimeoutError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        os.close(self._commands)
        os.close(self._events)


@pytest.fixture
def browser(chromium: str, tmp_path: Path) -> Iterator[Browser]:
    page = Browser(chromium, tmp_path / "chromium-profile", tmp_path / "chromium.log")
    try:
        yield page
    finally:
        page.close()


# --- the view ------------------------------------------------------------------------------------


def start_view(stack: Stack) -> str:
    """``wallmap view`` as a process against the stack's router; returns the page's URL."""
    port = free_port()
    log = stack.tmp_path / "view.log"
    proc = subprocess.Popen(
        [sys.executable, "-m", "wallmap", "view", "--port", str(port), *stack.zenoh_args],
        stdout=log.open("wb"),
        stderr=subprocess.STDOUT,
    )
    stack.services.append(Service("view", proc, log))  # stopped with the stack
    wait_for_port(port)
    return f"http://127.0.0.1:{port}/"


def get(url: str) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status, response.headers["Content-Type"], response.read()
    except urllib.error.HTTPError as err:
        return err.code, err.headers["Content-Type"], err.read()


def drawn(browser: Browser) -> dict[int, bool]:
    """The walls the page drew: id -> tentative."""
    items = browser.evaluate(
        "[...document.querySelectorAll('#drawn li')]"
        ".map(li => [Number(li.dataset.id), li.dataset.tentative === 'true'])"
    )
    return dict(items)


def wait_for_walls(browser: Browser, served: dict[int, bool], timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while (shown := drawn(browser)) != served:
        missing, extra = sorted(set(served) - set(shown)), sorted(set(shown) - set(served))
        flags = [i for i in served if shown.get(i, served[i]) != served[i]]
        assert time.monotonic() < deadline, (
            f"drawn {len(shown)} walls, served {len(served)}: missing {missing[:10]}, "
            f"extra {extra[:10]}, tentative flag differs {flags[:10]}"
        )
        time.sleep(0.2)


def screen_point(browser: Browser, x: float, y: float) -> tuple[float, float]:
    """Where the map-frame point (x, y) is on the screen, from the transform the page reports."""
    view = browser.evaluate(
        "(() => { const c = document.getElementById('map'), r = c.getBoundingClientRect();"
        " return {...c.dataset, left: r.left, top: r.top}; })()"
    )
    scale = float(view["scale"])
    return view["left"] + float(view["ox"]) + x * scale, view["top"] + float(view["oy"]) - y * scale


def hover_longest_wall(browser: Browser, walls: list[dict[str, Any]]) -> tuple[dict, str]:
    """Hover the middle of the longest segment of the longest confirmed wall: its tooltip."""
    wall = max(
        (w for w in walls if not w["tentative"]),
        key=lambda w: np.hypot(*np.subtract(w["p1"], w["p0"])),
    )
    a, b = max(wall["segments"], key=lambda s: np.hypot(*np.subtract(s[1], s[0])))
    browser.mouse("mouseMoved", *screen_point(browser, (a[0] + b[0]) / 2, (a[1] + b[1]) / 2))
    tip = browser.wait_for(
        "(t => !t.hidden && t.textContent)(document.getElementById('tip'))", timeout=5
    )
    return wall, tip


def check_screenshot(browser: Browser, path: Path) -> dict[str, int]:
    """Save a PNG of the page and count, by decoding it in the browser, the colours it holds."""
    data = browser.call("Page.captureScreenshot", format="png")["data"]
    path.write_bytes(base64.b64decode(data))
    png = path.read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    assert int.from_bytes(png[16:20], "big") == WIDTH
    return browser.evaluate(
        f"""(async () => {{
          const img = new Image();
          img.src = "data:image/png;base64,{data}";
          await img.decode();
          const c = new OffscreenCanvas(img.width, img.height), g = c.getContext("2d");
          g.drawImage(img, 0, 0);
          const px = g.getImageData(0, 0, img.width, img.height).data, seen = new Set();
          let red = 0, blue = 0;
          for (let i = 0; i < px.length; i += 4) {{
            seen.add((px[i] << 16) | (px[i + 1] << 8) | px[i + 2]);
            if (px[i] === 0xb3 && px[i + 1] === 0x26 && px[i + 2] === 0x1e) red++;
            if (px[i] === 0x2b && px[i + 1] === 0x6c && px[i + 2] === 0xb0) blue++;
          }}
          return {{colours: seen.size, wall_pixels: red, trajectory_pixels: blue}};
        }})()"""
    )


# --- tests -------------------------------------------------------------------------------------


def test_page_draws_the_live_map_of_a_played_scene(stack, browser, tmp_path):
    bag = tmp_path / "s.bag"
    scene = write_scene_bag(bag, seed=11, n_frames=150, fmt="ros1", sensor="depth16")
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    url = start_view(stack)
    browser.call("Page.navigate", url=url)

    # While the bag plays, the page follows the map and the API the detector's newest walls.
    player = stack.start("player", "player", str(bag), "--fast", *stack.zenoh_args)
    counts, observed = set(), 0
    while player.proc.poll() is None:
        counts.add(len(drawn(browser)))
        latest = json.loads(get(url + "api/latest")[2])["observations"]
        observed += bool(latest and latest["walls"])
        time.sleep(0.1)
    assert player.proc.returncode == 0, player.output()
    reply = stack.query("--tentative")
    served = {w["id"]: w["tentative"] for w in reply["walls"]}
    assert len(served) >= 3
    wait_for_walls(browser, served)
    assert observed > 0
    browser.wait_for("document.getElementById('status').textContent === 'live'")

    # The API: the same walls as JSON, the newest pose and observations, errors as JSON.
    settings = ZenohSettings(connect=(stack.endpoint,), prefix=stack.prefix)
    with open_session(settings) as session:
        query = MapQuery(trajectory=True)
        keyframes = fetch_map(session, Keys(stack.prefix), query).trajectory or ()
        trajectory = [list(p) for p in keyframes]
    deadline = time.monotonic() + 10  # the view re-reads the trajectory every 2 s
    while True:
        status, kind, body = get(url + "api/map")
        api = json.loads(body)
        if api["trajectory"] == trajectory or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    assert (status, kind) == (200, "application/json")
    assert api["full"]
    assert {w["id"] for w in api["walls"]} == set(served)
    assert api["trajectory"] == trajectory
    status, kind, body = get(url + f"api/map?since={api['version']}")
    assert status == 200
    assert json.loads(body)["walls"] == []  # nothing changed since
    status, kind, body = get(url + "api/latest")
    latest = json.loads(body)
    assert (status, kind) == (200, "application/json")
    assert latest["status"] is None
    assert latest["pose"]["stamp"] == pytest.approx(trajectory[-1][0], abs=1.0)
    assert latest["observations"]["seq"] == scene.n_frames - 1  # the last frame
    # The player sends poses ahead of its frames: the newest is at or past the last frame, which
    # is placed with the pose at its own stamp.
    assert latest["pose"]["stamp"] >= latest["observations"]["stamp"]
    assert latest["observations"]["pose"]["stamp"] == latest["observations"]["stamp"]
    for path in ("nothing", "api/nothing", "../pyproject.toml"):
        status, kind, body = get(url + path)
        assert (status, kind) == (404, "application/json"), path
        assert "error" in json.loads(body)
    assert get(url + "api/map?since=x")[0] == 400

    wall, tip = hover_longest_wall(browser, reply["walls"])
    assert tip.startswith(f"wall {wall['id']}\n"), tip
    assert f"u      {wall['u']:.3f} m" in tip
    assert f"n_obs  {wall['n_obs']} " in tip
    check = check_screenshot(browser, tmp_path / "view.png")
    print(f"screenshot {tmp_path / 'view.png'}: {check}")
    assert check["colours"] > 20
    assert check["wall_pixels"] > 500
    assert check["trajectory_pixels"] > 50
    assert browser.errors == []


def test_page_fills_the_rooms_and_tells_a_rooms_numbers_on_hover(stack, browser, tmp_path):
    """A strip of three rooms: the page draws the mapper's rooms and doors, and hovering a room
    shows its id, area, walls and doors."""
    bag = tmp_path / "strip.bag"
    write_scene_bag(bag, seed=1, n_frames=900, fmt="ros1", sensor="depth16")
    stack.start("mapper", "mapper", *stack.zenoh_args)
    stack.start("detector", "detector", *stack.zenoh_args)
    url = start_view(stack)
    browser.call("Page.navigate", url=url)
    stack.run("player", str(bag), "--fast", *stack.zenoh_args)
    browser.wait_for(
        "document.getElementById('summary').textContent.includes('3 rooms, 2 doors')", timeout=20
    )
    # The rooms follow the map about once a second: the last update after the bag may reach
    # the page after a query. The page must come to show the mapper's room as it is served.
    deadline = time.monotonic() + 15
    while True:
        served = json.loads(stack.run("query", "--rooms", "--json", *stack.zenoh_args).stdout)
        assert len(served["rooms"]) == 3
        room = max(served["rooms"], key=lambda r: r["area"])
        browser.mouse("mouseMoved", *screen_point(browser, *room["centroid"]))
        tip = browser.wait_for(
            "(t => !t.hidden && t.textContent)(document.getElementById('tip'))", timeout=5
        )
        if f"area   {room['area']:.2f} m²" in tip or time.monotonic() > deadline:
            break
        browser.mouse("mouseMoved", 1, 1)
        time.sleep(1.0)
    assert tip.startswith(f"room {room['id']}"), tip
    assert f"area   {room['area']:.2f} m²" in tip
    assert tip.count("door ") == len(room["doors"])
    assert browser.errors == []


def build_big_map(n_walls: int) -> Any:
    """benchmarks/mapper_scaling.py's grid of rooms, as benchmarks/query_latency.py uses it."""
    spec = importlib.util.spec_from_file_location(
        "mapper_scaling", ROOT / "benchmarks" / "mapper_scaling.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.build(n_walls, np.random.default_rng(0))


def test_thousands_of_walls_draw_fast_and_pan_and_zoom(stack, browser, tmp_path):
    state = tmp_path / "map.json"
    state_file.write(state, state_file.to_json(build_big_map(2000)))
    stack.start("mapper", "mapper", "--state", str(state), *stack.zenoh_args)
    url = start_view(stack)
    browser.call("Page.navigate", url=url)
    browser.wait_for("document.querySelectorAll('#drawn li').length > 0", timeout=30)
    reply = stack.query("--tentative")  # the mapper is up: the page has its walls
    served = {w["id"]: w["tentative"] for w in reply["walls"]}
    assert len(served) > 1900
    wait_for_walls(browser, served)
    wall, tip = hover_longest_wall(browser, reply["walls"])
    assert tip.startswith(f"wall {wall['id']}\n"), tip

    # Zoom in about the centre and back out, then pan: each is one frame, timed by the page.
    centre = (WIDTH / 2, HEIGHT / 2)
    frame = browser.next_frame()
    scale, ox = float(frame["scale"]), float(frame["ox"])
    times = []
    for delta_y in (-600, -300, 300, 600, None):
        before = int(frame["frames"])
        begin = time.perf_counter()
        if delta_y is None:
            browser.mouse("mousePressed", *centre, button="left", buttons=1, clickCount=1)
            browser.mouse("mouseMoved", centre[0] + 120, centre[1] + 40, button="left", buttons=1)
            browser.mouse("mouseReleased", centre[0] + 120, centre[1] + 40, button="left")
        else:
            browser.mouse("mouseWheel", *centre, deltaX=0, deltaY=delta_y)
        frame = browser.next_frame()
        waited = (time.perf_counter() - begin) * 1e3
        assert int(frame["frames"]) == before + 1
        times.append((float(frame["renderMs"]), float(frame["frameMs"])))
        print(f"{delta_y or 'drag'}: drawn {times[-1]} ms, seen by the test after {waited:.0f} ms")
        if delta_y == 600:
            assert float(frame["scale"]) == pytest.approx(scale, rel=1e-6)  # in and back out
    assert float(frame["ox"]) == pytest.approx(ox + 120)
    print(f"draw and frame times at {len(served)} walls (ms): {times}")
    assert max(frame_ms for _, frame_ms in times) < 200
    assert browser.errors == []


def test_user_errors_end_in_one_line(tmp_path):
    router = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = subprocess.run(
            [sys.executable, "-m", "wallmap", "view", "--port", str(port), "--connect", router],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        )
    assert out.returncode == 1
    assert out.stderr.strip() == (
        f"wallmap view: error: cannot serve on 127.0.0.1:{port}: Address already in use"
        " (check another --port)"
    )
    out = subprocess.run(
        [sys.executable, "-m", "wallmap", "view", "--port", "0", "--connect", router],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert out.returncode == 1
    assert out.stderr.startswith(f"wallmap view: error: cannot reach a Zenoh router at {router}")
    assert len(out.stderr.strip().splitlines()) == 1


# --- the state behind the API, without processes -----------------------------------------------


def wall(wall_id: int, y: float, n_obs: int = 3) -> dict[str, Any]:
    return {
        "id": wall_id,
        "u": 0.0,
        "v": y,
        "cov": [[1e-4, 0.0], [0.0, 1e-4]],
        "p0": [-1.0, y],
        "p1": [1.0, y],
        "segments": [[[-1.0, y], [1.0, y]]],
        "n_obs": n_obs,
        "n_views": 2,
        "tentative": False,
    }


def reply(frames: int, walls: list[dict], trajectory: list) -> MapReply:
    body = {"frames": frames, "observations": 3 * frames, "walls": walls}
    return MapReply.from_map({**body, "trajectory": trajectory})


def update(frames: int, walls: list[dict], removed: list[int]) -> MapUpdate:
    return MapUpdate.from_map({"frames": frames, "walls": walls, "removed": removed})


def test_api_sends_only_what_changed_and_skips_stale_updates():
    live = LiveMap()
    live.replace(reply(10, [wall(1, 1.0), wall(2, 2.0)], []))
    first = live.delta(0)
    assert first["full"]
    assert [w["id"] for w in first["walls"]] == [1, 2]
    assert live.apply_update(update(12, [wall(2, 2.1)], [1]))
    changed = live.delta(first["version"])
    assert not changed["full"]
    assert [w["v"] for w in changed["walls"]] == [2.1]
    assert changed["removed"] == [1]
    assert "trajectory" not in changed  # unchanged
    # An update taken before the last full reply would put old walls back: it is skipped.
    live.replace(reply(20, [wall(2, 2.2)], [[0.0, 0, 0, 0]]))
    assert not live.apply_update(update(15, [wall(2, 2.1)], []))
    now = live.delta(changed["version"])
    assert [w["v"] for w in now["walls"]] == [2.2]
    assert now["trajectory"] == [[0.0, 0.0, 0.0, 0.0]]
    assert live.delta(now["version"])["walls"] == []
    assert live.delta(now["version"] + 5)["full"]  # a version from another run of the view
    with pytest.raises(MessageError, match="finite"):  # refused before it reaches the map
        update(30, [{**wall(3, 1.0), "u": float("nan")}], [])
    assert live.delta(0)["walls"] == now["walls"]


def test_api_sends_the_rooms_when_they_change():
    live = LiveMap()
    first = live.delta(0)
    assert first["rooms"] == {"rooms": [], "doors": []}
    body = {"v": 1, "rooms": [{"id": 4, "polygon": [[0, 0], [1, 0], [1, 1]]}], "doors": []}
    live.set_rooms(body)
    changed = live.delta(first["version"])
    assert changed["rooms"]["rooms"][0]["id"] == 4
    live.set_rooms(body)  # the same again: nothing new
    assert "rooms" not in live.delta(changed["version"])


def test_latest_observations_are_placed_with_the_pose_at_their_stamp():
    live = LiveMap()
    for stamp, x in ((1.0, 0.0), (2.0, 5.0), (3.0, 9.0)):
        live.add_pose(Pose(stamp, x, 0.0, np.pi / 2))
    ends = np.array([2.0, -1.0]), np.array([2.0, 1.0])
    seen = WallObservation(np.array([2.0, 0.0]), np.eye(2) * 1e-4, *ends, 50, 0.01)
    live.set_observations(Observations("run", 7, 2.25, "base_link", [seen]))
    latest = live.latest()
    assert latest["pose"]["x"] == 9.0  # the newest
    assert latest["recent"] == [[0.0, 0.0], [5.0, 0.0], [9.0, 0.0]]  # no trajectory yet
    assert latest["observations"]["pose"]["x"] == 6.0  # interpolated at the frame's stamp
    placed = latest["observations"]["walls"][0]
    np.testing.assert_allclose(placed["p0"], [7.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(placed["p1"], [5.0, 2.0], atol=1e-12)
