"""The docs' shell blocks marked runnable run as written, in a fresh folder, as a reader would.

A reader copies a block from the README or docs/ into a terminal. Every fenced block whose info
string is ``sh runnable`` is run by bash, the blocks of one page one after the other in one
shell, top to bottom, in a folder holding what the docs assume the reader has: ``my.bag`` (a
generated scene). The commands a block puts in the background (the services) are stopped as a
supervisor would (SIGTERM, the last started first) once the page's last block ends, and each
must exit 0; the page must end with status 0; nothing may print a traceback; and what the
page says it makes exists.

The blocks use the default endpoint, 127.0.0.1:7447, as written: nothing else in the tests does.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, assert_clean_exit, run_wallmap

RUNNABLE = re.compile(r"^```sh runnable\n(.*?)^```", re.DOTALL | re.MULTILINE)
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

# Stops what the page left running, the last started first (the router, started first, last),
# and fails the page if any of it did not exit 0.
EPILOGUE = """
finish() {
  code=$?
  for pid in $(jobs -p | tac); do
    kill -TERM "$pid" 2>/dev/null || true
    wait "$pid" || { echo "docs: a background command exited $?" >&2; code=1; }
  done
  exit "$code"
}
trap finish EXIT
"""

# What each page's blocks leave in the folder (files), and say (a pattern of their output).
MADE = {
    "README.md": (["map.json", "map.png", "map.geojson"], r"published \d+ frames"),
    "configuration.md": (["run.toml", "map.json"], r"\d+ walls"),
    "doctor.md": ([], r"verdict\s+ready"),
    "fleet.md": (["fleet.png"], r"\d+ walls from \d+ frames"),
    "rooms.md": (["rooms.json", "map.png", "map.geojson"], r"\d+ rooms?, \d+ doors?"),
    "view.md": ([], r"wallmap view: http://127\.0\.0\.1:8766/"),
}


TIMEOUT = 120  # s: every page takes seconds


def runnable_blocks(page: Path) -> list[str]:
    """The page's ``sh runnable`` blocks, in order."""
    return RUNNABLE.findall(page.read_text(encoding="utf-8"))


def test_the_pages_that_promise_runnable_blocks_have_them() -> None:
    marked = {page.name for page in PAGES if runnable_blocks(page)}
    assert marked == set(MADE), "a page gained or lost its runnable blocks: update MADE"


@pytest.fixture(scope="module")
def my_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reader's bag: a short generated scene (4 s at 15 Hz, real time in the view's page)."""
    folder = tmp_path_factory.mktemp("bag")
    run_wallmap("scene", str(folder / "my.bag"), "--frames", "60", timeout=300)
    return folder / "my.bag"


def _processes_in_group(group: int) -> list[str]:
    """The command lines of the processes in a process group (what a page left running)."""
    ps = ["ps", "-e", "-o", "pgid=,args="]
    listed = subprocess.run(ps, capture_output=True, text=True, check=False).stdout
    return [
        line.split(None, 1)[1]
        for line in listed.splitlines()
        if line.split() and line.split()[0] == str(group)
    ]


def _default_endpoint_free() -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", 7447))
        except OSError:
            return False
    return True


@pytest.mark.parametrize("name", sorted(MADE))
def test_a_page_s_runnable_blocks_run_as_written(name: str, my_bag: Path, tmp_path: Path) -> None:
    if not _default_endpoint_free():
        pytest.skip("127.0.0.1:7447, the endpoint the docs use, is taken on this machine")
    page = next(p for p in PAGES if p.name == name)
    (tmp_path / "my.bag").symlink_to(my_bag)
    script = tmp_path / "page.sh"
    script.write_text(EPILOGUE + "set -e -o pipefail\n" + "\n".join(runnable_blocks(page)))
    env = {k: v for k, v in os.environ.items() if not k.startswith("WALLMAP_")}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    log = tmp_path / "page.log"
    with log.open("wb") as out:
        shell = subprocess.Popen(
            ["bash", str(script)],
            cwd=tmp_path,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        try:
            code = shell.wait(timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            left = _processes_in_group(shell.pid)
            os.killpg(shell.pid, signal.SIGKILL)
            shell.wait()
            pytest.fail(
                f"{name}'s blocks did not end in {TIMEOUT} s; still running: {left}\n"
                f"{log.read_text()[-4000:]}"
            )
    output = log.read_text(errors="replace")
    assert_clean_exit(f"{name}'s runnable blocks", code, output)
    files, said = MADE[name]
    for made in files:
        assert (tmp_path / made).is_file(), f"{name} promises {made}:\n{output[-4000:]}"
    assert re.search(said, output), f"{name}'s blocks did not say /{said}/:\n{output[-4000:]}"
