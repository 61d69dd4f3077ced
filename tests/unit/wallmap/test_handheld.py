"""Generated handheld recordings: 6-DoF camera, a tilted fixed frame, a kitchen's clutter.

The camera is carried 1.4 m up, pitched down 25 degrees, rolling and pitching 10 degrees either
way and rising and falling 0.2 m; the trajectory is recorded in a frame tilted 30 degrees from
level whose floor lies 1.3 m below its origin; counters with appliances stand along the walls.
The map is scored against the scene's truth, brought the three ways users have it.
"""

from __future__ import annotations

import pytest

from wallmap.common.map_consistency import MappedWall, fans
from wallmap.config import configured
from wallmap.evaluation import evaluate_map
from wallmap.offline import map_bag, walls
from wallmap.scene import SCENE_KINDS, Camera, Handheld, write_handheld_recording

SEED = 41
CAMERA = Camera(width=128, height=96)


HANDHELD = Handheld(frame_tilt_deg=30.0, floor_z=-1.3)


TUM = configured(
    f"player.source.intrinsics={[CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy]}",
    "player.source.depth_scale=1000",
)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("handheld")
    plan = SCENE_KINDS["kitchen"].plan(SEED)
    made = {}
    for style in ("camera", "robot", "tum"):
        path = folder / (style if style == "tum" else f"{style}.bag")
        made[style] = write_handheld_recording(
            path, seed=SEED, n_frames=500, style=style, plan=plan, handheld=HANDHELD, camera=CAMERA
        )
    return made


def score(info, reply_walls):
    result = evaluate_map(reply_walls, info.plan, info.seen_counts)
    print(f"\n{info.path.name}: {result.summary()}")
    return result


@pytest.mark.parametrize("style", ["camera", "robot", "tum"])
def test_a_handheld_camera_in_a_tilted_frame_maps_the_walls_not_the_clutter(recordings, style):
    info = recordings[style]
    wall_map = map_bag(info.path, TUM if style == "tum" else None)
    assert wall_map.frames == info.n_frames
    served = walls(wall_map, min_obs=3)
    result = score(info, served)
    assert result.precision >= 0.85
    assert result.recall >= 0.9
    assert result.median_angle_deg <= 0.5
    assert result.median_offset_m <= 0.02
    assert result.duplicates <= 1
    assert fans([MappedWall.from_reply(w) for w in served]) == []


def test_without_levelling_the_tilted_frame_gives_no_map(recordings):
    """What --level none does to a frame tilted 30 degrees: the band is not where the walls are."""
    info = recordings["camera"]
    levelled = score(info, walls(map_bag(info.path), min_obs=3))
    as_is = score(
        info, walls(map_bag(info.path, configured("player.source.level=none")), min_obs=3)
    )
    assert as_is.recall < levelled.recall - 0.5
