"""The messages the services exchange, with validation on the way in.

Each type converts to a plain map for :func:`wallmap.common.codec.encode` and back with
``from_map``, which refuses anything malformed or non-finite with a
:class:`~wallmap.common.codec.MessageError` naming the field. Keys and payloads are documented in
``docs/protocol.md``; ``Pose`` is the contract's ``{prefix}/pose``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from wallmap.common import se2
from wallmap.common.codec import MessageError, check_coordinates, decode, encode
from wallmap.common.fields import (
    array,
    count,
    flag,
    integer,
    listed,
    number,
    plain_matrix2,
    point,
    refusal,
    required,
    string,
    table,
)
from wallmap.common.pose3d import pose_matrix, rpy_from_quaternion

if TYPE_CHECKING:  # the fit's module loads the compiled kernels: not for every message reader
    from wallmap.common.line_fit import LineFit

Array = NDArray[np.float64]


def _covariance(value: Any, n: int, key: str) -> Array:
    """A covariance: symmetric (to rounding) and positive semi-definite."""
    cov = array(value, (n, n), key)
    size = np.abs(cov)
    # np.allclose(cov, cov.T, atol=1e-12 + 1e-9 * max |cov|) without its cost (a tenth of a
    # frame's decoding): |cov - cov.T| is symmetric, so bounding it by |cov| bounds it by |cov.T|.
    if not (np.abs(cov - cov.T) <= 1e-12 + 1e-9 * size.max() + 1e-5 * size).all():
        raise refusal(key, "symmetric", value)
    if float(np.linalg.eigvalsh(cov).min()) < -1e-12:
        raise refusal(key, "positive semi-definite", value)
    return cov


def _wall_covariance(value: Any, key: str) -> Array:
    """A wall's 2x2 covariance, checked as ``_covariance`` checks any, and non-singular.

    On plain floats, since every wall of every frame brings one: numpy's parse and checks were
    a third of decoding a frame's observations. Two rows of two floats (what every sender
    writes) are read as they are; anything else goes through numpy's parse (``array``), as
    before. The same tests on the same float64 values, in the same order of operations: the
    same matrices pass.
    """
    rows = plain_matrix2(value) or array(value, (2, 2), key).tolist()
    (a, b), (c, d) = rows
    tol = 1e-12 + 1e-9 * max(abs(a), abs(b), abs(c), abs(d))
    gap = abs(b - c)
    if not (gap <= tol + 1e-5 * abs(b) and gap <= tol + 1e-5 * abs(c)):
        raise refusal(key, "symmetric", value)
    # the smaller eigenvalue in closed form, eigvalsh's cost spared
    if 0.5 * (a + d) - math.hypot(0.5 * (a - d), c) < -1e-12:
        raise refusal(key, "positive semi-definite", value)
    if a * d - b * c <= 0.0:
        raise refusal(key, "non-singular", value)
    return np.array([[a, b], [c, d]])


def _sensor(m: dict[str, Any]) -> str:
    """Whose noise the points carry; older senders had only depth cameras."""
    value = string(m.get("sensor", "depth"), "sensor")
    if value not in ("depth", "scan"):
        raise refusal("sensor", "'depth' or 'scan'", value)
    return value


@dataclass(frozen=True, eq=False)  # array fields make generated equality ambiguous
class Pose:
    """A robot (or sensor) pose in the map frame: the contract's ``{prefix}/pose``.

    ``cov`` is the 3x3 covariance of (x, y, yaw), or None when the source gives none. ``z``,
    ``roll`` and ``pitch`` make it a 6-DoF pose (a handheld camera, a SLAM's camera pose); the
    map uses the planar part, the rest belongs with the frame's mounting (``common.pose3d``).
    """

    stamp: float
    x: float
    y: float
    yaw: float
    cov: Array | None = None
    frame: str = "map"
    child: str = "base_link"
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0

    @property
    def vector(self) -> Array:
        """(x, y, yaw) as an array."""
        return np.array([self.x, self.y, self.yaw])

    @property
    def is_planar(self) -> bool:
        """Whether it lies on the floor, level (no height, roll or pitch)."""
        return self.z == 0.0 and self.roll == 0.0 and self.pitch == 0.0

    @property
    def matrix(self) -> Array:
        """The 4x4 transform frame <- child."""
        return pose_matrix(self.x, self.y, self.z, self.roll, self.pitch, self.yaw)

    def towards(self, later: Pose, stamp: float) -> Pose:
        """The planar pose at ``stamp`` on the way to ``later``, interpolated.

        Linear in position, the yaw the short way round; the covariance of the nearer of the two.
        """
        f = (stamp - self.stamp) / (later.stamp - self.stamp)
        dyaw = se2.wrap(later.yaw - self.yaw)
        return Pose(
            stamp=stamp,
            x=self.x + f * (later.x - self.x),
            y=self.y + f * (later.y - self.y),
            yaw=se2.wrap(self.yaw + f * dyaw),
            cov=(self if f < 0.5 else later).cov,
            frame=self.frame,
            child=self.child,
        )

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding; the 6-DoF fields only when the pose has them."""
        m: dict[str, Any] = {
            "stamp": self.stamp,
            "frame": self.frame,
            "child": self.child,
            "x": self.x,
            "y": self.y,
            "yaw": self.yaw,
        }
        if not self.is_planar:
            m.update(z=self.z, roll=self.roll, pitch=self.pitch)
        if self.cov is not None:
            m["cov"] = self.cov.tolist()
        return m

    @classmethod
    def from_map(cls, m: dict[str, Any]) -> Pose:
        """Validate and build; raises MessageError.

        A quaternion ``q`` ([qx, qy, qz, qw]) defines roll, pitch and yaw; without it ``yaw`` is
        required and ``roll``, ``pitch`` (and ``z``) default to 0.
        """
        m = table(m)
        cov = m.get("cov")
        if "q" in m:
            roll, pitch, yaw = rpy_from_quaternion(_quaternion(m["q"]))
        else:
            yaw = number(required(m, "yaw"), "yaw")
            roll, pitch = number(m.get("roll", 0.0), "roll"), number(m.get("pitch", 0.0), "pitch")
        return cls(
            stamp=number(required(m, "stamp"), "stamp"),
            x=number(required(m, "x"), "x"),
            y=number(required(m, "y"), "y"),
            yaw=yaw,
            cov=None if cov is None else _covariance(cov, 3, "cov"),
            frame=string(m.get("frame", "map"), "frame"),
            child=string(m.get("child", "base_link"), "child"),
            z=number(m.get("z", 0.0), "z"),
            roll=roll,
            pitch=pitch,
        )


def _quaternion(value: Any) -> tuple[float, float, float, float]:
    q = array(value, (4,), "q")
    norm = float(np.linalg.norm(q))
    if not 0.9 < norm < 1.1:
        raise refusal("q", "a unit quaternion [qx, qy, qz, qw]", value)
    qx, qy, qz, qw = (float(v) / norm for v in q)
    return qx, qy, qz, qw


@dataclass(frozen=True)
class Frame:
    """One sensor frame: an organized cloud (h, w, 3) in the sensor frame and the sensor's mount.

    ``run`` names the player run and ``seq`` numbers its frames from 0, so the mapper can
    acknowledge them and a player in ``--fast`` mode can wait. ``sensor`` says whose noise the
    points carry: a depth camera's (``depth``, even when the player sent only the chosen row) or
    a 2-D scanner's (``scan``). ``lossless`` says the player waits for the pipeline (``--fast``):
    its frames are never skipped, however far behind a service is. ``band`` (low, high) says the
    points are the stack of that height band the player picked (``scan_row.pick_points``), not
    a whole cloud.
    """

    run: str
    seq: int
    stamp: float
    frame_id: str
    points: NDArray[np.float32]
    T_base_sensor: Array  # on the wire: base_from_sensor (docs/protocol.md)
    sensor: str = "depth"
    lossless: bool = False
    band: tuple[float, float] | None = None
    sweep: float = 0.0

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding (the points go as raw bytes)."""
        return {
            "run": self.run,
            "seq": self.seq,
            "stamp": self.stamp,
            "frame_id": self.frame_id,
            "points": self.points,
            "base_from_sensor": self.T_base_sensor,
            "sensor": self.sensor,
            "lossless": self.lossless,
            **({} if self.band is None else {"band": list(self.band)}),
            **({"sweep": self.sweep} if self.sweep else {}),
        }

    @classmethod
    def from_map(cls, m: dict[str, Any]) -> Frame:
        """Validate and build; raises MessageError."""
        m = table(m)
        points = required(m, "points")
        if (
            not isinstance(points, np.ndarray)
            or points.dtype != np.float32
            or points.ndim != 3
            or points.shape[2] != 3
            or points.shape[0] * points.shape[1] == 0
        ):
            raise refusal("points", "a float32 array of shape (rows, columns, 3)", points)
        return cls(
            run=string(required(m, "run"), "run"),
            seq=count(required(m, "seq"), "seq"),
            stamp=number(required(m, "stamp"), "stamp"),
            frame_id=string(required(m, "frame_id"), "frame_id"),
            points=points,
            T_base_sensor=array(required(m, "base_from_sensor"), (4, 4), "base_from_sensor"),
            sensor=_sensor(m),
            lossless=flag(m.get("lossless", False), "lossless"),
            band=_band(m),
            sweep=_sweep(m),
        )


def _sweep(m: dict[str, Any]) -> float:
    """The optional ``sweep``: seconds the frame's capture spans, not deskewed (0: an instant)."""
    if m.get("sweep") is None:
        return 0.0
    sweep = number(m["sweep"], "sweep")
    if not 0.0 <= sweep <= 10.0:
        raise refusal("sweep", "0-10 s", sweep)
    return sweep


def _band(m: dict[str, Any]) -> tuple[float, float] | None:
    if m.get("band") is None:
        return None
    band = array(m["band"], (2,), "band")
    if not band[0] < band[1]:
        raise refusal("band", "[low, high] with low below high", m["band"])
    return float(band[0]), float(band[1])


@dataclass(frozen=True)
class WallObservation:
    """A wall seen in one frame, in the robot's base frame.

    ``closest`` is the paper's (u, v): the closest point of the wall's line to the robot.
    """

    closest: Array
    cov: Array
    p0: Array
    p1: Array
    n_points: int
    rms: float

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding."""
        return {
            "u": float(self.closest[0]),
            "v": float(self.closest[1]),
            "cov": self.cov.tolist(),
            "p0": self.p0.tolist(),
            "p1": self.p1.tolist(),
            "n_points": self.n_points,
            "rms": self.rms,
        }

    @classmethod
    def from_fit(cls, fit: LineFit) -> WallObservation:
        """The wall a line fit found, as the detector reports it.

        One place that says which of the fit's results travel (the line, its covariance, the
        extent, the support); the rest (normal, offset, noise estimates) stays with the detector.
        The arrays are the fit's own, not copies: both are frozen, and they are packed as they are.
        """
        return cls(
            closest=fit.closest,
            cov=fit.cov,
            p0=fit.p0,
            p1=fit.p1,
            n_points=fit.n_points,
            rms=fit.rms,
        )

    @classmethod
    def from_map(cls, m: dict[str, Any]) -> WallObservation:
        """Validate and build; raises MessageError."""
        m = table(m, "walls")
        u, v = number(required(m, "u"), "u"), number(required(m, "v"), "v")
        check_coordinates((u, v), "the wall's closest point (u, v)")
        if math.hypot(u, v) < 1e-3:
            msg = "wall passes through the sensor (u = v = 0)"
            raise MessageError(msg)
        cov = _wall_covariance(required(m, "cov"), "cov")
        p0, p1 = point(required(m, "p0"), "p0"), point(required(m, "p1"), "p1")
        check_coordinates((*p0, *p1), "a segment end (p0, p1)")
        return cls(
            closest=np.array([u, v]),
            cov=cov,
            p0=np.array(p0),
            p1=np.array(p1),
            n_points=integer(required(m, "n_points"), "n_points"),
            rms=number(required(m, "rms"), "rms"),
        )


@dataclass(frozen=True)
class Observations:
    """The detector's output for one frame, also when it found no wall.

    ``lossless`` is copied from the frame. ``skipped``: the detector skipped the frame (behind in
    real-time playback); the message stands for it, so the mapper does not wait for it.
    ``rays`` is what the sensor saw through, in the base frame: the sensor's position
    ``ray_origin`` and (n, 2) points where some of its rays in the height band ended (the
    farthest return of sampled image columns). Space between them is free: a mapped wall that
    such a ray crosses well before its end was not a wall there. ``sensor`` is the frame's
    (``depth`` or ``scan``): a depth camera sees clutter in 3-D that a scanner does not.
    """

    run: str
    seq: int
    stamp: float
    frame: str
    walls: list[WallObservation] = field(default_factory=list)
    lossless: bool = False
    ray_origin: Array | None = None
    rays: Array | None = None
    sensor: str = "depth"
    skipped: bool = False
    sweep: float = 0.0

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding."""
        m = {
            "run": self.run,
            "seq": self.seq,
            "stamp": self.stamp,
            "frame": self.frame,
            "walls": [w.to_map() for w in self.walls],
            "lossless": self.lossless,
            "sensor": self.sensor,
            "skipped": self.skipped,
        }
        if self.sweep:
            m["sweep"] = self.sweep
        if self.rays is not None and self.ray_origin is not None:
            m["free"] = {"origin": self.ray_origin.tolist(), "ends": self.rays.tolist()}
        return m

    @classmethod
    def from_map(cls, m: dict[str, Any]) -> Observations:
        """Validate and build; raises MessageError."""
        m = table(m)
        walls = listed(required(m, "walls"), "walls")
        origin, rays = _free(m)
        return cls(
            run=string(required(m, "run"), "run"),
            seq=count(required(m, "seq"), "seq"),
            stamp=number(required(m, "stamp"), "stamp"),
            frame=string(m.get("frame", "base_link"), "frame"),
            walls=[WallObservation.from_map(w) for w in walls],
            lossless=flag(m.get("lossless", False), "lossless"),
            ray_origin=origin,
            rays=rays,
            sensor=_sensor(m),
            skipped=flag(m.get("skipped", False), "skipped"),
            sweep=_sweep(m),
        )


MAX_RAYS = 4096


def _free(m: dict[str, Any]) -> tuple[Array | None, Array | None]:
    """The optional ``free`` field: the rays' origin (2,) and ends (n, 2)."""
    free = m.get("free")
    if free is None:
        return None, None
    free = table(free, "free")
    ends = required(free, "ends", "free.ends")
    if not isinstance(ends, list) or len(ends) > MAX_RAYS:
        raise refusal("free.ends", f"a list of at most {MAX_RAYS} points", ends)
    origin = array(required(free, "origin", "free.origin"), (2,), "free.origin")
    return origin, array(ends, (len(ends), 2), "free.ends") if ends else np.zeros((0, 2))


@dataclass(frozen=True)
class Progress:
    """The mapper's acknowledgement of one player run: frames processed so far.

    ``epoch`` names the mapper process: a mapper restarted on its state file acknowledges less
    than the one before it did, and a player takes that (and sends again) only from a new epoch.
    """

    run: str
    processed: int
    integrated: int
    dropped: int
    epoch: str = ""

    def to_map(self) -> dict[str, Any]:
        """Plain map for encoding."""
        return {
            "run": self.run,
            "processed": self.processed,
            "integrated": self.integrated,
            "dropped": self.dropped,
            "epoch": self.epoch,
        }

    @classmethod
    def from_map(cls, m: dict[str, Any]) -> Progress:
        """Validate and build; raises MessageError."""
        m = table(m)
        return cls(
            run=string(required(m, "run"), "run"),
            processed=integer(required(m, "processed"), "processed"),
            integrated=integer(required(m, "integrated"), "integrated"),
            dropped=integer(required(m, "dropped"), "dropped"),
            epoch=string(m.get("epoch", ""), "epoch"),
        )


def pack(message: Pose | Frame | Observations | Progress) -> bytes:
    """Encode any message."""
    return encode(message.to_map())


def unpack_pose(payload: bytes) -> Pose:
    """Decode and validate a pose."""
    return Pose.from_map(decode(payload))


def unpack_frame(payload: bytes) -> Frame:
    """Decode and validate a sensor frame."""
    return Frame.from_map(decode(payload))


def unpack_observations(payload: bytes) -> Observations:
    """Decode and validate a detector output."""
    return Observations.from_map(decode(payload))


def unpack_progress(payload: bytes) -> Progress:
    """Decode and validate a mapper acknowledgement."""
    return Progress.from_map(decode(payload))
