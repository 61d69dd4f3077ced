"""The wall map's estimation: one small EKF per wall, gated maximum-likelihood association.

For each observed wall, every mapped wall whose extent lies near the observed segment is scored
by the log-likelihood of the innovation under the innovation covariance; the best one that passes
the chi-square gate takes the observation, otherwise the observation starts a new wall. The extent
check is what keeps two collinear walls in different rooms apart: on the line alone they are the
same wall. Walls found to be one merge (the older id survives); rays that passed through a wall's
line mark where it is not. What is served of all this is ``serving``'s policy. Pure, no Zenoh.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from wallmap.common import compiled, ekf, keyframes, se2, wall_model
from wallmap.common.compiled import plain
from wallmap.common.keyframes import Keyframe
from wallmap.common.messages import Observations, Pose, WallObservation
from wallmap.services.mapper.extent import Extent
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.wall import Wall
from wallmap.services.mapper.wall_index import WallIndex

Array = NDArray[np.float64]


NEAR_LINE = 1.0  # m: farther lines are never candidates for an observation
THROUGH_MARGIN = 0.1  # m: a ray ends this far past a wall (plus its noise) to cross it
THROUGH_NOISE = 3e-3  # m per m^2 of range: 3 sigma of a depth camera's range noise, a little more
THROUGH_NEAR = 0.3  # m from the sensor: nearer crossings are not counted
CROSSING_ANGLE = math.radians(30.0)  # a wall at least this far from parallel may cross a gap
CROSSING_REACH = 0.2  # m it must reach past the line on both sides: a T only meets it
KEYFRAME_GAP = 100  # frames without a keyframe at most (a robot standing still)


def _segment_in_map(obs: WallObservation, pose: Array) -> Array:
    """The observed segment's two ends in the map frame (in floats: three per observation)."""
    x, y, yaw = pose.tolist()
    c, s = math.cos(yaw), math.sin(yaw)
    (ax, ay), (bx, by) = obs.p0.tolist(), obs.p1.tolist()
    return np.array(
        [[x + c * ax - s * ay, y + s * ax + c * ay], [x + c * bx - s * by, y + s * bx + c * by]]
    )


def _moved(a: Array, b: Array, distance: float, angle: float) -> bool:
    """Whether pose ``b`` is a new viewpoint after ``a``."""
    (ax, ay, ayaw), (bx, by, byaw) = a.tolist(), b.tolist()
    turn = abs(se2.wrap(byaw - ayaw))
    return math.hypot(bx - ax, by - ay) >= distance or turn >= angle


class WallMap:
    """All walls, with the counters the map reply carries. Not thread-safe: callers lock."""

    def __init__(self, config: MapperConfig | None = None) -> None:
        self.config = config or MapperConfig()
        self.walls: dict[int, Wall] = {}
        self.next_id = 0
        self.frames = 0
        self.observations = 0
        self.stamp: float | None = None
        self.trajectory: list[Keyframe] = []  # keyframes: stamp, x, y, yaw
        self._since_keyframe: list[Keyframe] = []  # the poses used since the last keyframe
        self.merges: list[tuple[int, int, float]] = []  # (merged id, surviving id, stamp)
        self.changed: set[int] = set()  # since the last take_changes()
        self.removed: set[int] = set()
        self.index = WallIndex(margin=self.config.max_extent_gap)
        self.version = 0  # grows with every integrated frame: replies can be cached by it

    def restore(self, wall: Wall) -> None:
        """Put back a wall read from the state file."""
        self.walls[wall.id] = wall
        self.index.file(wall.id, wall.ends)

    def integrate(self, frame: Observations, pose: Pose, *, start_walls: bool = True) -> list[int]:
        """Fold one frame's observations in; returns the wall id each observation went to.

        ``start_walls``: whether an observation no wall takes starts one (id -1 where not).
        """
        pose_vec = plain(pose.vector, np.float64)  # the compiled loops take one kind of array
        pose_cov = plain(pose.cov if pose.cov is not None else self.config.pose_cov, np.float64)
        depth = frame.sensor == "depth"
        ids = [
            self._integrate_one(
                obs, pose_vec, pose_cov, frame.stamp, depth=depth, start=start_walls
            )
            for obs in frame.walls
        ]
        self.finish_frame(frame, pose)
        return ids

    def skip_frame(self, frame: Observations) -> None:
        """A frame taken and left out of the map (its pose refused): counted, nothing else."""
        self.frames += 1
        self.version += 1
        self.stamp = frame.stamp if self.stamp is None else max(self.stamp, frame.stamp)

    def finish_frame(self, frame: Observations, pose: Pose) -> None:
        """After a frame's observations: what its rays saw through, the counters, a keyframe."""
        # A scanner's rays are its returns, one height: they draw the floor seen (rooms), and
        # test no wall (a lidar's walls are its returns already).
        rays = frame.rays
        if (
            frame.sensor != "scan"
            and rays is not None
            and frame.ray_origin is not None
            and len(rays)
        ):
            self._see_through(frame.ray_origin, rays, pose.vector)
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
        kernels = compiled.map_kernels()
        start, rays, length, limit, box = kernels.rays_in_map(
            plain(origin, np.float64),
            plain(ends, np.float64),
            plain(pose, np.float64),
            THROUGH_MARGIN,
            THROUGH_NOISE,
        )
        walls = [self.walls[wall_id] for wall_id in sorted(self.index.near(box))]
        if not walls:
            return
        which, points = kernels.crossings(
            start,
            rays,
            length,
            limit,
            np.array([wall.normal for wall in walls], dtype=np.float64),
            np.array([wall.foot for wall in walls], dtype=np.float64),
            THROUGH_NEAR,
        )
        for k in np.unique(which):
            if walls[k].extent.add_through(points[which == k]):
                self.changed.add(walls[k].id)

    def path(self) -> list[Keyframe]:
        """The keyframes, then the newest pose used: what the map reply's trajectory is."""
        return self.trajectory + self._since_keyframe[-1:]

    def _keep_keyframe(self, pose: Pose) -> None:
        """A keyframe every step of travel or turn, and where interpolation would misplace a frame.

        Judged poses are corrected frame by frame (``common.keyframes``).
        """
        new = Keyframe(pose.stamp, pose.x, pose.y, pose.yaw)
        cfg = self.config
        pending = self._since_keyframe
        if not self.trajectory or new[0] <= self.trajectory[-1][0]:
            self.trajectory.append(new)  # the first pose, or a new run
            pending.clear()
            return
        if len(pending) >= KEYFRAME_GAP or not keyframes.interpolates(
            self.trajectory[-1], new, pending, *cfg.keyframe_error
        ):
            self.trajectory.append(pending[-1])  # the last pose the straight line still held
            pending.clear()
        last = np.array(self.trajectory[-1][1:])
        if _moved(last, pose.vector, cfg.keyframe_distance, cfg.keyframe_angle):
            self.trajectory.append(new)
            pending.clear()
        else:
            pending.append(new)

    def _integrate_one(
        self,
        obs: WallObservation,
        pose: Array,
        pose_cov: Array,
        stamp: float,
        *,
        depth: bool,
        start: bool,
    ) -> int:
        wall = self.match(obs, pose, pose_cov)
        if wall is None:
            if not start:
                return -1
            s, p, anchor = ekf.initial_state(obs.closest, obs.cov, pose, pose_cov)
            return self.add_wall(obs, s, p, anchor, pose, stamp, depth=depth).id
        wall.set_state(
            *compiled.map_kernels().update(
                plain(wall.s, np.float64),
                plain(wall.p, np.float64),
                plain(wall.anchor, np.float64),
                plain(obs.closest, np.float64),
                plain(obs.cov, np.float64),
                pose,
                pose_cov,
            )
        )
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
    ) -> Wall | None:
        """The most likely wall for ``obs`` seen from ``pose`` within the gate (None: no wall).

        Maximum likelihood over the walls near the observed segment, on the innovation
        covariance (wall, observation and pose). ``min_obs``: only walls seen that often.
        """
        walls = [w for w in self.near_observation(obs, pose) if w.n_obs >= min_obs]
        if not walls:
            return None
        n = len(walls)
        z, r = np.empty((n, 2)), np.empty((n, 2, 2))  # the observation, once for each wall
        z[:], r[:] = obs.closest, obs.cov
        best = compiled.pose_kernels().best_pairs(
            np.array([w.s for w in walls], dtype=np.float64),
            np.array([w.p for w in walls], dtype=np.float64),
            np.array([w.anchor for w in walls], dtype=np.float64),
            z,
            r,
            plain(pose, np.float64),
            plain(pose_cov, np.float64),
            np.zeros(n, dtype=np.int64),  # all pairs are the one observation's
            self.config.gate,
        )
        return walls[best[0]] if len(best) else None

    def _merge_duplicates(self, wall: Wall, stamp: float) -> Wall:
        """Merge walls on ``wall``'s line: sharing its extent, or across a gap (_continues)."""
        gap = self.config.merge_gap
        (ax, ay), (bx, by) = wall.ends.tolist()
        _, _, dx, dy, _, _ = wall.frame
        reach = np.array([[ax - gap * dx, ay - gap * dy], [bx + gap * dx, by + gap * dy]])
        for other in self._near(reach, max_gap=0.0):
            if other.id not in self.walls or other is wall or wall.id not in self.walls:
                continue
            (low, high), (other_low, other_high) = wall.span, wall.span_of(other.ends.tolist())
            overlap = min(high, other_high) >= max(low, other_low)
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
        (a0, a1), (b0, b1) = a.along(a.ends).tolist(), a.along(b.ends).tolist()
        middle = 0.5 * (max(min(a0, a1), min(b0, b1)) + min(max(a0, a1), max(b0, b1)))
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
            self.next_id,
            s,
            p,
            anchor,
            seg.copy(),
            extent,
            1,
            stamp,
            stamp,
            1,
            pose.copy(),
            int(depth),
        )
        wall.extend(seg)  # puts the end points on the line
        extent.add(seg)
        self.restore(wall)
        self.changed.add(wall.id)
        self.next_id += 1
        return wall


def _seen_through(wall: Wall, ends: Array) -> float:
    """Share of a stretch of ``wall``'s line (two map points) that rays crossed repeatedly."""
    gap = wall.extent.along(ends)
    return wall.extent.seen_through(gap.min(), gap.max())
