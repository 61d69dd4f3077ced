"""The wall map: one small EKF per wall, gated maximum-likelihood association. Pure, no Zenoh.

For each observed wall, every mapped wall whose extent lies near the observed segment is scored
by the log-likelihood of the innovation under the innovation covariance; the best one that passes
the chi-square gate takes the observation, otherwise the observation starts a new wall. The extent
check is what keeps two collinear walls in different rooms apart: on the line alone they are the
same wall.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common import ekf, se2, wall_model
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.services.mapper.extent import Extent
from wallmap.services.mapper.wall_index import WallIndex

Array = NDArray[np.float64]


SHADOW_SAMPLES = 21  # points along a wall tested for a shadow
NEAR_LINE = 1.0  # m: farther lines are never candidates for an observation
THROUGH_MARGIN = 0.1  # m: a ray ends this far past a wall (plus its noise) to cross it
THROUGH_NOISE = 3e-3  # m per m^2 of range: 3 sigma of a depth camera's range noise, a little more
THROUGH_NEAR = 0.3  # m from the sensor: nearer crossings are not counted
CROSSING_ANGLE = math.radians(30.0)  # a wall at least this far from parallel may cross a gap
CROSSING_REACH = 0.2  # m it must reach past the line on both sides: a T only meets it
SEEN_THROUGH = 0.5  # a wall seen through along this share of its length is none


def _default_pose_cov() -> Array:
    return np.diag([0.02**2, 0.02**2, np.radians(0.5) ** 2])


@dataclass(frozen=True)
class MapperConfig:
    """Everything that tunes the map.

    Attributes:
        gate: chi-square gate on the squared Mahalanobis distance of the innovation.
        max_extent_gap: an observed segment farther than this along the wall from the wall's
            extent is another wall on the same line (m).
        pose_cov: x/y/yaw covariance assumed for poses that carry none: no pose source is exact,
            and without it a wall seen a hundred times would refuse the next good observation.
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
            a door, a window, an occlusion...
        door_width: ...but one with a gap wider than a door that the sensor saw through (rays
            crossing the gap well before they ended) is two walls; so are two whose gap a wall
            crosses.
        line_floor: offset (m) and angle (rad) standard deviations added to both estimates when
            testing whether two walls are on one line: walls are not perfectly straight.
        fan_angle: of two confirmed walls within this angle (rad)...
        fan_offset: ...and this distance (m) whose segments overlap by more than...
        fan_overlap: ...this (m), only the one seen more often is served (see ``_fanned``).
        min_length: a wall whose served segments add up to less than this (m) is served as
            tentative: the detector reports no shorter line, so such a wall is a sliver of one.
        confirm_obs: a wall is tentative (a possible phantom) until seen this many times...
        confirm_views: ...from this many distinct viewpoints (moved ``view_distance`` or turned
            ``view_angle`` since the last one): one glimpse, however long, is not a wall.
        keyframe_distance: the trajectory kept with the map has a pose every this far (m)...
        keyframe_angle: ...or every this much turn (rad); also the distinct-view thresholds.
    """

    gate: float = ekf.CHI2_2DOF_999
    max_extent_gap: float = 1.0
    pose_cov: Array = field(default_factory=_default_pose_cov)
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
    merge_gap: float = 3.0
    door_width: float = 1.8
    line_floor: tuple[float, float] = (0.01, float(np.radians(0.5)))
    fan_angle: float = np.radians(8.0)
    fan_offset: float = 0.30
    fan_overlap: float = 0.3
    min_length: float = 0.25
    confirm_obs: int = 3
    confirm_views: int = 2
    keyframe_distance: float = 0.1
    keyframe_angle: float = np.radians(5.0)


@dataclass(frozen=True)
class MapQuery:
    """Which walls a reply holds: the selector parameters of ``{prefix}/map/walls``.

    Attributes:
        min_obs: walls seen at least this many times.
        tentative: also walls not yet confirmed (possible phantoms).
        bbox: (xmin, ymin, xmax, ymax): walls whose extent crosses this box.
        since: walls seen at or after this stamp.
        trajectory: add the keyframe trajectory.
    """

    min_obs: int = 1
    tentative: bool = False
    bbox: tuple[float, float, float, float] | None = None
    since: float | None = None
    trajectory: bool = False

    @classmethod
    def from_parameters(cls, params: Mapping[str, str]) -> MapQuery:
        """Parse selector parameters; ValueError says which one is wrong and why."""
        unknown = set(params) - {"min_obs", "tentative", "bbox", "since", "trajectory", "format"}
        if unknown:
            msg = f"unknown parameter {sorted(unknown)[0]!r}"
            raise ValueError(msg)
        try:
            min_obs = int(params.get("min_obs") or 1)
        except ValueError:
            msg = f"min_obs must be an integer, got {params.get('min_obs')!r}"
            raise ValueError(msg) from None
        bbox = None
        if params.get("bbox"):
            try:
                xmin, ymin, xmax, ymax = (float(v) for v in params["bbox"].split(","))
            except ValueError:
                msg = f"bbox must be xmin,ymin,xmax,ymax in metres, got {params['bbox']!r}"
                raise ValueError(msg) from None
            if not (xmin <= xmax and ymin <= ymax):
                msg = f"bbox must have xmin <= xmax and ymin <= ymax, got {params['bbox']!r}"
                raise ValueError(msg)
            bbox = (xmin, ymin, xmax, ymax)
        since = None
        if params.get("since"):
            try:
                since = float(params["since"])
            except ValueError:
                msg = f"since must be a stamp in seconds, got {params['since']!r}"
                raise ValueError(msg) from None
        flags = {}
        for name in ("tentative", "trajectory"):
            value = params.get(name, "false")
            if value not in ("true", "false"):
                msg = f"{name} must be true or false, got {value!r}"
                raise ValueError(msg)
            flags[name] = value == "true"
        return cls(min_obs, flags["tentative"], bbox, since, flags["trajectory"])


def _segment_in_map(obs: WallObservation, pose: Array) -> Array:
    """The observed segment's two ends in the map frame."""
    rot = se2.rotation(pose[2])
    return np.array([pose[:2] + rot @ obs.p0, pose[:2] + rot @ obs.p1])


def _moved(a: Array, b: Array, distance: float, angle: float) -> bool:
    """Whether pose ``b`` is a new viewpoint after ``a``."""
    (ax, ay, ayaw), (bx, by, byaw) = a.tolist(), b.tolist()
    turn = abs(se2.wrap(byaw - ayaw))
    return math.hypot(bx - ax, by - ay) >= distance or turn >= angle


def _end_near(ends: list[float], px: float, py: float, reach: float) -> int | None:
    """Which wall end lies within reach of point (px, py), the nearer if both, or None.

    ``ends`` is (x0, y0, x1, y1): 0 is the first segment's start, 1 the last one's end.
    """
    x0, y0, x1, y1 = ends
    d0, d1 = math.hypot(x0 - px, y0 - py), math.hypot(x1 - px, y1 - py)
    best, distance = (0, d0) if d0 <= d1 else (1, d1)
    return best if distance <= reach else None


def _passes(ends: list[float], px: float, py: float, margin: float) -> bool:
    """Whether point (px, py), on a wall's line, lies between its ends, ``margin`` inside."""
    x0, y0, x1, y1 = ends
    dx, dy = x1 - x0, y1 - y0
    length = math.hypot(dx, dy)
    along = ((px - x0) * dx + (py - y0) * dy) / max(length, 1e-12)
    return margin < along < length - margin


def _crosses_box(p0: Array, p1: Array, box: tuple[float, float, float, float]) -> bool:
    """Whether segment p0-p1 meets the box (Liang-Barsky clipping)."""
    lo, hi = np.array(box[:2]), np.array(box[2:])
    start, end, d = 0.0, 1.0, p1 - p0
    for axis in (0, 1):
        if abs(d[axis]) < 1e-12:
            if not lo[axis] <= p0[axis] <= hi[axis]:
                return False
            continue
        t0, t1 = sorted(((lo[axis] - p0[axis]) / d[axis], (hi[axis] - p0[axis]) / d[axis]))
        start, end = max(start, t0), min(end, t1)
    return start <= end


@dataclass
class Wall:
    """One mapped wall: its EKF state (anchored closest point), covariance and extent.

    ``ends`` is the union of everything observed (it decides which walls an observation may
    join); ``extent`` counts observations along the wall and gives the served segments.
    """

    id: int
    s: Array
    p: Array
    anchor: Array
    ends: Array  # 2x2, map frame, on the line
    extent: Extent
    n_obs: int
    first_seen: float
    last_seen: float
    views: int
    last_view: Array  # (x, y, yaw) of the last distinct viewpoint
    depth_obs: int = 0  # observations from a depth camera (the rest from a scanner)

    def __post_init__(self) -> None:
        self._segments: tuple[tuple[int, bytes], Array] | None = None
        self.set_state(self.s, self.p)

    def set_state(self, s: Array, p: Array) -> None:
        """New EKF state; the line's foot point, direction and normal follow."""
        self.s, self.p = s, p
        self.foot = wall_model.foot(s, self.anchor)
        (fx, fy), (sx, sy) = self.foot.tolist(), s.tolist()
        r = math.hypot(sx, sy)
        nx, ny = sx / r, sy / r
        self.normal = np.array([nx, ny])
        self.direction = np.array([-ny, nx])  # wall_model.direction, in floats
        # The same as plain floats, and the extent's span along the line, for _near's hot loop.
        self.frame = (fx, fy, -ny, nx, nx, ny)
        self.span = self._span(self.ends.tolist())

    def _span(self, points: list[list[float]]) -> tuple[float, float]:
        """Lowest and highest position of map points along the wall (plain floats)."""
        fx, fy, dx, dy, _, _ = self.frame
        t = [(x - fx) * dx + (y - fy) * dy for x, y in points]
        return min(t), max(t)

    def along(self, points: Array) -> Array:
        """Positions of map points along the wall, from its foot point."""
        return (points - self.foot) @ self.direction

    def on_line(self, t: Array) -> Array:
        """Map points at positions ``t`` along the wall."""
        return self.foot + np.outer(t, self.direction)

    def extend(self, points: Array) -> None:
        """Grow ``ends`` to cover ``points`` (their projections onto the current line)."""
        self.span = self._span(self.ends.tolist() + points.tolist())
        self.ends = self.on_line(np.array(self.span))

    def segments(self) -> Array:
        """The served segments (k x 2 x 2), from the extent counts, on the current line.

        Kept until the line or the counts change (every change to the counts comes with one to
        ``n_obs``), so replies on a large map redo only the walls that changed. Read-only.
        """
        key = (self.n_obs, self.extent.revision, self.s.tobytes())
        if self._segments is None or self._segments[0] != key:
            intervals = self.extent.intervals()
            axis = self.extent.origin + np.outer(np.ravel(intervals), self.extent.direction)
            pieces = self.on_line(self.along(axis)).reshape(-1, 2, 2)
            pieces.flags.writeable = False
            self._segments = (key, pieces)
        return self._segments[1]

    def confirmed(self, config: MapperConfig) -> bool:
        """Seen often enough, from enough viewpoints, to be served as a wall."""
        return self.n_obs >= config.confirm_obs and self.views >= config.confirm_views

    def to_reply(self, segments: Array, *, tentative: bool) -> dict[str, Any]:
        """The contract's wall record, in the map frame, with its segments."""
        uv, jac = wall_model.to_map_frame(self.s, self.anchor)
        return {
            "id": self.id,
            "u": float(uv[0]),
            "v": float(uv[1]),
            "cov": (jac @ self.p @ jac.T).tolist(),
            "p0": segments[0, 0].tolist(),
            "p1": segments[-1, 1].tolist(),
            "segments": segments.tolist(),
            "n_obs": self.n_obs,
            "n_views": self.views,
            "tentative": tentative,
            "first_seen": self.first_seen,
            "last_seen": self.last_seen,
        }


class WallMap:
    """All walls, with the counters the map reply carries. Not thread-safe: callers lock."""

    def __init__(self, config: MapperConfig | None = None) -> None:
        self.config = config or MapperConfig()
        self.walls: dict[int, Wall] = {}
        self.next_id = 0
        self.frames = 0
        self.observations = 0
        self.stamp: float | None = None
        self.trajectory: list[tuple[float, float, float, float]] = []  # stamp, x, y, yaw
        self.merges: list[tuple[int, int, float]] = []  # (merged id, surviving id, stamp)
        self.changed: set[int] = set()  # since the last take_changes()
        self.removed: set[int] = set()
        self.index = WallIndex(margin=self.config.max_extent_gap)
        self.version = 0  # grows with every integrated frame: replies can be cached by it

    def restore(self, wall: Wall) -> None:
        """Put back a wall read from the state file."""
        self.walls[wall.id] = wall
        self.index.file(wall.id, wall.ends)

    def integrate(self, frame: Observations, pose: Pose) -> list[int]:
        """Fold one frame's observations in; returns the wall id each observation went to."""
        pose_vec = pose.vector
        pose_cov = pose.cov if pose.cov is not None else self.config.pose_cov
        depth = frame.sensor == "depth"
        ids = [
            self._integrate_one(obs, pose_vec, pose_cov, frame.stamp, depth=depth)
            for obs in frame.walls
        ]
        self.finish_frame(frame, pose)
        return ids

    def finish_frame(self, frame: Observations, pose: Pose) -> None:
        """After a frame's observations: what its rays saw through, the counters, a keyframe."""
        if frame.rays is not None and frame.ray_origin is not None and len(frame.rays):
            self._see_through(frame.ray_origin, frame.rays, pose.vector)
        self.frames += 1
        self.version += 1
        self.observations += len(frame.walls)
        self.stamp = frame.stamp if self.stamp is None else max(self.stamp, frame.stamp)
        self._keep_keyframe(pose)

    def _see_through(self, origin: Array, ends: Array, pose: Array) -> None:
        """Count the rays that crossed walls well before they ended (see ``Extent``).

        A ray crosses a wall's line at some distance from the sensor; it ended past the wall by
        more than ``THROUGH_MARGIN`` plus its range noise, so the wall is not there.
        """
        rot = se2.rotation(pose[2])
        start = pose[:2] + rot @ origin
        stops = pose[:2] + ends @ rot.T
        rays = stops - start
        length = np.linalg.norm(rays, axis=1)
        margin = THROUGH_MARGIN + THROUGH_NOISE * length**2
        box = np.array([np.minimum(stops.min(axis=0), start), np.maximum(stops.max(axis=0), start)])
        for wall_id in sorted(self.index.near(box)):
            wall = self.walls[wall_id]
            towards = rays @ wall.normal
            with np.errstate(divide="ignore", invalid="ignore"):
                share = (wall.normal @ (wall.foot - start)) / towards  # where along each ray
            distance = share * length
            crossed = (distance > THROUGH_NEAR) & (distance < length - margin)
            if crossed.any() and wall.extent.add_through(
                start + share[crossed, None] * rays[crossed]
            ):
                self.changed.add(wall.id)

    def _keep_keyframe(self, pose: Pose) -> None:
        last = np.array(self.trajectory[-1][1:]) if self.trajectory else None
        cfg = self.config
        if last is None or _moved(last, pose.vector, cfg.keyframe_distance, cfg.keyframe_angle):
            self.trajectory.append((pose.stamp, pose.x, pose.y, pose.yaw))

    def _integrate_one(
        self, obs: WallObservation, pose: Array, pose_cov: Array, stamp: float, *, depth: bool
    ) -> int:
        best = self.match(obs, pose, pose_cov)
        if best is None:
            s, p, anchor = ekf.initial_state(obs.closest, obs.cov, pose, pose_cov)
            return self.add_wall(obs, s, p, anchor, pose, stamp, depth=depth).id
        wall, innov = best
        wall.set_state(*ekf.update(wall.s, wall.p, innov))
        return self.observed(wall, obs, pose, stamp, depth=depth).id

    def observed(
        self, wall: Wall, obs: WallObservation, pose: Array, stamp: float, *, depth: bool
    ) -> Wall:
        """Account for an observation whose update ``wall`` has taken: extent, counts, merges.

        Returns the wall that holds the observation now (another, if this one merged into it).
        """
        seg = _segment_in_map(obs, pose)
        wall.depth_obs += int(depth)
        wall.extend(seg)
        self.index.file(wall.id, wall.ends)
        wall.extent.add(seg)
        wall.n_obs += 1
        wall.last_seen = max(wall.last_seen, stamp)
        cfg = self.config
        if _moved(wall.last_view, pose, cfg.keyframe_distance, cfg.keyframe_angle):
            wall.views += 1
            wall.last_view = pose.copy()
        self.changed.add(wall.id)
        return self._merge_duplicates(wall, stamp)

    def near_observation(self, obs: WallObservation, pose: Array) -> list[Wall]:
        """The walls that may have made ``obs`` seen from ``pose``: association's candidates."""
        return self._near(_segment_in_map(obs, pose))

    def match(
        self, obs: WallObservation, pose: Array, pose_cov: Array, min_obs: int = 0
    ) -> tuple[Wall, ekf.Innovation] | None:
        """The most likely wall for ``obs`` seen from ``pose`` within the gate (None: no wall).

        Maximum likelihood over the walls near the observed segment, on the innovation
        covariance (wall, observation and pose). ``min_obs``: only walls seen that often.
        """
        best: tuple[float, Wall, ekf.Innovation] | None = None
        for wall in self.near_observation(obs, pose):
            if wall.n_obs < min_obs:
                continue
            innov = ekf.innovation(
                wall.s, wall.p, wall.anchor, obs.closest, obs.cov, pose, pose_cov
            )
            if innov.mahalanobis2 <= self.config.gate and (
                best is None or innov.log_likelihood > best[0]
            ):
                best = (innov.log_likelihood, wall, innov)
        return None if best is None else best[1:]

    def _merge_duplicates(self, wall: Wall, stamp: float) -> Wall:
        """Merge walls on ``wall``'s line: sharing its extent, or across a gap (_continues)."""
        gap = self.config.merge_gap
        reach = wall.ends + np.array([-1.0, 1.0])[:, None] * gap * wall.direction
        for other in self._near(reach, max_gap=0.0):
            if other.id not in self.walls or other is wall or wall.id not in self.walls:
                continue
            ta, tb = wall.along(wall.ends), wall.along(other.ends)
            overlap = min(ta.max(), tb.max()) >= max(ta.min(), tb.min())
            if self._same_wall(wall, other) if overlap else self._continues(wall, other):
                wall = self._absorb(wall, other, stamp)
        return wall

    def _absorb(self, a: Wall, b: Wall, stamp: float) -> Wall:
        """Make two walls one: the older id survives, the merge is reported."""
        keep, gone = (a, b) if a.id < b.id else (b, a)
        keep.set_state(*ekf.fuse(keep.s, keep.p, keep.anchor, gone.s, gone.p, gone.anchor))
        keep.extend(gone.ends)
        keep.extent.absorb(gone.extent)
        keep.n_obs += gone.n_obs
        keep.depth_obs += gone.depth_obs
        keep.views += gone.views
        keep.first_seen = min(keep.first_seen, gone.first_seen)
        keep.last_seen = max(keep.last_seen, gone.last_seen)
        del self.walls[gone.id]
        self.index.remove(gone.id)
        self.index.file(keep.id, keep.ends)
        self.merges.append((gone.id, keep.id, stamp))
        self.changed.discard(gone.id)
        self.removed.add(gone.id)
        self.changed.add(keep.id)
        return keep

    def _continues(self, a: Wall, b: Wall) -> bool:
        """Whether ``b`` is ``a`` on the far side of a gap: one wall with a door or a window.

        Both confirmed and seen twice as often as that, their extents apart by at most
        ``merge_gap``, their lines within
        ``merge_angle`` and ``merge_offset`` at the gap and statistically one line (the
        estimates and their covariances, with ``line_floor``), no wall crossing the line in the
        gap, and a gap wider than ``door_width`` not seen through.
        """
        cfg = self.config
        settled = 2 * cfg.confirm_obs  # a merge is for good: decide it on settled estimates
        if not (a.confirmed(cfg) and b.confirmed(cfg)) or min(a.n_obs, b.n_obs) < settled:
            return False
        ta, tb = a.along(a.ends), a.along(b.ends)
        gap_start, gap_end = (ta.max(), tb.min()) if ta.max() < tb.min() else (tb.max(), ta.min())
        if gap_end - gap_start > cfg.merge_gap:
            return False
        if np.arccos(min(abs(float(a.normal @ b.normal)), 1.0)) > cfg.merge_angle:
            return False
        ends = a.on_line(np.array([gap_start, gap_end]))
        middle = 0.5 * (ends[0] + ends[1])
        if abs(float(b.normal @ (middle - b.foot))) > cfg.merge_offset:
            return False
        chi2 = ekf.line_agreement(a.s, a.p, a.anchor, b.s, b.p, b.anchor, cfg.line_floor)
        if chi2 > ekf.CHI2_2DOF_999 or self._crossed(a, b, ends):
            return False
        if gap_end - gap_start <= cfg.door_width:
            return True
        gap = a.extent.along(ends)
        return max(a.extent.seen_through(gap.min(), gap.max()), _seen_through(b, ends)) < 0.3

    def _crossed(self, a: Wall, b: Wall, gap: Array) -> bool:
        """Whether a confirmed wall crosses ``a``'s line between the two ends of ``gap``."""
        across = gap[1] - gap[0]
        length2 = max(float(across @ across), 1e-12)
        for other in (self.walls[i] for i in sorted(self.index.near(gap))):
            if other is a or other is b or not other.confirmed(self.config):
                continue
            if abs(float(other.normal @ a.normal)) > math.cos(CROSSING_ANGLE):
                continue
            for p, q in other.segments():
                side_p, side_q = float(a.normal @ (p - a.foot)), float(a.normal @ (q - a.foot))
                if min(side_p, side_q) > -CROSSING_REACH or max(side_p, side_q) < CROSSING_REACH:
                    continue  # ends at the line (a T) or stays on one side
                at = p + (q - p) * (side_p / (side_p - side_q))  # where it meets the line
                if 0.0 < float((at - gap[0]) @ across) / length2 < 1.0:
                    return True
        return False

    def _same_wall(self, a: Wall, b: Wall) -> bool:
        """Lines within ``merge_angle`` and ``merge_offset`` where the extents overlap."""
        na, nb = a.normal, b.normal
        if np.arccos(min(abs(float(na @ nb)), 1.0)) > self.config.merge_angle:
            return False
        ta, tb = a.along(a.ends), a.along(b.ends)
        middle = 0.5 * (max(ta.min(), tb.min()) + min(ta.max(), tb.max()))
        point = a.on_line(np.array([middle]))[0]
        offset = abs(float(nb @ (point - b.foot)))
        return offset <= self.config.merge_offset

    def _near(self, seg: Array, max_gap: float | None = None) -> list[Wall]:
        """Walls near a segment, along the wall and across it.

        Their extent comes within ``max_gap`` (default ``max_extent_gap``) of the segment along
        the wall, and their line within ``NEAR_LINE`` of its middle: farther lines could only
        pass the association gate with metres of uncertainty, and leaving them out spares an
        innovation each. Plain floats: there are only a handful of candidates.
        """
        limit = self.config.max_extent_gap if max_gap is None else max_gap
        (ax, ay), (bx, by) = seg.tolist()
        mx, my = 0.5 * (ax + bx), 0.5 * (ay + by)
        near = []
        walls = self.walls
        for wall_id in sorted(self.index.near(seg)):
            wall = walls[wall_id]
            fx, fy, dx, dy, nx, ny = wall.frame
            t0, t1 = (ax - fx) * dx + (ay - fy) * dy, (bx - fx) * dx + (by - fy) * dy
            if t0 > t1:
                t0, t1 = t1, t0
            low, high = wall.span
            if (
                t0 - high <= limit
                and low - t1 <= limit
                and -NEAR_LINE <= (mx - fx) * nx + (my - fy) * ny <= NEAR_LINE
            ):
                near.append(wall)
        return near

    def add_wall(
        self,
        obs: WallObservation,
        s: Array,
        p: Array,
        anchor: Array,
        pose: Array,
        stamp: float,
        *,
        depth: bool,
    ) -> Wall:
        """Start a wall at state ``(s, p, anchor)`` from its first observation ``obs``."""
        seg = _segment_in_map(obs, pose)
        extent = Extent(anchor + s, wall_model.direction(s))
        wall = Wall(
            self.next_id, s, p, anchor, seg.copy(), extent, 1, stamp, stamp, 1, pose.copy(),
            int(depth),
        )  # fmt: skip
        wall.extend(seg)  # puts the end points on the line
        extent.add(seg)
        self.restore(wall)
        self.changed.add(wall.id)
        self.next_id += 1
        return wall

    def _shadowed(self, wall: Wall) -> bool:
        """Whether far better supported walls run along most of this one (see MapperConfig).

        The wall is sampled along its extent; a sample is covered where a better supported
        wall within ``shadow_angle`` passes within ``shadow_offset`` of it, inside that
        wall's extent. Two such walls can cover a line blended across the corner they make.
        """
        cfg = self.config
        pieces = wall.segments()
        (ax, ay), (bx, by) = pieces[0, 0].tolist(), pieces[-1, 1].tolist()
        samples: Array | None = None
        covered = np.zeros(SHADOW_SAMPLES, dtype=bool)
        cos_max, offset = math.cos(cfg.shadow_angle), cfg.shadow_offset
        for other in (self.walls[i] for i in self.index.near(wall.ends)):
            if other is wall or other.n_obs < cfg.shadow_ratio * wall.n_obs:
                continue
            fx, fy, _, _, nx, ny = other.frame
            if abs(wall.frame[4] * nx + wall.frame[5] * ny) < cos_max:
                continue
            # Both ends beyond the band on one side: no point between them is inside it.
            da, db = (ax - fx) * nx + (ay - fy) * ny, (bx - fx) * nx + (by - fy) * ny
            if min(da, db) > offset or max(da, db) < -offset:
                continue
            if samples is None:
                samples = np.linspace(pieces[0, 0], pieces[-1, 1], SHADOW_SAMPLES)
            across = np.abs((samples - other.foot) @ other.normal)
            along = other.along(samples)
            theirs = other.segments()
            low, high = other.along(theirs[0, 0]), other.along(theirs[-1, 1])
            covered |= (across <= offset) & (along >= low - offset) & (along <= high + offset)
        return float(covered.mean()) >= cfg.shadow_cover

    def served(self, wall: Wall) -> bool:
        """Confirmed, not seen through, not a shadow of another wall: what a reply serves."""
        if not wall.confirmed(self.config):
            return False
        if wall.extent.free_share() >= SEEN_THROUGH:
            return False
        pieces = wall.segments()
        length = float(np.linalg.norm(pieces[:, 1] - pieces[:, 0], axis=1).sum())
        if length < self.config.min_length or self._shadowed(wall):
            return False
        return not self._fanned(wall, pieces)

    def _fanned(self, wall: Wall, pieces: Array) -> bool:
        """Whether a better-seen confirmed wall runs alongside: one surface as two lines.

        On real clutter a surface and what stands against it (a cabinet front, appliances on a
        counter) come out as lines a few degrees and centimetres apart. Of two confirmed walls
        within ``fan_angle`` and ``fan_offset`` whose segments overlap by ``fan_overlap``, only
        the one seen more often (the older on a tie) is served. Walls seen mostly by a scanner
        are left alone: its one plane sees no clutter stand against walls, and a bent wall's
        near-parallel pieces are each where its points are.
        """
        cfg = self.config
        if 2 * wall.depth_obs <= wall.n_obs:
            return False
        cos_max = math.cos(cfg.fan_angle)
        ta = wall.along(pieces.reshape(-1, 2))
        for other in (self.walls[i] for i in sorted(self.index.near(wall.ends))):
            if other is wall or (other.n_obs, -other.id) < (wall.n_obs, -wall.id):
                continue
            if abs(float(wall.normal @ other.normal)) < cos_max or not other.confirmed(cfg):
                continue
            if 2 * other.depth_obs <= other.n_obs:
                continue
            theirs = other.segments()
            tb = wall.along(theirs.reshape(-1, 2))
            low, high = max(ta.min(), tb.min()), min(ta.max(), tb.max())
            if high - low <= cfg.fan_overlap:
                continue
            middle = wall.on_line(np.array([0.5 * (low + high)]))[0]
            if abs(float(other.normal @ (middle - other.foot))) <= cfg.fan_offset:
                return True
        return False

    def _selected(self, wall: Wall, query: MapQuery, served: dict[int, bool]) -> bool:
        served[wall.id] = self.served(wall)
        if wall.n_obs < query.min_obs or (not query.tentative and not served[wall.id]):
            return False
        if query.since is not None and wall.last_seen < query.since:
            return False
        return query.bbox is None or any(_crosses_box(a, b, query.bbox) for a, b in wall.segments())

    def cornered_segments(self, ids: Iterable[int], served: dict[int, bool]) -> dict[int, Array]:
        """The segments of walls ``ids``, with their ends joined at corners.

        An end of a served wall that meets a served neighbour's end at a corner moves onto the
        corner (an L); so does one that meets a neighbour going on through the crossing (a T),
        which keeps its segments. ``served`` caches :meth:`served` and comes back filled for
        ``ids``.
        """
        raw: dict[int, tuple[Array, list[float]]] = {}

        def segments(wall: Wall) -> tuple[Array, list[float]]:
            """The wall's segments and its two ends (x0, y0, x1, y1) as floats."""
            if wall.id not in raw:
                pieces = wall.segments()
                raw[wall.id] = pieces, [*pieces[0, 0].tolist(), *pieces[-1, 1].tolist()]
            return raw[wall.id]

        def is_served(wall: Wall) -> bool:
            if wall.id not in served:
                served[wall.id] = self.served(wall)
            return served[wall.id]

        cfg = self.config
        sin_min, reach = math.sin(cfg.corner_angle), cfg.corner_reach
        band, max_reach = cfg.corner_band, cfg.corner_max_reach
        out = {}
        for wall_id in ids:
            a = self.walls[wall_id]
            pieces, a_ends = segments(a)
            mine = pieces.copy()
            out[wall_id] = mine
            if not is_served(a):
                continue
            afx, afy, _, _, anx, any_ = a.frame
            a_offset = anx * afx + any_ * afy
            for b in (self.walls[i] for i in sorted(self.index.near(a.ends)) if i != a.id):
                bfx, bfy, _, _, bnx, bny = b.frame
                det = anx * bny - any_ * bnx  # sine of the angle between the lines
                if abs(det) < sin_min or not is_served(b):
                    continue
                b_offset = bnx * bfx + bny * bfy
                # Where the two lines cross (Cramer's rule on the 2x2 system of their normals).
                cx = (a_offset * bny - any_ * b_offset) / det
                cy = (anx * b_offset - bnx * a_offset) / det
                # The shallower the corner, the farther past it the inlier band reaches.
                far = min(max_reach, max(reach, band / abs(det)))
                end_a = _end_near(a_ends, cx, cy, far)
                if end_a is None:
                    continue
                b_ends = segments(b)[1]
                # An L (both end at the crossing) or a T (b goes on through it): a's end goes
                # there. The wall that goes on through a T is not cut (its end is not near).
                if _end_near(b_ends, cx, cy, far) is not None or _passes(b_ends, cx, cy, far):
                    mine[(0, -1)[end_a], end_a] = (cx, cy)
        return out

    def reply(self, query: MapQuery | None = None) -> dict[str, Any]:
        """The contract's map reply (without the schema version, which the codec adds)."""
        query = query or MapQuery()
        served: dict[int, bool] = {}
        chosen = [w.id for w in self.walls.values() if self._selected(w, query, served)]
        segments = self.cornered_segments(chosen, served)
        body: dict[str, Any] = {
            "frame": "map",
            "frames": self.frames,
            "observations": self.observations,
            "stamp": self.stamp,
            "walls": [self.walls[i].to_reply(segments[i], tentative=not served[i]) for i in chosen],
            "merges": [list(m) for m in self.merges],
        }
        if query.trajectory:
            body["trajectory"] = [list(p) for p in self.trajectory]
        return body

    def take_changes(self) -> dict[str, Any]:
        """Walls changed and ids removed since the last call: the body of a map update.

        A wall's neighbours come along: a change can move the corner they share.
        """
        ids = set(self.changed)
        for i in self.changed:
            ids |= self.index.near(self.walls[i].ends)
        served: dict[int, bool] = {}
        segments = self.cornered_segments(sorted(ids), served)
        walls = [self.walls[i].to_reply(segments[i], tentative=not served[i]) for i in sorted(ids)]
        removed = sorted(self.removed)
        self.changed.clear()
        self.removed.clear()
        return {"frames": self.frames, "stamp": self.stamp, "walls": walls, "removed": removed}


def _seen_through(wall: Wall, ends: Array) -> float:
    """Share of a stretch of ``wall``'s line (two map points) that rays crossed repeatedly."""
    gap = wall.extent.along(ends)
    return wall.extent.seen_through(gap.min(), gap.max())
