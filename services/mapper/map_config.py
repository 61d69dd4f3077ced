"""Everything that tunes the map: association, merging, and what is served. Pure.

One frozen dataclass, the ``[mapper.map]`` section of the configuration, read by the map's
estimation (``wall_map``) and by what it serves (``serving``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wallmap.common import ekf

Array = NDArray[np.float64]


@dataclass(frozen=True)
class MapperConfig:
    """Everything that tunes the map.

    Attributes:
        gate: chi-square gate on the squared Mahalanobis distance of the innovation.
        max_extent_gap: an observed segment farther than this along the wall from the wall's
            extent is another wall on the same line (m).
        pose_sd: x, y (m) and yaw (rad) standard deviations assumed for poses that carry no
            covariance: no pose source is exact, and without it a wall seen a hundred times
            would refuse the next good observation.
        merge_angle: two walls whose lines differ by less than this angle (rad)...
        merge_offset: ...and lie closer than this (m) where their extents overlap are one wall:
            they merge, and the older id survives. 3 degrees and 10 cm is also the rule by which
            two walls count as a duplicate (docs/real-data.md); the two faces of a wall thinner
            than 10 cm, seen from both sides, become one.
        corner_reach: served ends of two confirmed walls that both lie this close (m) to where
            their lines cross meet there: each wall's extent overshoots a corner a little, where
            its detected lines took in points of the other wall.
        corner_band: ...or within this (m) divided by the sine of the angle between them,
            whichever is farther: a detected line takes in the other wall's points up to where
            that wall leaves its inlier band, ``band / sin(angle)`` past a shallow corner
            (0.15 m is the band of a Kinect-like camera at about 6 m).
        corner_max_reach: the farthest an end moves to a corner (m): lines a few degrees apart
            that cross mid-length are no corner, and are not cut there.
        corner_angle: walls closer to parallel than this (rad) have no corner.
        shadow_angle: a wall that lies, along ``shadow_cover`` of its length, within
            ``shadow_offset`` (m) of walls seen ``shadow_ratio`` times as often and at most this
            angle (rad) from it is a shadow of them: a line blended across a shallow corner
            from far away, lying on one wall or on both walls of the corner. It is served as
            tentative.
        shadow_offset: see above.
        shadow_ratio: see above.
        shadow_cover: see above.
        merge_gap: two confirmed walls on one line (their estimates agree, see
            ``line_agreement``) separated along it by at most this (m) are one wall with a gap:
            a door, a window, an occlusion, a stretch of glass (4 m: an office's glass front
            between two pieces of solid wall is one wall, issue 28)...
        door_width: ...but one with a gap wider than a door that the sensor saw through (rays
            crossing the gap well before they ended) is two walls; so are two whose gap a wall
            crosses.
        line_floor: offset (m) and angle (rad) standard deviations added to both estimates when
            testing whether two walls are on one line: walls are not perfectly straight.
        fan_angle: of two confirmed walls within this angle (rad)...
        fan_offset: ...and this distance (m) whose segments overlap by more than...
        fan_overlap: ...this (m), only the one seen more often is served (see ``_fanned``).
        fan_share: ...and for a wall seen mostly by a scanner, by this share of its length too.
        min_length: a wall whose served segments add up to less than this (m) is served as
            tentative: the detector reports no shorter line, so such a wall is a sliver of one.
        confirm_obs: a wall is tentative (a possible phantom) until seen this many times...
        confirm_views: ...from this many distinct viewpoints (moved ``view_distance`` or turned
            ``view_angle`` since the last one): one glimpse, however long, is not a wall.
        keyframe_distance: the trajectory kept with the map has a pose every this far (m)...
        keyframe_angle: ...or every this much turn (rad); also the distinct-view thresholds.
        keyframe_error: ...and wherever the poses used between two keyframes stray from the
            line between them by more than this (m, rad): interpolated, the trajectory places
            every frame within it (a judged pose is corrected frame by frame).
    """

    gate: float = ekf.CHI2_2DOF_999
    max_extent_gap: float = 1.0
    pose_sd: tuple[float, float, float] = (0.02, 0.02, math.radians(0.5))
    merge_angle: float = np.radians(3.0)
    merge_offset: float = 0.10
    corner_reach: float = 0.4
    corner_band: float = 0.15
    corner_max_reach: float = 0.6
    corner_angle: float = np.radians(3.0)
    shadow_angle: float = np.radians(15.0)
    shadow_offset: float = 0.10
    shadow_ratio: float = 2.0
    shadow_cover: float = 0.7
    merge_gap: float = 4.0
    door_width: float = 1.8
    line_floor: tuple[float, float] = (0.01, float(np.radians(0.5)))
    fan_angle: float = np.radians(8.0)
    fan_offset: float = 0.30
    fan_overlap: float = 0.3
    fan_share: float = 0.5
    min_length: float = 0.25
    confirm_obs: int = 3
    confirm_views: int = 2
    keyframe_distance: float = 0.1
    keyframe_angle: float = np.radians(5.0)
    keyframe_error: tuple[float, float] = (0.01, float(np.radians(0.2)))

    @property
    def pose_cov(self) -> Array:
        """The covariance of ``pose_sd``."""
        return np.diag(np.square(self.pose_sd))
