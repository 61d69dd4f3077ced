"""A router and a subscriber keep no memory of the players that came and went.

With Zenoh's shared-memory transport on (its default), a router and every subscriber kept about
20 MB for each session that had sent frames above 3 kB, after the session ended: a detector and
its router grew by that much with every bag played. The player sends without it
(``common.transport``).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import Stack

from wallmap.scene import Camera, write_scene_bag

pytestmark = pytest.mark.e2e

PLAYS = 4


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no resident size for process {pid}")


def test_players_that_come_and_go_leave_the_router_and_detector_as_they_were(
    stack: Stack, tmp_path: Path
) -> None:
    bag = tmp_path / "d.bag"
    write_scene_bag(bag, seed=4, n_frames=60, fmt="ros1", sensor="depth16", camera=Camera(320, 240))
    detector = stack.start("detector", "detector", *stack.zenoh_args)
    stack.start("mapper", "mapper", *stack.zenoh_args)
    router = stack.services[0]
    sizes = []
    for _ in range(PLAYS):
        played = stack.run("player", str(bag), "--fast", *stack.zenoh_args)
        assert played.returncode == 0, played.stdout + played.stderr
        sizes.append((_rss_mb(router.proc.pid), _rss_mb(detector.proc.pid)))
    grown = [after - first for first, after in zip(sizes[0], sizes[-1], strict=True)]
    print(f"\nrouter and detector MB after each play: {sizes}")
    assert max(grown) < 15.0, f"grew {grown} MB over {PLAYS - 1} plays"
