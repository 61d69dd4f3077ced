"""An offline tf tree built from a bag's /tf and /tf_static, answering lookups like tf2.

The player needs two kinds of lookups per sensor frame: the robot pose (map -> base_link through
odom) and the sensor mounting (base_link -> camera). Bags are read once up front, so samples are
kept per edge in sorted numpy arrays and found with ``np.searchsorted``; lookups then cost a few
microseconds per edge, which keeps 10^5 of them well under a second per edge on the chain.
"""

import math
from collections import deque
from typing import Any

import numpy as np

from wallmap.common.pose3d import Quaternion, Vector3, slerp, transform_matrix
from wallmap.common.pose3d import invert as _inverse
from wallmap.common.pose3d_batch import invert_many, slerp_many, transform_matrices

__all__ = ["TfBuffer", "TfError", "normalize_frame", "transform_matrix"]


class TfError(LookupError):
    """A tf lookup that cannot be answered: unknown frame, no path, or extrapolation."""


def normalize_frame(frame: str) -> str:
    """Strip the leading '/' that ROS 1 frame names often carry, so '/odom' == 'odom'."""
    return frame.lstrip("/")


class _Edge:
    """The transform parent <- child: one fixed sample (static) or samples over time (dynamic)."""

    def __init__(self, parent: str, child: str, *, static: bool) -> None:
        self.parent = parent
        self.child = child
        self.static = static
        self._pending: list[tuple[float, Vector3, Quaternion]] = []
        self._stamps = np.empty(0)
        self._translations = np.empty((0, 3))
        self._quaternions = np.empty((0, 4))
        self._static_matrix: np.ndarray | None = None

    def add(self, stamp: float, translation: Vector3, quaternion: Quaternion) -> None:
        """Queue a sample; a static edge keeps only the newest, like tf2's static cache."""
        if self.static:
            self._static_matrix = transform_matrix(translation, quaternion)
        else:
            self._pending.append((stamp, translation, quaternion))

    def _freeze(self) -> None:
        """Merge queued samples into the sorted arrays; a repeated stamp keeps its last sample."""
        stamps = np.concatenate([self._stamps, [s for s, _, _ in self._pending]])
        translations = np.concatenate([self._translations, [t for _, t, _ in self._pending]])
        quaternions = np.concatenate([self._quaternions, [q for _, _, q in self._pending]])
        self._pending.clear()
        order = np.argsort(stamps, kind="stable")
        stamps = stamps[order]
        keep = np.append(stamps[1:] != stamps[:-1], True)
        self._stamps = stamps[keep]
        self._translations = translations[order][keep]
        self._quaternions = quaternions[order][keep]

    def matrix_at(self, stamp: float, tolerance: float, query: str) -> np.ndarray:
        """Return parent <- child at ``stamp``, interpolating between the bracketing samples."""
        if self._static_matrix is not None:
            return self._static_matrix
        if self._pending:
            self._freeze()
        stamps = self._stamps
        index = int(stamps.searchsorted(stamp))
        if index < stamps.size and stamps[index] == stamp:
            return self._sample(index)
        if index in {0, stamps.size}:
            first, last = float(stamps[0]), float(stamps[-1])
            gap = first - stamp if index == 0 else stamp - last
            if gap > tolerance:
                direction = "past" if index == 0 else "future"
                slack = f" (tolerance {tolerance:g} s)" if tolerance else ""
                raise TfError(
                    f"tf lookup {query} at {stamp:.6f} s would require extrapolation into the "
                    f"{direction}: edge {self.parent} -> {self.child} has data for "
                    f"[{first:.6f}, {last:.6f}] s{slack}"
                )
            return self._sample(0 if index == 0 else stamps.size - 1)
        t0, t1 = float(stamps[index - 1]), float(stamps[index])
        weight = (stamp - t0) / (t1 - t0)
        p0, p1 = self._translations[index - 1], self._translations[index]
        translation = p0 + (p1 - p0) * weight
        rotation = slerp(
            tuple(self._quaternions[index - 1].tolist()),
            tuple(self._quaternions[index].tolist()),
            weight,
        )
        return transform_matrix(tuple(translation.tolist()), rotation)

    def matrices_at(self, stamps: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
        """``matrix_at`` at many stamps: (n, 4, 4), and which are within ``tolerance``.

        Where ``matrix_at`` would raise (extrapolation beyond the tolerance), the matrix is the
        nearest sample's and the stamp is marked not found.
        """
        if self._static_matrix is not None:
            return np.broadcast_to(self._static_matrix, (len(stamps), 4, 4)), np.ones(
                len(stamps), dtype=bool
            )
        if self._pending:
            self._freeze()
        known = self._stamps
        index = known.searchsorted(stamps)
        upper = np.minimum(index, known.size - 1)
        sampled = (index == known.size) | (known[upper] == stamps) | (index == 0)
        found = ~(
            ((index == 0) & (known[0] - stamps > tolerance))
            | ((index == known.size) & (stamps - known[-1] > tolerance))
        )
        lower = np.where(sampled, upper, index - 1)
        t0, t1 = known[lower], known[upper]
        weight = np.where(sampled, 0.0, (stamps - t0) / np.where(sampled, 1.0, t1 - t0))
        p0, p1 = self._translations[lower], self._translations[upper]
        q0, q1 = self._quaternions[lower], self._quaternions[upper]
        # A sample is taken as it is; between two, the rotation along the shorter arc.
        rotation = np.where(sampled[:, None], q1, slerp_many(q0, q1, weight))
        return transform_matrices(p0 + (p1 - p0) * weight[:, None], rotation), found

    def _sample(self, index: int) -> np.ndarray:
        return transform_matrix(
            tuple(self._translations[index].tolist()), tuple(self._quaternions[index].tolist())
        )


# One step of a path: the edge, and whether it is walked child -> parent (its own direction).
_Step = tuple[_Edge, bool]


class TfBuffer:
    """All transforms of a recording, queried as ``lookup(target, source, stamp)``.

    Frames may be connected through any number of edges in either direction; the path is found
    by breadth-first search over the edges and cached until a new edge appears.
    """

    def __init__(self, *, tolerance: float = 0.0) -> None:
        """Create an empty buffer.

        Args:
            tolerance: Seconds a dynamic edge may be queried outside its recorded range, using
                its first or last sample, before the lookup raises an extrapolation TfError.
        """
        self.tolerance = tolerance
        self._edges: dict[tuple[str, str], _Edge] = {}
        self._neighbours: dict[str, list[tuple[str, _Edge, bool]]] = {}
        self._paths: dict[tuple[str, str], list[_Step]] = {}

    @property
    def frames(self) -> list[str]:
        """Every frame named by some transform, sorted."""
        return sorted(self._neighbours)

    def __bool__(self) -> bool:
        """True once any transform was added, so callers can tell "no tf at all"."""
        return bool(self._edges)

    def add_message(self, msg: Any, *, static: bool) -> tuple[list[tuple[str, float]], list[str]]:
        """Add a ``tf2_msgs/TFMessage``'s transforms.

        Returns:
            ``(added, refused)``: (child frame, stamp) of each transform added, and the reason
            for each one refused (tf2 skips unusable transforms rather than failing on them).
        """
        added, refused = [], []
        for transform in msg.transforms:
            t, q = transform.transform.translation, transform.transform.rotation
            stamp = transform.header.stamp.sec + transform.header.stamp.nanosec * 1e-9
            try:
                self.add_transform(
                    transform.header.frame_id,
                    transform.child_frame_id,
                    stamp,
                    (t.x, t.y, t.z),
                    (q.x, q.y, q.z, q.w),
                    static=static,
                )
            except TfError as err:
                refused.append(str(err))
            else:
                added.append((normalize_frame(transform.child_frame_id), stamp))
        return added, refused

    def add_transform(
        self,
        parent: str,
        child: str,
        stamp: float,
        translation: Vector3 | np.ndarray,
        quaternion: Quaternion | np.ndarray,
        *,
        static: bool,
    ) -> None:
        """Record the transform parent <- child (maps child-frame points into parent).

        Args:
            parent: Parent frame (the TransformStamped header frame_id).
            child: Child frame (child_frame_id).
            stamp: Header stamp in float seconds; ignored for static transforms.
            translation: (x, y, z) of the child origin in the parent frame.
            quaternion: (x, y, z, w) rotation of the child frame in the parent frame.
            static: True for /tf_static: the edge then holds at all times.

        Raises:
            TfError: Empty or identical frame names, or a zero quaternion.
        """
        parent, child = normalize_frame(parent), normalize_frame(child)
        if not parent or not child or parent == child:
            raise TfError(
                f"invalid tf edge {parent!r} -> {child!r}: frames must differ and be named"
            )
        qx, qy, qz, qw = (float(c) for c in quaternion)
        norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        if not norm > 1e-9:
            raise TfError(f"tf edge {parent} -> {child} at {stamp:.6f} s has a zero quaternion")
        tx, ty, tz = (float(c) for c in translation)
        edge = self._edges.get((parent, child))
        if edge is None:
            # The first sample decides the edge's kind, as tf2's frame caches do.
            edge = _Edge(parent, child, static=static)
            self._edges[(parent, child)] = edge
            self._neighbours.setdefault(parent, []).append((child, edge, False))
            self._neighbours.setdefault(child, []).append((parent, edge, True))
            self._paths.clear()
        edge.add(float(stamp), (tx, ty, tz), (qx / norm, qy / norm, qz / norm, qw / norm))

    def has_path(self, target: str, source: str) -> bool:
        """Whether ``lookup(target, source, ...)`` can find a chain of edges at all."""
        return self._path(normalize_frame(target), normalize_frame(source)) is not None

    def lookup(
        self, target: str, source: str, stamp: float, *, tolerance: float | None = None
    ) -> np.ndarray:
        """Return T_target_source, the 4x4 transform mapping ``source`` points into ``target``.

        Args:
            target: Frame the result maps into.
            source: Frame the result maps from.
            stamp: Time in float seconds; dynamic edges interpolate (linear translation, slerp).
            tolerance: Overrides the buffer's extrapolation tolerance for this lookup;
                ``math.inf`` clamps to the nearest sample.

        Returns:
            float64 4x4 homogeneous transform.

        Raises:
            TfError: Unknown frame or no path (listing the known frames), or a dynamic edge
                queried outside its recorded range by more than the tolerance.
        """
        target, source = normalize_frame(target), normalize_frame(source)
        if target == source:
            return np.eye(4)
        path = self._path(target, source)
        if path is None:
            raise TfError(self.no_path_message(target, source))
        slack = self.tolerance if tolerance is None else tolerance
        query = f"{target} <- {source}"
        result = np.eye(4)
        for edge, upward in path:
            step = edge.matrix_at(stamp, slack, query)
            result = (step if upward else _inverse(step)) @ result
        return result

    def lookup_many(
        self, target: str, source: str, stamps: np.ndarray, *, tolerance: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``lookup`` at many stamps at once: (n, 4, 4) transforms, and which stamps have one.

        A stamp ``lookup`` would refuse for extrapolation is marked not found (its matrix is
        meaningless); an unknown frame or a missing path raises TfError as ``lookup`` does.
        """
        target, source = normalize_frame(target), normalize_frame(source)
        stamps = np.asarray(stamps, dtype=np.float64)
        result = np.broadcast_to(np.eye(4), (len(stamps), 4, 4))
        found = np.ones(len(stamps), dtype=bool)
        if target == source:
            return result, found
        path = self._path(target, source)
        if path is None:
            raise TfError(self.no_path_message(target, source))
        slack = self.tolerance if tolerance is None else tolerance
        for edge, upward in path:
            step, ok = edge.matrices_at(stamps, slack)
            result = (step if upward else invert_many(step)) @ result
            found &= ok
        return result, found

    def moving_frame(self, fixed: str, sensor: str) -> str | None:
        """The frame that moves in ``fixed`` and carries ``sensor``: a pose source's child.

        On the chain from the fixed frame to the sensor, the child of the last edge that
        changes over time (``map -> camera_link`` of a handheld camera, whose
        ``camera_link -> optical`` is static); None when the two are not connected.
        """
        fixed, sensor = normalize_frame(fixed), normalize_frame(sensor)
        path = self._path(sensor, fixed)
        if not path:
            return None
        frame = fixed
        moving = None
        for edge, upward in path:
            frame = edge.parent if upward else edge.child
            if not edge.static:
                moving = frame
        return moving if moving is not None else sensor

    def _path(self, target: str, source: str) -> list[_Step] | None:
        """Edges from source to target (breadth-first, so the shortest chain), cached."""
        key = (target, source)
        if key in self._paths:
            return self._paths[key]
        if source not in self._neighbours or target not in self._neighbours:
            return None
        previous: dict[str, tuple[str, _Edge, bool] | None] = {source: None}
        queue = deque([source])
        while queue and target not in previous:
            frame = queue.popleft()
            for neighbour, edge, upward in self._neighbours[frame]:
                if neighbour not in previous:
                    previous[neighbour] = (frame, edge, upward)
                    queue.append(neighbour)
        if target not in previous:
            return None
        steps: list[_Step] = []
        frame = target
        while (link := previous[frame]) is not None:
            frame, edge, upward = link
            steps.append((edge, upward))
        steps.reverse()
        self._paths[key] = steps
        return steps

    def _component(self, frame: str) -> list[str]:
        """Frames reachable from ``frame``, sorted, to show which link is missing."""
        seen = {frame}
        queue = deque([frame])
        while queue:
            for neighbour, _, _ in self._neighbours.get(queue.popleft(), []):
                if neighbour not in seen:
                    seen.add(neighbour)
                    queue.append(neighbour)
        return sorted(seen)

    def no_path_message(self, target: str, source: str) -> str:
        """Explain why two frames are not connected, naming what each side connects to."""
        target, source = normalize_frame(target), normalize_frame(source)
        known = ", ".join(self.frames) or "none"
        parts = []
        for frame in (source, target):
            if frame not in self._neighbours:
                parts.append(f"{frame!r} is not in tf")
            else:
                parts.append(f"{frame!r} connects to [{', '.join(self._component(frame))}]")
        return (
            f"no tf path from {source!r} to {target!r}: {'; '.join(parts)} (known frames: {known})"
        )
