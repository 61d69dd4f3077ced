"""The odometry service as a process: the mapper's poses from the scans, and its flags' errors."""

from __future__ import annotations

from wallmap.evaluation import evaluate_map

N_FRAMES = 300  # conftest.odometry_scene's frames


def test_odometry_service_gives_the_mapper_its_poses(stack, odometry_scene) -> None:
    """Player without poses, the odometry service as the pose source: the map is right.

    Played a second time into the same services, the bag is a new run: the odometry starts
    afresh (its first scan is older than the last one it matched) and the map stays right.
    """
    bag, plan, trajectory, seen = odometry_scene
    x, y, yaw = trajectory.pose_at(0)
    for service, *extra in (
        ("mapper",),
        ("detector",),
        ("odometry", f"--initial-pose={x},{y},{yaw}"),
    ):
        stack.start(service, service, *extra, *stack.zenoh_args)
    for run in (1, 2):
        played = stack.run(
            "player",
            str(bag),
            "--fast",
            "--pose-source",
            "none",
            "--wait-for",
            "detector,mapper,odometry",
            *stack.zenoh_args,
        )
        assert played.returncode == 0, played.stderr
        assert f"published {N_FRAMES} frames and 0 poses" in played.stdout
        reply = stack.query("--min-obs", "3")
        assert reply["frames"] == run * N_FRAMES
        score = evaluate_map(reply["walls"], plan, seen)
        print(f"\nrun {run}: {score.summary()}")
        assert score.precision >= 0.9  # 16 of 17 here, as in one process
        assert score.recall >= 0.95
        assert score.duplicates == 0
        assert score.median_offset_m < 0.02
    odometry = next(s for s in stack.services if s.name == "odometry").output()
    assert "not matched" not in odometry
    assert "scan matching starts afresh" in odometry


def test_odometry_takes_whole_depth_clouds_by_the_detectors_rows(stack, scene_bags) -> None:
    """`player --whole-clouds`: the odometry cuts each depth frame to its scan row as the
    detector does (its ``--rows``). It was handed the history window as the row choice, and
    its worker died on the first frame (``'HistorySettings' object has no attribute 'band'``),
    and ``--history`` was never its own."""
    info = scene_bags("odometry-depth.bag", seed=607, n_frames=60, fmt="ros1", sensor="depth16")
    for service in ("mapper", "detector", "odometry"):
        stack.start(service, service, "--history", "5", *stack.zenoh_args)
    played = stack.run(
        "player",
        str(info.path),
        "--fast",
        "--whole-clouds",
        "--pose-source",
        "none",
        "--wait-for",
        "detector,mapper,odometry",
        *stack.zenoh_args,
    )
    assert played.returncode == 0, played.stderr
    assert stack.query()["frames"] == 60
    assert stack.counters("odometry")["published"] == 60


def test_odometry_command_line_errors(stack) -> None:
    bad = stack.run("odometry", "--initial-pose", "1,2", *stack.zenoh_args, timeout=30, expect=2)
    assert "expected X,Y,YAW" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    clash = stack.run(
        "up",
        "missing.bag",
        "--odometry",
        "--pose-source",
        "odom",
        *stack.zenoh_args,
        timeout=30,
        expect=None,
    )
    assert clash.returncode != 0
    assert "--odometry estimates the poses itself" in clash.stderr
