"""The compiled loops: compiled once, for the arrays every frame brings; numba loaded lazily."""

import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from test_band_kernels import MOUNT, cluttered_stack

from wallmap.common import band_kernels, line_kernels, map_kernels, pose_kernels, room_kernels
from wallmap.common.compiled import compile_all
from wallmap.common.map_records import WallRecord
from wallmap.common.messages import Frame, Observations, Pose, WallObservation, pack, unpack_frame
from wallmap.offline import run_bag
from wallmap.scene import Camera, write_scene_bag
from wallmap.scene.floorplan import free_rays, generate_floorplan
from wallmap.services.detector.detector import DetectorConfig, WallDetector
from wallmap.services.mapper.room_map import RoomMap
from wallmap.services.mapper.wall_map import WallMap


def kernels() -> dict[str, object]:
    return {
        f"{module.__name__}.{name}": value
        for module in (line_kernels, band_kernels, room_kernels, pose_kernels, map_kernels)
        for name, value in vars(module).items()
        if hasattr(value, "signatures")
    }


def test_a_frame_from_the_wire_runs_the_loops_compiled_at_install() -> None:
    """A decoded frame's arrays are read-only: were they handed on as they are, numba would
    compile every loop again for them, seconds in the middle of a run."""
    compile_all()
    before = {name: list(k.signatures) for name, k in kernels().items()}
    assert all(len(s) <= 1 for s in before.values()), before  # helpers: inlined, none
    detector = WallDetector(DetectorConfig())
    for seq in range(5):
        stack = cluttered_stack(np.random.default_rng(seq), width=160)
        sent = Frame("run", seq, 0.1 * seq, "camera", stack, MOUNT, band=(1.3, 2.1))
        frame = unpack_frame(pack(sent))
        assert not frame.points.flags.writeable
        assert detector.detect(frame).walls, "the wall 3 m ahead is seen"
    after = {name: list(k.signatures) for name, k in kernels().items()}
    assert after == before


def test_a_rooms_update_runs_the_loops_compiled_at_install() -> None:
    """Wall ends are views into the map's segments, not contiguous: handed on as they are,
    numba would compile a loop again for them in the mapper's first rooms update."""
    compile_all()
    before = {name: list(k.signatures) for name, k in kernels().items()}
    plan = generate_floorplan(500)
    records = tuple(
        WallRecord(w.id, 0.0, 0.0, ((1e-4, 0.0), (0.0, 1e-4)), w.p0, w.p1, ((w.p0, w.p1),), 10)
        for w in plan.walls
    )
    rooms = RoomMap()
    for at in plan.route:
        rooms.add_frame(np.array([*at, 0.0]), np.zeros(2), free_rays(plan, np.array(at)))
    assert rooms.update(records, 0.0).rooms, "the plan's rooms are found"
    after = {name: list(k.signatures) for name, k in kernels().items()}
    assert after == before


def test_judged_poses_run_the_loops_compiled_at_install(tmp_path: Path) -> None:
    """The pose judge's and the map's loops get the map's and the frame's arrays as they are."""
    compile_all()
    before = {name: list(k.signatures) for name, k in kernels().items()}
    bag = tmp_path / "depth.bag"
    camera = Camera(width=160, height=120)
    write_scene_bag(bag, seed=3, n_frames=120, fmt="ros1", sensor="depth16", camera=camera)
    judge = run_bag(bag).mapping.judge
    assert judge is not None
    assert judge.counts.judged > 50
    after = {name: list(k.signatures) for name, k in kernels().items()}
    assert after == before


def test_the_configuration_does_not_load_numba() -> None:
    """Every wallmap command reads the configuration; numba's 0.2 s is the detector's alone."""
    code = "import sys, wallmap.config, wallmap.cli; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_band_stack_is_picked_before_numba_is_loaded() -> None:
    """A player's first frames do not wait for numba's 0.3 s: numpy picks them meanwhile."""
    code = (
        "import sys, numpy as np; from wallmap.common import scan_row; "
        "points = np.random.default_rng(1).normal(0, 1, (20, 30, 3)).astype(np.float32); "
        "stack = scan_row.band_stack(points, np.eye(4), (0.0, 1.0)); "
        "print(stack.shape, np.isfinite(stack).any(), 'numba' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(6, 30, 3) True False"


def test_a_pose_in_whole_numbers_runs_the_map_s_loops_compiled_at_install() -> None:
    """A pose given in ints (a caller's ``Pose(t, 0, 0, 0)``) is an int array to numpy."""
    compile_all()
    before = {name: list(k.signatures) for name, k in kernels().items()}
    seen = WallObservation(
        closest=np.array([2.0, 0.0]),
        cov=np.eye(2) * 1e-3,
        p0=np.array([2.0, -1.0]),
        p1=np.array([2.0, 1.0]),
        n_points=100,
        rms=0.01,
    )
    wall_map = WallMap()
    for seq in range(3):
        frame = Observations("run", seq, float(seq), "base_link", [seen], False, np.zeros(2))
        frame = replace(frame, rays=np.array([[3.0, 0.5], [1.0, -0.2]]))
        assert wall_map.integrate(frame, Pose(float(seq), 0, 0, 0)) == [0]
    after = {name: list(k.signatures) for name, k in kernels().items()}
    assert after == before


LOOP = """
from numba import njit


@njit(cache=True)
def twice(x):
    return 2 * x


def warm_up():
    twice(1.0)
"""

READY = """
import importlib, sys
sys.path.insert(0, sys.argv[1])
from wallmap.common.compiled import make_ready
print(make_ready(importlib.import_module("tiny_loop")).compiled)
"""


def test_a_loop_is_said_compiled_once_then_loaded_from_the_cache(tmp_path: Path) -> None:
    """The services say "compiled" only when numba compiled: a slow load from its cache on a
    busy machine is not a compile, and saying so on every start sends users looking for a
    broken cache."""
    (tmp_path / "tiny_loop.py").write_text(LOOP)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    runs = [
        subprocess.run(
            [sys.executable, "-c", READY, str(tmp_path)],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        ).stdout.strip()
        for _ in range(2)
    ]
    assert runs == ["1", "0"]
