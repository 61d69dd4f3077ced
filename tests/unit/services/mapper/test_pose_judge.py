"""Poses as real sources give them (late, noisy, glitching), judged against the walls.

Generated scenes whose every pose source carries the faults (``wallmap.scene.PoseFaults``),
mapped in one process as the services map them (``wallmap.offline``), scored against the
scene's truth.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import replace as replaced

import numpy as np
import pytest

from wallmap.common import se2
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.config import configured
from wallmap.evaluation import evaluate_map
from wallmap.offline import run_bag, walls
from wallmap.scene import Glitch, PoseFaults
from wallmap.scene.bags import tum_path_for
from wallmap.services.mapper import restore, state_file
from wallmap.services.mapper.pose_buffer import PoseBuffer, SourcePose
from wallmap.services.mapper.pose_judge import JudgeConfig, PoseJudge
from wallmap.services.mapper.settings import MapperSettings
from wallmap.services.mapper.wall_map import WallMap

GLITCH = Glitch(start=15.0, duration=3.0, yaw_deg=12.0, offset_m=0.1)
FAULTS = PoseFaults(latency=0.08, heading_sd_deg=0.5, glitches=(GLITCH,), seed=3)


@pytest.fixture(scope="module")
def faulty(scene_bags):
    """A depth camera's scene, its poses 80 ms late, 0.5 deg noisy, 3 s 12 deg and 10 cm off."""
    return scene_bags(
        "faulty-depth.bag", seed=3, n_frames=600, fmt="ros1", sensor="depth16", faults=FAULTS
    )


def _spec(info, source: str) -> str:
    return f"tum:{tum_path_for(info.path)}" if source == "tum" else source


@pytest.mark.parametrize("source", ["tf", "pose:/ground_truth", "pose:/amcl_pose", "tum"])
def test_late_noisy_glitching_poses_map_one_wall_a_surface(faulty, source: str) -> None:
    pipeline = run_bag(
        faulty.path, configured(f"player.source.pose_source={_spec(faulty, source)}")
    )
    score = evaluate_map(walls(pipeline.map, 3), faulty.plan, faulty.seen_counts)
    found = pipeline.mapping.judge.summary()
    print(f"\n{source}: {score.summary()}; {found}")
    assert pipeline.map.frames == faulty.n_frames  # every frame taken
    assert score.precision >= 0.98
    assert score.recall >= 0.95
    assert score.duplicates == 0
    assert score.median_offset_m <= 0.015
    assert found["latency_s"] == pytest.approx(FAULTS.latency, abs=0.01)
    assert found["frames_recovered"] > 0  # the glitch was seen and placed by the walls


def test_taken_as_they_come_the_same_poses_do_not(faulty) -> None:
    """The bar above is the judge's: without it, the same bag maps worse (``--trust-poses``)."""
    spec = _spec(faulty, "tum")
    judged = run_bag(faulty.path, configured(f"player.source.pose_source={spec}"))
    trusted = run_bag(
        faulty.path, configured(f"player.source.pose_source={spec}", "mapper.judge.enabled=false")
    )
    assert trusted.mapping.judge is None
    as_given = evaluate_map(walls(trusted.map, 3), faulty.plan, faulty.seen_counts)
    judged_score = evaluate_map(walls(judged.map, 3), faulty.plan, faulty.seen_counts)
    print(f"\ntrusted: {as_given.summary()}\njudged: {judged_score.summary()}")
    assert as_given.precision < judged_score.precision - 0.1
    assert as_given.median_offset_m > 3 * judged_score.median_offset_m


@pytest.mark.parametrize("latency", [0.03, 0.15])
def test_the_latency_is_estimated_within_10_ms(scene_bags, latency: float) -> None:
    faults = PoseFaults(latency=latency, heading_sd_deg=0.3, seed=5)
    info = scene_bags(
        f"late-{latency}.bag", seed=5, n_frames=450, fmt="ros1", sensor="laserscan", faults=faults
    )
    pipeline = run_bag(info.path, configured(f"player.source.pose_source={_spec(info, 'tum')}"))
    found = pipeline.mapping.judge.summary()
    score = evaluate_map(walls(pipeline.map, 3), info.plan, info.seen_counts)
    print(f"\n{latency}: {score.summary()}; {found}")
    assert found["settled"]
    assert found["latency_s"] == pytest.approx(latency, abs=0.01)
    assert score.precision >= 0.98
    assert score.recall >= 0.95
    assert score.duplicates == 0


def test_a_given_latency_is_used_not_estimated(faulty) -> None:
    spec = _spec(faulty, "tum")
    pipeline = run_bag(
        faulty.path,
        configured(f"player.source.pose_source={spec}", "mapper.judge.latency=0.08"),
        frames=100,
    )
    found = pipeline.mapping.judge.summary()
    assert found["latency_fixed"]
    assert found["latency_s"] == 0.08
    assert pipeline.mapping.source_stamp(100.0) == pytest.approx(100.08)


# --- one judge, one room: a glitch placed, a contradiction refused --------------------------

ROOM = [
    ((-3.0, -2.0), (3.0, -2.0)),
    ((3.0, -2.0), (3.0, 2.0)),
    ((3.0, 2.0), (-3.0, 2.0)),
    ((-3.0, 2.0), (-3.0, -2.0)),
]


def _seen(pose: np.ndarray, walls_seen=ROOM) -> list[WallObservation]:
    """Every wall of the room seen from ``pose``, exactly, as the detector reports it."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    out = []
    for a, b in walls_seen:
        p0, p1 = np.array(a), np.array(b)
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        foot = p0 + ((np.array([x, y]) - p0) @ d) * d
        ends = (np.array([p0, p1]) - [x, y]) @ rot
        out.append(
            WallObservation(rot.T @ (foot - [x, y]), np.eye(2) * 1e-5, ends[0], ends[1], 200, 0.003)
        )
    return out


def _frame(stamp: float, pose: np.ndarray, walls_seen=ROOM) -> Observations:
    return Observations(
        "r", int(stamp * 10), stamp, "base_link", _seen(pose, walls_seen), sensor="scan"
    )


def _source(stamp: float, pose: np.ndarray) -> SourcePose:
    return SourcePose(Pose(stamp, *map(float, pose)), np.zeros(3), 0.0)


def _mapped_room() -> tuple[PoseJudge, WallMap, list[np.ndarray]]:
    """A judge and the room mapped by it from exact poses, turning on the spot."""
    judge, wall_map = PoseJudge(JudgeConfig(latency=0.0)), WallMap()
    poses = [np.array([0.2 * math.cos(k / 5), 0.3 * math.sin(k / 7), 0.1 * k]) for k in range(60)]
    for k, pose in enumerate(poses):
        verdict = judge.judge(_frame(k * 0.1, pose), _source(k * 0.1, pose), wall_map, None)
        wall_map.integrate(_frame(k * 0.1, pose), verdict.pose)
    return judge, wall_map, poses


def test_a_tracker_that_jumps_15_degrees_is_placed_where_the_walls_say() -> None:
    judge, wall_map, poses = _mapped_room()
    true = np.array([0.1, -0.1, poses[-1][2] + 0.1])
    wrong = true + np.array([0.15, -0.1, math.radians(15.0)])
    verdict = judge.judge(_frame(6.1, true), _source(6.1, wrong), wall_map, None)
    assert verdict.kind == "recovered"
    assert not verdict.start_walls  # a pose the source got wrong starts no wall
    assert verdict.pose is not None
    error = verdict.pose.vector - true
    error[2] = se2.wrap(float(error[2]))
    np.testing.assert_allclose(error, 0.0, atol=2e-3)
    assert judge.counts.recovered == 1


def test_walls_that_say_nothing_clear_refuse_the_frame() -> None:
    """A jump, and one wall in view: where along it the frame was, the walls cannot say."""
    judge, wall_map, poses = _mapped_room()
    true = np.array([0.0, 0.0, poses[-1][2] + 0.1])
    wrong = true + np.array([0.3, 0.2, math.radians(15.0)])
    verdict = judge.judge(_frame(6.1, true, ROOM[:1]), _source(6.1, wrong), wall_map, None)
    assert verdict.kind == "refused"
    assert verdict.pose is None
    assert judge.counts.refused == 1


def test_the_judge_goes_on_from_its_state_file_entry_exactly() -> None:
    """Restored from the JSON of a state file, it judges the next frames as the original does:
    a mapper restarted on its state re-takes the frames since the save and must map them the
    same (same walls, same ids)."""
    judge, wall_map = PoseJudge(JudgeConfig()), WallMap()  # the latency estimated too
    poses = PoseBuffer()
    track = [
        np.array([0.2 * math.cos(k / 5), 0.3 * math.sin(k / 7), 0.1 * k + 0.02 * math.sin(k)])
        for k in range(120)
    ]
    for k, pose in enumerate(track):
        poses.add(Pose(k * 0.1, *map(float, pose)))
    for k, pose in enumerate(track[:80]):
        verdict = judge.judge(_frame(k * 0.1, pose), _source(k * 0.1, pose), wall_map, poses)
        wall_map.integrate(_frame(k * 0.1, pose), verdict.pose)
    again = PoseJudge.from_json(json.loads(json.dumps(judge.to_json())), judge.config)
    assert again.summary() == judge.summary()
    for k, pose in enumerate(track[80:], start=80):
        noisy = pose + np.array([0.01, -0.01, math.radians(1.0)]) * math.sin(k)
        mine = judge.judge(_frame(k * 0.1, pose), _source(k * 0.1, noisy), wall_map, poses)
        theirs = again.judge(_frame(k * 0.1, pose), _source(k * 0.1, noisy), wall_map, poses)
        assert mine.kind == theirs.kind
        assert mine.pose == theirs.pose or np.array_equal(mine.pose.vector, theirs.pose.vector)
    assert again.to_json() == judge.to_json()
    with pytest.raises(ValueError, match="finite"):
        PoseJudge.from_json({**judge.to_json(), "latency": float("nan")}, judge.config)


def test_a_mapper_restored_on_a_state_file_takes_its_judge_or_says_why_not(tmp_path) -> None:
    """The judge a state file kept is the one a restarted mapper goes on with; a damaged entry
    is one readable line, not a traceback."""
    judge, _, _ = _mapped_room()
    state = tmp_path / "map.json"
    state.write_text(json.dumps({"poses": judge.to_json()}))
    settings = replaced(MapperSettings(), state=state, judge=judge.config)
    assert restore.judge_of(settings).summary() == judge.summary()
    state.write_text(json.dumps({"poses": {**judge.to_json(), "offset": [1.0]}}))
    with pytest.raises(state_file.StateError, match="unusable 'poses' entry"):
        restore.judge_of(settings)


def test_after_the_source_jumps_a_frame_no_wall_can_check_starts_none_for_a_while() -> None:
    """One frame fitted to a wrong pose may clear the doubt; the frames after it, seeing only a
    new wall, would start a turned copy of it. Five seconds on, the source is taken again."""
    judge, wall_map, poses = _mapped_room()
    true = np.array([0.0, 0.0, poses[-1][2] + 0.1])
    wrong = true + np.array([0.0, 0.0, math.radians(15.0)])
    judge.judge(_frame(6.1, true), _source(6.1, wrong), wall_map, None)
    assert judge.jumped == 6.1
    far = [((20.0, -5.0), (20.0, 5.0))]  # a wall far from every mapped one
    soon = judge.judge(_frame(6.2, true, far), _source(6.2, true), wall_map, None)
    later = judge.judge(_frame(11.3, true, far), _source(11.3, true), wall_map, None)
    assert (soon.kind, soon.start_walls) == ("unjudged", False)
    assert (later.kind, later.start_walls) == ("unjudged", True)


def test_a_source_ahead_of_the_frames_by_more_or_less_is_judged_the_same() -> None:
    """How many poses have come beyond a frame's is a matter of timing (how far ahead of the
    frames the source runs): a run judged with all of them sent at once, and with each sent
    only just in time, gives the same latency and the same poses."""
    rate, late = 20.0, 0.05
    stamps = np.arange(0.0, 20.0, 1.0 / rate)
    turn = 0.4 * np.sin(stamps / 1.3) + 0.2 * np.sin(stamps * 1.7)

    def truth(t: float) -> np.ndarray:
        return np.array([0.1 * math.cos(t), 0.1 * math.sin(t), float(np.interp(t, stamps, turn))])

    sent = [Pose(t + late, *map(float, truth(t))) for t in np.arange(-1.0, 21.0, 0.01)]
    ahead, in_time = PoseBuffer(), PoseBuffer()
    for pose in sent:
        ahead.add(pose)
    judges = PoseJudge(JudgeConfig()), PoseJudge(JudgeConfig())
    maps = WallMap(), WallMap()
    waiting = iter(sent)
    for t in map(float, stamps):
        frame = _frame(t, truth(t))
        while not isinstance(in_time.sample(judges[1].source_stamp(t)), SourcePose):
            in_time.add(next(waiting))  # the pose after the frame's has just come
        verdicts = []
        for judge, wall_map, buffer in zip(judges, maps, (ahead, in_time), strict=True):
            source = buffer.sample(judge.source_stamp(t))
            assert isinstance(source, SourcePose)
            verdicts.append(judge.judge(frame, source, wall_map, buffer))
            wall_map.integrate(frame, verdicts[-1].pose)
        assert judges[0].summary() == judges[1].summary()
        assert np.array_equal(verdicts[0].pose.vector, verdicts[1].pose.vector)
    assert judges[0].settled
    assert judges[0].latency == pytest.approx(late, abs=0.01)


STEP_DEG = 15.0


def test_a_source_wrong_by_less_than_its_jitter_shows_is_placed_by_the_walls() -> None:
    """No jump: the source's poses jitter by a degree, so a 15-degree step is not one.

    The walls still say clearly where the frame was; and, the source caught wrong, a frame
    that no settled wall can check after it starts no wall (a wall mapped from a wrong pose
    would stay beside the true one).
    """
    rng = np.random.default_rng(4)
    judge, wall_map = PoseJudge(JudgeConfig(latency=0.0)), WallMap()
    poses = [np.array([0.2 * math.cos(k / 5), 0.3 * math.sin(k / 7), 0.1 * k]) for k in range(60)]
    for k, pose in enumerate(poses):
        jittered = pose + rng.normal(0.0, [0.01, 0.01, math.radians(1.0)])
        verdict = judge.judge(_frame(k * 0.1, pose), _source(k * 0.1, jittered), wall_map, None)
        wall_map.integrate(_frame(k * 0.1, pose), verdict.pose)
    true = poses[-1] + np.array([0.01, 0.01, 0.1])
    wrong = true + np.array([0.05, -0.05, math.radians(STEP_DEG)])
    assert not copy.deepcopy(judge.jumps).add(6.0, wrong), "a step the jump test takes for jitter"
    verdict = judge.judge(_frame(6.0, true), _source(6.0, wrong), wall_map, None)
    assert verdict.kind == "recovered"
    assert verdict.pose is not None
    np.testing.assert_allclose(verdict.pose.vector[:2], true[:2], atol=0.01)
    assert abs(se2.wrap(float(verdict.pose.vector[2] - true[2]))) < math.radians(0.3)
    unseen = [((6.0, -1.0), (6.0, 1.0))]  # a wall beyond the room, never mapped
    after = judge.judge(_frame(6.1, true, unseen), _source(6.1, wrong), wall_map, None)
    assert after.kind == "unjudged"
    assert not after.start_walls
