"""What the mapper's threads share: the mapping, its pose buffer and each run's progress, locked.

Pure: no Zenoh. The intake (``services.mapper.intake``) folds frames in under its lock, the
service's threads add poses and answer queries from it; ``reply`` encodes a map state once for
every client that asks for it.
"""

from __future__ import annotations

import json
import threading
import uuid
from collections.abc import Iterable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from wallmap.common.codec import encode_as
from wallmap.common.frame_order import RunProgress
from wallmap.common.map_query import MapQuery
from wallmap.common.messages import Progress
from wallmap.services.mapper import serving
from wallmap.services.mapper.mapping import Mapping
from wallmap.services.mapper.pose_buffer import Lookup, SourcePose
from wallmap.services.mapper.wall_map import WallMap

if TYPE_CHECKING:  # the counters are the service's; any object with their methods will do
    from wallmap.common.runtime import Stats

UPDATE_FRAMES = 5  # frames integrated that make an update due sooner (a bag played --fast)
LATENCY_WAIT = 0.5  # s a frame waits for the pose its latency asks for, before extrapolating
# Why a frame was dropped, as counted and served (``dropped_reasons``).
DROP_REASONS = {Lookup.WAIT: "pose_timeout", Lookup.MISSING: "no_pose"}
BACKLOG = "backlog"  # dropped because MAX_PENDING newer frames wait for poses too


class MapperCore:
    """The mapping, the pose buffer and per-run counters behind one lock, shared by the workers.

    The mapping is the mapper's estimation (``services.mapper.mapping.Mapping``): the map, the
    pose judge or, under ``--slam``, the pose correction, and the rooms.
    """

    def __init__(self, mapping: Mapping, stats: Stats, runs: Iterable[Progress] = ()) -> None:
        self.mapping = mapping
        self.corrector = mapping.corrector  # --slam
        self.judge = mapping.judge  # every pose judged against the walls (the default)
        self.poses = mapping.poses
        # What the judge found of the pose source, for `wallmap status`: replaced (never
        # changed in place) after each frame, so the status queryable reads it without a lock.
        self.pose_source: dict[str, Any] = {} if self.judge is None else self.judge.summary()
        self.stats = stats
        self.lock = threading.Condition()
        self.poses_added = 0  # poses received: an intake waiting for one waits for it to change
        self.dirty = False
        # Set once UPDATE_FRAMES frames were integrated since the last map update (the map's
        # count of frames then): a bag played --fast goes through hundreds of frames a second,
        # and the odometry holds its poses onto the walls of those updates (every
        # UPDATE_PERIOD alone, it would see 150 frames old ones).
        self.update_due = threading.Event()
        self.updated_frames = self.map.frames
        # Whether anything subscribes to the map updates (Zenoh's matching status, set from its
        # callback): with nobody listening the changes wait, unbuilt, for the next one that does.
        self.updates_wanted = True
        # Each run's progress, with this process's epoch in every acknowledgement.
        self.progress = RunProgress(runs, epoch=uuid.uuid4().hex[:12])
        self._replies: dict[tuple[object, ...], bytes] = {}  # encoded, for one map state

    @property
    def map(self) -> WallMap:
        """The wall map (the mapping's: a remap replaces it)."""
        return self.mapping.map

    def source_pose(self, stamp: float, waited: float) -> SourcePose | Lookup:
        """The source's pose for the instant ``stamp``, at the stamp its latency says.

        A latency estimate may ask for a pose the source has not sent (yet, or ever, at the
        end of a run), and a stamp past the newest pose waits for the next: after
        LATENCY_WAIT the newest is carried on to it, up to the mapping's lookahead. Call with
        the lock held.
        """
        return self.mapping.source_pose(stamp, carry=waited >= LATENCY_WAIT)

    def reply(self, query: MapQuery, fmt: str) -> bytes:
        """The encoded map reply plus the mapper's counters, built once per map state.

        Many clients polling a map that does not change then cost one encoding between them.
        """
        counts = self.stats.snapshot()
        extra: dict[str, object] = {
            "dropped": counts.get("dropped", 0),
            "dropped_reasons": {
                reason: counts.get(f"dropped.{reason}", 0)
                for reason in (*DROP_REASONS.values(), BACKLOG)
            },
            "refused": counts.get("refused", 0),
            "skipped": counts.get("skipped", 0),
            "lost": counts.get("lost", 0),
            "missed": {what: counts.get(f"missed.{what}", 0) for what in ("observations", "poses")},
        }
        with self.lock:
            if self.corrector is not None:
                extra["slam"] = self.corrector.summary()
            if self.judge is not None:
                extra["pose_source"] = self.pose_source
            state = (self.map.version, len(self.map.merges), json.dumps(extra))
            if self._replies and next(iter(self._replies))[0] != state:
                self._replies.clear()
            key = (state, query, fmt)
            if key not in self._replies:
                body = replace(serving.reply(self.map, query), counters=extra).to_map()
                self._replies[key] = encode_as(body, fmt)
            return self._replies[key]
