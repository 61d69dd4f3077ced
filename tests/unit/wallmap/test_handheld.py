"""Generated handheld recordings mapped offline: 6-DoF camera, a tilted fixed frame, a kitchen's
clutter, brought the three ways users have it (``handheld_scenes``), scored against the truth.
"""

from __future__ import annotations

import pytest
from handheld_scenes import TUM, score

from wallmap.common.map_consistency import MappedWall, fans
from wallmap.config import configured
from wallmap.offline import map_bag, walls


@pytest.mark.parametrize("style", ["camera", "robot", "tum"])
def test_a_handheld_camera_in_a_tilted_frame_maps_the_walls_not_the_clutter(
    handheld_recordings, style
):
    info = handheld_recordings[style]
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


def test_without_levelling_the_tilted_frame_gives_no_map(handheld_recordings):
    """What --level none does to a frame tilted 30 degrees: the band is not where the walls are."""
    info = handheld_recordings["camera"]
    levelled = score(info, walls(map_bag(info.path), min_obs=3))
    as_is = score(
        info, walls(map_bag(info.path, configured("player.source.level=none")), min_obs=3)
    )
    assert as_is.recall < levelled.recall - 0.5
