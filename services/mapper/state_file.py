"""The mapper's state on disk: the whole map, written atomically, read back at start.

JSON, so a person can read it and a script can use it. It is written to a temporary file in the
same folder and renamed over the old one, so a crash mid-write leaves the previous state whole.
Wall ids and the next id are kept, so ids stay stable across restarts.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from wallmap.common.keyframes import Keyframe
from wallmap.common.messages import Progress
from wallmap.services.mapper.extent import Extent
from wallmap.services.mapper.map_config import MapperConfig
from wallmap.services.mapper.wall import Wall
from wallmap.services.mapper.wall_map import WallMap

STATE_VERSION = 1


class StateError(RuntimeError):
    """The state file cannot be used; the message says why, in one line."""


def to_json(
    wall_map: WallMap,
    runs: Iterable[Progress] = (),
    slam: dict[str, Any] | None = None,
    config: dict[str, Any] | None = None,
    poses: dict[str, Any] | None = None,
    rooms: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Everything needed to carry on where the map stopped.

    ``runs`` are the players' runs as far as this map has taken them: a mapper restarted on the
    file acknowledges them from there, and the players send it the rest again. ``slam``: the
    pose correction's state (``PoseCorrector.to_json``) under ``--slam``. ``poses``: what the
    pose judge found of its source (``PoseJudge.to_json``). ``rooms``: the floor seen and the
    rooms' ids (``RoomMap.to_json``). ``config``: the
    configuration the map was made with (plain values, as ``wallmap config`` prints it); kept
    for people and scripts, not read back.
    """
    return {
        "config": config,
        "slam": slam,
        "poses": poses,
        "rooms": rooms,
        "v": STATE_VERSION,
        "runs": [[r.run, r.processed, r.integrated, r.dropped] for r in runs],
        "next_id": wall_map.next_id,
        "frames": wall_map.frames,
        "observations": wall_map.observations,
        "stamp": wall_map.stamp,
        "trajectory": wall_map.path(),
        "merges": wall_map.merges,
        "walls": [
            {
                "id": w.id,
                "s": w.s.tolist(),
                "p": w.p.tolist(),
                "anchor": w.anchor.tolist(),
                "ends": w.ends.tolist(),
                "extent": w.extent.to_json(),
                "n_obs": w.n_obs,
                "depth_obs": w.depth_obs,
                "views": w.views,
                "last_view": w.last_view.tolist(),
                "first_seen": w.first_seen,
                "last_seen": w.last_seen,
            }
            for w in wall_map.walls.values()
        ],
    }


def from_json(data: dict[str, Any], config: MapperConfig) -> WallMap:
    """Rebuild a map; raises KeyError, TypeError or ValueError on a malformed document."""
    if data.get("v") != STATE_VERSION:
        msg = f"unsupported state version {data.get('v')!r}"
        raise ValueError(msg)
    wall_map = WallMap(config)
    wall_map.next_id = int(data["next_id"])
    wall_map.frames = int(data["frames"])
    wall_map.observations = int(data["observations"])
    wall_map.stamp = None if data["stamp"] is None else float(data["stamp"])
    wall_map.merges = [(int(a), int(b), float(t)) for a, b, t in data["merges"]]
    wall_map.trajectory = [
        Keyframe(float(t), float(x), float(y), float(a)) for t, x, y, a in data["trajectory"]
    ]
    for w in data["walls"]:
        wall = Wall(
            id=int(w["id"]),
            s=np.array(w["s"], dtype=float).reshape(2),
            p=np.array(w["p"], dtype=float).reshape(2, 2),
            anchor=np.array(w["anchor"], dtype=float).reshape(2),
            ends=np.array(w["ends"], dtype=float).reshape(2, 2),
            extent=Extent.from_json(w["extent"]),
            n_obs=int(w["n_obs"]),
            first_seen=float(w["first_seen"]),
            last_seen=float(w["last_seen"]),
            views=int(w["views"]),
            last_view=np.array(w["last_view"], dtype=float).reshape(3),
            depth_obs=int(w.get("depth_obs", w["n_obs"])),  # older files: as depth cameras made
        )
        if not all(np.isfinite(a).all() for a in (wall.s, wall.p, wall.anchor, wall.ends)):
            msg = f"wall {wall.id} holds non-finite numbers"
            raise ValueError(msg)
        wall_map.restore(wall)
        wall_map.next_id = max(wall_map.next_id, wall.id + 1)
    return wall_map


def write(path: Path, document: dict[str, Any]) -> None:
    """Write a state document (from :func:`to_json`) atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(document, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_runs(path: Path) -> list[Progress]:
    """The runs a state file records (none when it does not exist or predates them)."""
    if not path.exists():
        return []
    try:
        rows = json.loads(path.read_text(encoding="utf-8")).get("runs", [])
        return [Progress(str(run), int(n), int(i), int(d)) for run, n, i, d in rows]
    except (OSError, ValueError, TypeError, AttributeError) as err:
        msg = f"state file {path} has unusable runs ({type(err).__name__}: {err}); move it away"
        raise StateError(msg) from err


def load_entry(path: Path, name: str) -> dict[str, Any] | None:
    """An entry of a state file: ``slam`` (the pose correction) or ``poses`` (the pose judge).

    None: no such entry, or no file yet.
    """
    if not path.exists():
        return None
    try:
        entry = json.loads(path.read_text(encoding="utf-8")).get(name)
    except (OSError, ValueError, AttributeError) as err:
        msg = f"state file {path} is unusable ({type(err).__name__}: {err}); move it away"
        raise StateError(msg) from err
    if entry is not None and not isinstance(entry, dict):
        msg = f"state file {path} has an unusable {name!r} entry; move it away"
        raise StateError(msg)
    return entry


def load(path: Path, config: MapperConfig) -> WallMap:
    """Read the state, or start an empty map when the file does not exist yet."""
    if not path.exists():
        return WallMap(config)
    try:
        return from_json(json.loads(path.read_text(encoding="utf-8")), config)
    except (OSError, ValueError, KeyError, TypeError) as err:
        msg = f"state file {path} is unusable ({type(err).__name__}: {err}); move it away"
        raise StateError(msg) from err
