"""The map as people read it on a terminal (``wallmap query``, ``up`` and ``demo``)."""

from __future__ import annotations

from wallmap.common.map_records import MapReply, WallRecord
from wallmap.map_client import describe_pose_source, format_table


def _wall(wall_id: int) -> WallRecord:
    return WallRecord(
        id=wall_id,
        u=1.0,
        v=0.0,
        cov=((1e-4, 0.0), (0.0, 1e-4)),
        p0=(1.0, -1.0),
        p1=(1.0, 1.0),
        segments=(((1.0, -1.0), (1.0, 1.0)),),
        n_obs=5,
        n_views=2,
        tentative=False,
        first_seen=0.0,
        last_seen=1.0,
    )


def test_one_wall_is_one_row_under_the_header() -> None:
    lines = format_table(MapReply(frames=1, observations=1, walls=(_wall(7),))).splitlines()
    assert lines[0] == "1 wall from 1 frame and 1 observation (frame map)"
    assert lines[1].split() == ["id", "u", "v", "sigma", "x0", "y0", "x1", "y1", "length", "n_obs"]
    assert lines[2].split()[0] == "7"
    assert float(lines[2].split()[8]) == 2.0  # length


def test_no_wall_is_said_without_an_empty_table() -> None:
    text = format_table(MapReply(frames=58, observations=0))
    assert text == "0 walls from 58 frames and 0 observations (frame map)"


def test_the_pose_line_says_whether_the_latency_was_estimated_given_or_guessed() -> None:
    found = {
        "latency_s": 0.0234,
        "latency_fixed": False,
        "settled": True,
        "position_sd_m": 0.002,
        "heading_sd_deg": 1.31,
        "frames_corrected": 350,
        "frames_recovered": 0,
        "frames_refused": 0,
        "frames_unjudged": 64,
    }
    assert "latency +23 ms (estimated)" in describe_pose_source(found)
    guessed = describe_pose_source({**found, "latency_s": 0.0, "settled": False})
    assert "latency +0 ms (not yet estimated: the guess)" in guessed
    given = describe_pose_source({**found, "latency_s": -0.03, "latency_fixed": True})
    assert "latency -30 ms (given)" in given
