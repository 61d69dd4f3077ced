"""The live map as the page sees it: the mapper's walls, trajectory, newest pose and observations.

Every change bumps a version number and stamps the walls it touched, so a page that has seen
version N asks for ``since=N`` and gets only the walls that changed and the ids that went; with
thousands of walls and a map that changes every half second, that keeps each poll small. The
state is fed by the Zenoh threads of :mod:`wallmap.view.server` and read by the HTTP threads,
behind one lock.
"""

from __future__ import annotations

import bisect
import math
import threading
from collections import deque
from collections.abc import Iterable
from typing import Any

from wallmap.common import se2
from wallmap.common.map_records import MapReply, MapUpdate, WallRecord
from wallmap.common.messages import Observations, Pose

POSES_KEPT = 256  # recent poses, to place each observation with the pose nearest its stamp


def _pose_json(pose: Pose) -> dict[str, float]:
    return {"stamp": pose.stamp, "x": pose.x, "y": pose.y, "yaw": pose.yaw}


def _pose_at(poses: deque[Pose], stamp: float) -> Pose | None:
    """The pose at ``stamp`` between the two kept around it, else the nearest kept one."""
    if not poses:
        return None
    stamps = [p.stamp for p in poses]
    i = bisect.bisect_left(stamps, stamp)
    if i == len(poses) or (i == 0 and stamps[0] != stamp):
        return poses[min(i, len(poses) - 1)]
    after = poses[i]
    if after.stamp == stamp:
        return after
    return poses[i - 1].towards(after, stamp)


class LiveMap:
    """The map, versioned per wall, its rooms, the newest pose and observations. Thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.version = 0
        self._walls: dict[int, WallRecord] = {}
        self._changed: dict[int, int] = {}  # wall id -> version of its last change
        self._removed: dict[int, int] = {}  # wall id -> version it went at
        self._trajectory: list[list[float]] = []
        self._trajectory_version = 0
        self._counts: dict[str, Any] = {"frames": 0, "observations": 0, "stamp": None}
        self._reply_frames = -1  # frames behind the last full reply: older updates are stale
        self._poses: deque[Pose] = deque(maxlen=POSES_KEPT)
        self._observations: Observations | None = None
        self._status: str | None = "waiting for the mapper"
        self._rooms: dict[str, Any] = {"rooms": [], "doors": []}
        self._rooms_version = 0

    # --- feeding -----------------------------------------------------------------------------

    def replace(self, reply: MapReply) -> None:
        """Take a whole map reply (with ``tentative=true``): walls not in it are gone."""
        walls = {w.id: w for w in reply.walls}
        trajectory = [list(p) for p in reply.trajectory or ()]
        counts = {"frames": reply.frames, "observations": reply.observations, "stamp": reply.stamp}
        with self._lock:
            version = self.version + 1
            changed = self._store(walls.values(), version)
            for wall_id in set(self._walls) - set(walls):
                self._drop(wall_id, version)
                changed = True
            if trajectory != self._trajectory:
                self._trajectory = trajectory
                self._trajectory_version = version
                changed = True
            changed |= self._count(counts)
            self._reply_frames = self._counts["frames"]
            if changed:
                self.version = version

    def apply_update(self, update: MapUpdate) -> bool:
        """Fold in a ``map/updates`` message; False when it predates the last full reply.

        An update queued while a full query ran can be older than that reply; applying it would
        put back walls as they were, so it is skipped (its changes are in the reply already).
        """
        counts = {"frames": update.frames, "stamp": update.stamp}
        with self._lock:
            if update.frames < self._reply_frames:
                return False
            version = self.version + 1
            changed = self._store(update.walls, version)
            for wall_id in update.removed:
                if wall_id in self._walls:
                    self._drop(wall_id, version)
                    changed = True
            changed |= self._count(counts)
            if changed:
                self.version = version
            return True

    def set_rooms(self, body: dict[str, Any]) -> None:
        """Take the mapper's rooms and doors (``map/rooms`` or its updates), whole."""
        rooms = {"rooms": list(body.get("rooms", ())), "doors": list(body.get("doors", ()))}
        with self._lock:
            if rooms != self._rooms:
                self.version += 1
                self._rooms, self._rooms_version = rooms, self.version

    def add_pose(self, pose: Pose) -> None:
        """Keep a pose in its place by stamp; when full, the oldest makes room.

        A player sends each frame's own pose after the poses ahead of it: late ones are common.
        """
        with self._lock:
            if self._poses and pose.stamp < self._poses[-1].stamp:
                if pose.stamp < self._poses[0].stamp:
                    return  # older than all kept: the oldest would be dropped for it anyway
                if len(self._poses) == self._poses.maxlen:
                    self._poses.popleft()
                stamps = [p.stamp for p in self._poses]
                self._poses.insert(bisect.bisect(stamps, pose.stamp), pose)
            else:
                self._poses.append(pose)

    def set_observations(self, observations: Observations) -> None:
        """Keep the detector's newest frame (placed in the map when it is read)."""
        with self._lock:
            self._observations = observations

    def set_status(self, status: str | None) -> None:
        """What keeps the map from being current (no mapper, ...), or None when all is well."""
        with self._lock:
            self._status = status

    def _store(self, walls: Iterable[WallRecord], version: int) -> bool:
        changed = False
        for wall in walls:
            if self._walls.get(wall.id) != wall:
                self._walls[wall.id] = wall
                self._changed[wall.id] = version
                self._removed.pop(wall.id, None)  # a restarted mapper reuses ids
                changed = True
        return changed

    def _drop(self, wall_id: int, version: int) -> None:
        del self._walls[wall_id]
        del self._changed[wall_id]
        self._removed[wall_id] = version

    def _count(self, counts: dict[str, Any]) -> bool:
        changed = any(self._counts.get(k) != v for k, v in counts.items())
        self._counts.update(counts)
        return changed

    # --- reading -----------------------------------------------------------------------------

    def delta(self, since: int) -> dict[str, Any]:
        """What changed after version ``since``: the body of ``GET /api/map?since=N``.

        ``full`` is true for ``since=0`` and for a version this server never gave out (a page
        left open across a restart of the view): then ``walls`` is the whole map.
        """
        with self._lock:
            full = since <= 0 or since > self.version
            if full:
                walls = [w.to_map() for w in self._walls.values()]
                removed: list[int] = []
            else:
                walls = [self._walls[i].to_map() for i, v in self._changed.items() if v > since]
                removed = [i for i, v in self._removed.items() if v > since]
            body: dict[str, Any] = {
                "version": self.version,
                "full": full,
                **self._counts,
                "walls": walls,
                "removed": removed,
            }
            if full or self._trajectory_version > since:
                body["trajectory"] = self._trajectory
            if full or self._rooms_version > since:
                body["rooms"] = self._rooms
            return body

    def latest(self) -> dict[str, Any]:
        """The newest pose and the detector's newest walls placed in the map: ``/api/latest``.

        ``recent`` is the path of the kept poses after the trajectory's last keyframe, so the
        page draws the trajectory up to the robot between two queries of the map.

        The observations are placed with the pose at their stamp, interpolated between the kept
        poses around it (the nearest where none is on one side): the poses run ahead of the
        frames, and a fast playback may have its frame's own pose dropped on the way.
        """
        with self._lock:
            pose = self._poses[-1] if self._poses else None
            obs = self._observations
            near = _pose_at(self._poses, obs.stamp) if obs else None
            status = self._status
            last = self._trajectory[-1][0] if self._trajectory else -math.inf
            recent = [[p.x, p.y] for p in self._poses if p.stamp > last]
        placed = None
        if obs is not None:
            placed = {"stamp": obs.stamp, "seq": obs.seq, "pose": None, "walls": []}
            if near is not None:
                placed["pose"] = _pose_json(near)
                for w in obs.walls:
                    p0, p1 = se2.transform_points((w.p0, w.p1), near.vector).tolist()
                    placed["walls"].append({"p0": p0, "p1": p1})
        return {
            "pose": _pose_json(pose) if pose else None,
            "recent": recent,
            "observations": placed,
            "status": status,
        }
