"""End to end, this checkout against an earlier commit, interleaved in one run.

Each recording goes through `wallmap player --fast` into a detector and a mapper (separate
processes, a real router on a free loopback port), once with this checkout's code and once with
the commit's (a `git worktree` in a temporary folder, run by the same Python), round after round.
Printed per tree: the player's seconds for the whole recording and each process's CPU seconds
(start-up included), medians over the rounds; and the ratio to the commit, the median of the
ratios of each round's two neighbouring runs, so a machine that slows down between rounds does
not tilt it. What a change to the frame path costs is read here, before and after.

    .venv/bin/python benchmarks/versus.py --base d3ac257 [--rounds 5] [--jackal]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from wallmap.launcher import free_loopback_port
from wallmap.scene import Camera, write_scene_bag

ROOT = Path(__file__).resolve().parents[1]
JACKAL = ROOT.parent / "shared" / "data" / "real" / "jackal_arena_2026-02-17-15-54-31"
MOCAP = ("--pose-source", "pose:/vrpn_client_node/jackal/pose")
PROCESSES = ("player", "detector", "mapper", "router")


@contextmanager
def worktree(commit: str) -> Iterator[Path]:
    """The commit's code in a temporary folder, prepared as ``make`` prepares a checkout.

    Its compiled loops and bytecode are built first, as ``make`` builds them: a fresh tree's
    services would compile them at their first start, tens of seconds, and a ``--fast`` player
    gives up waiting for them. Removed afterwards.
    """
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tree"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), commit],
            check=True,
            capture_output=True,
        )
        prepare = (
            ["-c", "from wallmap.common.compiled import compile_all; compile_all()"],
            ["-m", "compileall", "-q", "wallmap", "common", "services"],
        )
        for step in prepare:
            subprocess.run(
                [sys.executable, *step],
                cwd=path,
                env={**os.environ, "PYTHONPATH": str(path)},
                check=True,
                capture_output=True,
            )
        try:
            yield path
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(path)],
                check=False,
                capture_output=True,
            )


def _cpu(proc: subprocess.Popen[str]) -> float:
    """Wait for ``proc``; its CPU seconds (user and system)."""
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return usage.ru_utime + usage.ru_stime


def run_once(
    tree: Path, bag: Path, player_args: tuple[str, ...], odometry: bool = False
) -> dict[str, float]:
    """One recording through the services of ``tree``: seconds and CPU seconds per process.

    ``odometry``: an odometry service makes the poses from the scans.
    """
    env = {**os.environ, "PYTHONPATH": str(tree), "WALLMAP_LOG": "WARNING"}
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    wallmap = [sys.executable, "-m", "wallmap"]
    quiet = {"env": env, "cwd": tempfile.gettempdir(), "stderr": subprocess.DEVNULL}
    names = ("router", "mapper", "detector", *(("odometry",) if odometry else ()))
    services = [subprocess.Popen([*wallmap, "router", "--listen", endpoint], **quiet)]
    services += [
        subprocess.Popen([*wallmap, name, "--connect", endpoint], **quiet) for name in names[1:]
    ]
    play = [*wallmap, "player", str(bag), "--fast", "--connect", endpoint, *player_args]
    if odometry:
        play += ["--pose-source", "none", "--wait-for", ",".join(names[1:])]
    player = subprocess.Popen(play, stdout=subprocess.PIPE, text=True, **quiet)
    out = player.stdout.read() if player.stdout else ""
    result = {"player": _cpu(player)}
    for name, proc in reversed(list(zip(names, services, strict=True))):
        proc.terminate()  # the services first, while their router is there
        result[name] = _cpu(proc)
    found = re.search(r"in ([\d.]+) s .* integrated (\d+)", out)
    if player.returncode or found is None:
        raise SystemExit(f"{tree}: the player failed on {bag}:\n{out}")
    result["seconds"], result["frames"] = float(found[1]), int(found[2])
    return result


def recordings(folder: Path, jackal: bool) -> dict[str, tuple[Path, tuple[str, ...]]]:
    """The generated bags, and the Jackal's run where asked and present."""
    depth, cloud = folder / "depth.bag", folder / "cloud.bag"
    write_scene_bag(
        depth,
        seed=3,
        n_frames=400,
        fmt="ros1",
        sensor="depth16",
        camera=Camera(width=320, height=240),
        rate_hz=15.0,
    )
    write_scene_bag(
        cloud,
        seed=7,
        n_frames=90,
        fmt="ros1",
        sensor="pointcloud",
        camera=Camera(width=640, height=480),
        rate_hz=30.0,
    )
    found = {"320x240 depth, 15 Hz, 400": (depth, ()), "640x480 cloud, 30 Hz, 90": (cloud, ())}
    if jackal and JACKAL.exists():
        found["Jackal, motion capture, 414"] = (JACKAL, MOCAP)
    elif jackal:
        print(f"(the Jackal skipped: {JACKAL} is absent)")
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the commit to compare with")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--jackal", action="store_true", help="the real Jackal run too")
    args = parser.parse_args()
    commit = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", args.base],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp, worktree(commit) as base:
        trees = {commit: base, "this checkout": ROOT}
        bags = recordings(Path(tmp), args.jackal)
        runs: dict[tuple[str, str], list[dict[str, float]]] = {}
        for _ in range(args.rounds):
            for label, (bag, extra) in bags.items():
                for name, tree in trees.items():
                    runs.setdefault((label, name), []).append(run_once(tree, bag, extra))
    print(f"medians of {args.rounds} rounds; CPU seconds include each process's start-up")
    print(
        f"{'recording':<28} {'code':<14} {'seconds':>8} "
        + " ".join(f"{p:>8}" for p in PROCESSES)
        + f" {'vs ' + commit:>12}"
    )
    for (label, name), done in runs.items():
        before = runs[(label, commit)]
        pairs = zip(done, before, strict=True)
        ratio = statistics.median(a["seconds"] / b["seconds"] for a, b in pairs)
        cells = " ".join(f"{statistics.median(r[p] for r in done):>8.2f}" for p in PROCESSES)
        seconds = statistics.median(r["seconds"] for r in done)
        print(f"{label:<28} {name:<14} {seconds:>8.2f} {cells} {ratio:>11.2f}x")


if __name__ == "__main__":
    main()
