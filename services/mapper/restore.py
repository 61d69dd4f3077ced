"""The mapper's state across restarts: the core restored from its state file, and saved.

The map, each run's progress, what the pose judge learnt of the source (or the ``--slam``
correction) and the rooms' ids go in one file (``state_file``); an entry that cannot be used
stops the mapper with one line that says which and what to do. Pure: no Zenoh.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from wallmap.services.mapper import state_file
from wallmap.services.mapper.core import MapperCore
from wallmap.services.mapper.mapping import Mapping
from wallmap.services.mapper.pose_buffer import PoseBuffer
from wallmap.services.mapper.pose_correction import PoseCorrector
from wallmap.services.mapper.pose_judge import PoseJudge
from wallmap.services.mapper.settings import MapperSettings
from wallmap.services.mapper.wall_map import WallMap

if TYPE_CHECKING:
    from wallmap.common.runtime import Stats

T = TypeVar("T")


def restore(mapper: MapperSettings, stats: Stats, log: logging.Logger) -> MapperCore:
    """The map, each run's progress and the pose correction, from the state file if there is one."""
    wall_map = state_file.load(mapper.state, mapper.map) if mapper.state else WallMap(mapper.map)
    if wall_map.walls:
        log.info("loaded %d walls from %s", len(wall_map.walls), mapper.state)
    runs = state_file.load_runs(mapper.state) if mapper.state else []
    corrector = _corrector(mapper)
    if corrector is not None:
        corrector.check(wall_map)
    judge = judge_of(mapper) if corrector is None else None
    mapping = Mapping(
        judge=mapper.judge,
        wall_map=wall_map,
        corrector=corrector,
        judged=judge,
        poses=PoseBuffer(mapper.poses),
    )
    saved_rooms = state_file.load_entry(mapper.state, "rooms") if mapper.state else None
    if saved_rooms is not None:
        try:
            mapping.rooms.restore(saved_rooms)
        except ValueError as err:
            msg = f"state file {mapper.state} has an unusable 'rooms' entry ({err}); move it away"
            raise state_file.StateError(msg) from err
    return MapperCore(mapping, stats, runs)


def _corrector(mapper: MapperSettings) -> PoseCorrector | None:
    """The pose correction of ``--slam``, from the state file when it has one."""
    if not mapper.slam.enabled:
        return None
    return _restored(
        mapper,
        "slam",
        lambda: PoseCorrector(mapper.slam),
        lambda saved: PoseCorrector.from_json(saved, mapper.slam),
    )


def judge_of(mapper: MapperSettings) -> PoseJudge | None:
    """The pose judge, from the state file when it has one (what it learnt of the source)."""
    if not mapper.judge.enabled:
        return None
    return _restored(
        mapper,
        "poses",
        lambda: PoseJudge(mapper.judge),
        lambda saved: PoseJudge.from_json(saved, mapper.judge),
    )


def _restored(
    mapper: MapperSettings,
    entry: str,
    fresh: Callable[[], T],
    restore: Callable[[dict[str, Any]], T],
) -> T:
    """A state file's ``entry`` restored, or ``fresh()`` without one; one line if unusable."""
    saved = state_file.load_entry(mapper.state, entry) if mapper.state else None
    if saved is None:
        return fresh()
    try:
        return restore(saved)
    except (KeyError, TypeError, ValueError) as err:
        msg = f"state file {mapper.state} has an unusable {entry!r} entry ({err}); move it away"
        raise state_file.StateError(msg) from err


def save(core: MapperCore, path: Path | None, config: dict[str, Any] | None) -> None:
    """Write the state file if the map changed since the last save (the lock held to read it)."""
    if path is None:
        return
    with core.lock:
        if not core.dirty:
            return
        slam = core.corrector.to_json() if core.corrector is not None else None
        poses = core.judge.to_json() if core.judge is not None else None
        runs = core.progress.runs.values()
        rooms = core.mapping.rooms.to_json()
        document = state_file.to_json(core.map, runs, slam, config, poses, rooms)
        core.dirty = False
    state_file.write(path, document)
