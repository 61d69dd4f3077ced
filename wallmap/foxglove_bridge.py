"""Wallmap's messages as Foxglove messages, so Foxglove's 3D panel draws a run.

Pure conversion, no Zenoh: :class:`Bridge` takes decoded wallmap messages (poses, observations,
map replies and updates) and returns the Foxglove messages to log, each with its topic and its
log time (the wallmap message's stamp). ``wallmap record`` writes them to an MCAP file and
``wallmap foxglove`` serves them live (``wallmap/foxglove_cli.py``). Importing this module needs
the ``foxglove`` extra (``foxglove-sdk``). Topics and schemas: ``docs/foxglove.md``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from typing import Any, NamedTuple

from foxglove import Context
from foxglove.channels import (
    FrameTransformsChannel,
    PoseInFrameChannel,
    PosesInFrameChannel,
    SceneUpdateChannel,
)
from foxglove.messages import (
    Color,
    FrameTransform,
    FrameTransforms,
    KeyValuePair,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    PoseInFrame,
    PosesInFrame,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from wallmap.common import messages, se2
from wallmap.common.map_records import MapReply, MapUpdate, WallRecord
from wallmap.services.mapper.pose_buffer import PoseBuffer

WALLS = "/wallmap/walls"
POSE = "/wallmap/pose"
TF = "/tf"
OBSERVATIONS = "/wallmap/observations"
TRAJECTORY = "/wallmap/trajectory"
ROOMS = "/wallmap/rooms"
LATCHED = (WALLS, TRAJECTORY, ROOMS)  # state, not a stream: a viewer that connects late needs it

CONFIRMED = Color(r=0.25, g=0.55, b=1.0, a=1.0)
TENTATIVE = Color(r=1.0, g=0.6, b=0.1, a=0.6)  # possible phantoms: paler, so they stand out
OBSERVED = Color(r=0.2, g=0.9, b=0.3, a=1.0)
LABEL = Color(r=0.9, g=0.9, b=0.9, a=1.0)
ROOM = Color(r=0.3, g=0.8, b=0.8, a=0.9)
OPEN_ROOM = Color(r=0.3, g=0.8, b=0.8, a=0.45)  # not closed: partly explored, drawn paler
DOOR = Color(r=1.0, g=0.3, b=0.8, a=1.0)
ROOM_HEIGHT = 0.01  # m above the floor: outlines under the walls' lines
DOOR_THICKNESS = 0.08  # m
WALL_THICKNESS = 0.05  # m
OBSERVATION_THICKNESS = 0.03  # m
OBSERVATION_HEIGHT = 0.02  # m above the walls, so a seen wall is not hidden under its map line
EARLY_FRAMES = 64  # observations kept until the first pose arrives


class Out(NamedTuple):
    """One Foxglove message to log: its topic, the message, and its log time (ns)."""

    topic: str
    message: Any
    log_time: int


def make_channels(context: Context) -> dict[str, Any]:
    """One typed channel per topic, bound to ``context`` (an MCAP writer's or a server's)."""
    return {
        WALLS: SceneUpdateChannel(WALLS, context=context),
        POSE: PoseInFrameChannel(POSE, context=context),
        TF: FrameTransformsChannel(TF, context=context),
        OBSERVATIONS: SceneUpdateChannel(OBSERVATIONS, context=context),
        TRAJECTORY: PosesInFrameChannel(TRAJECTORY, context=context),
        ROOMS: SceneUpdateChannel(ROOMS, context=context),
    }


def nanoseconds(stamp: float) -> int:
    """Seconds as integer nanoseconds, as exact as the double (``stamp * 1e9`` loses ~100 ns)."""
    sec = math.floor(stamp)
    return sec * 1_000_000_000 + round((stamp - sec) * 1e9)


def timestamp(ns: int) -> Timestamp:
    """Foxglove's timestamp of ``ns`` nanoseconds since the epoch."""
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def yaw_quaternion(yaw: float) -> Quaternion:
    """The rotation by ``yaw`` about z: wallmap's poses are planar."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def foxglove_pose(x: float, y: float, yaw: float) -> Pose:
    """A planar pose as Foxglove's 3-D pose, on the floor (z = 0)."""
    return Pose(position=Vector3(x=x, y=y, z=0.0), orientation=yaw_quaternion(yaw))


def pose_in_frame(pose: messages.Pose) -> PoseInFrame:
    """The robot pose, drawn as an arrow in the map frame."""
    return PoseInFrame(
        timestamp=timestamp(nanoseconds(pose.stamp)),
        frame_id=pose.frame,
        pose=foxglove_pose(pose.x, pose.y, pose.yaw),
    )


def frame_transforms(pose: messages.Pose) -> FrameTransforms:
    """The pose as the transform map -> base_link, so the 3D panel can follow the robot."""
    return FrameTransforms(
        transforms=[
            FrameTransform(
                timestamp=timestamp(nanoseconds(pose.stamp)),
                parent_frame_id=pose.frame,
                child_frame_id=pose.child,
                translation=Vector3(x=pose.x, y=pose.y, z=0.0),
                rotation=yaw_quaternion(pose.yaw),
            )
        ]
    )


def trajectory(keyframes: Sequence[Sequence[float]], frame: str = "map") -> PosesInFrame:
    """The mapper's keyframes ``[[stamp, x, y, yaw], ...]`` as one path, stamped by the last."""
    return PosesInFrame(
        timestamp=timestamp(nanoseconds(keyframes[-1][0])),
        frame_id=frame,
        poses=[foxglove_pose(x, y, yaw) for _, x, y, yaw in keyframes],
    )


def _text(value: object) -> str:
    """A metadata value as text; booleans as in the JSON map reply."""
    return str(value).lower() if isinstance(value, bool) else str(value)


def _line_list(
    segments: Iterable[Sequence[Sequence[float]]], color: Color, thickness: float, z: float = 0.0
) -> LinePrimitive:
    points = [Point3(x=float(x), y=float(y), z=z) for segment in segments for x, y in segment]
    return LinePrimitive(
        type=LinePrimitiveLineType.LineList, points=points, color=color, thickness=thickness
    )


def _label(x: float, y: float, text: str, size: float, color: Color) -> TextPrimitive:
    """A label on the floor at (x, y), facing the viewer, the same size at any zoom."""
    return TextPrimitive(
        pose=foxglove_pose(x, y, 0.0),
        billboard=True,
        font_size=size,
        scale_invariant=True,
        color=color,
        text=text,
    )


def wall_entity(wall: WallRecord, ns: int, frame: str = "map") -> SceneEntity:
    """One wall of a map reply or update: its segments, its id as a label and as metadata.

    Tentative walls get their own colour: they are served only on request, and may be phantoms.
    """
    (x0, y0), (x1, y1) = wall.p0, wall.p1
    keys = ("id", "u", "v", "n_obs", "n_views", "tentative", "first_seen", "last_seen")
    colour, record = TENTATIVE if wall.tentative else CONFIRMED, wall.to_map()
    return _entity(
        f"wall/{wall.id}",
        ns,
        frame,
        {k: record[k] for k in keys},
        [_line_list(wall.segments, colour, WALL_THICKNESS)],
        [_label((x0 + x1) / 2.0, (y0 + y1) / 2.0, str(wall.id), 14.0, LABEL)],
    )


def _entity(
    entity_id: str,
    ns: int,
    frame: str,
    numbers: dict[str, Any],
    lines: list[LinePrimitive],
    texts: list[TextPrimitive] | None = None,
) -> SceneEntity:
    """One entity: its id, its lines and labels, and its numbers as metadata (shown on click)."""
    return SceneEntity(
        timestamp=timestamp(ns),
        frame_id=frame,
        id=entity_id,
        metadata=[KeyValuePair(key=k, value=_text(v)) for k, v in numbers.items()],
        lines=lines,
        texts=texts or [],
    )


def walls_scene(walls: Iterable[WallRecord], ns: int, frame: str = "map") -> SceneUpdate:
    """The whole map as one scene update.

    It deletes every entity first and then draws every wall, so each message stands alone:
    Foxglove shows the right map after a seek, and a viewer that connects late needs one message.
    """
    return SceneUpdate(
        deletions=[SceneEntityDeletion(timestamp=timestamp(ns), type=SceneEntityDeletionType.All)],
        entities=[wall_entity(w, ns, frame) for w in sorted(walls, key=lambda w: w.id)],
    )


def observations_scene(obs: messages.Observations, pose: messages.Pose) -> SceneUpdate:
    """One frame's observed segments, moved into the map frame with ``pose``.

    One entity, replaced by the next frame's, so the panel shows what the detector sees now.
    """
    segments = [se2.transform_points((w.p0, w.p1), pose.vector) for w in obs.walls]
    ns = nanoseconds(obs.stamp)
    return SceneUpdate(
        entities=[
            SceneEntity(
                timestamp=timestamp(ns),
                frame_id=pose.frame,
                id="observations",
                metadata=[
                    KeyValuePair(key="run", value=obs.run),
                    KeyValuePair(key="seq", value=str(obs.seq)),
                    KeyValuePair(key="walls", value=str(len(obs.walls))),
                    KeyValuePair(key="pose_stamp", value=repr(pose.stamp)),
                ],
                lines=[_line_list(segments, OBSERVED, OBSERVATION_THICKNESS, OBSERVATION_HEIGHT)]
                if segments
                else [],
            )
        ]
    )


def room_entity(room: dict[str, Any], ns: int, frame: str = "map") -> SceneEntity:
    """A room of the rooms reply: its outline (closed loop), ``R<id> <area> m²``, its numbers."""
    points = [Point3(x=float(x), y=float(y), z=ROOM_HEIGHT) for x, y in room["polygon"]]
    keys = ("id", "area", "closed", "walls", "doors")
    cx, cy = room["centroid"]
    outline = LinePrimitive(
        type=LinePrimitiveLineType.LineLoop,
        points=points,
        color=ROOM if room["closed"] else OPEN_ROOM,
        thickness=WALL_THICKNESS,
    )
    label = f"R{int(room['id'])} {float(room['area']):.1f} m²"
    return _entity(
        f"room/{int(room['id'])}",
        ns,
        frame,
        {k: room[k] for k in keys},
        [outline],
        [_label(float(cx), float(cy), label, 16.0, ROOM)],
    )


def door_entity(door: dict[str, Any], ns: int, frame: str = "map") -> SceneEntity:
    """A door: its span from jamb to jamb, and its numbers (width, wall, the rooms it joins)."""
    keys = ("id", "width", "wall", "rooms")
    span = _line_list([(door["p0"], door["p1"])], DOOR, DOOR_THICKNESS, ROOM_HEIGHT)
    return _entity(f"door/{int(door['id'])}", ns, frame, {k: door[k] for k in keys}, [span])


def rooms_scene(body: dict[str, Any], ns: int, frame: str = "map") -> SceneUpdate:
    """The rooms reply as one scene update that stands alone, as ``walls_scene`` does.

    Raises KeyError, TypeError or ValueError for a reply without the contract's fields.
    """
    return SceneUpdate(
        deletions=[SceneEntityDeletion(timestamp=timestamp(ns), type=SceneEntityDeletionType.All)],
        entities=[room_entity(r, ns, frame) for r in body["rooms"]]
        + [door_entity(d, ns, frame) for d in body["doors"]],
    )


class Bridge:
    """Wallmap messages in, Foxglove messages out, keeping what the conversion needs to know.

    It holds the map (the latest record of each wall, as a map update says to rebuild it) so
    every wall-map message is the whole map, and recent poses so an observation is drawn where
    the robot was at its stamp. Not thread-safe: one thread feeds it.
    """

    def __init__(self) -> None:
        self.walls: dict[int, WallRecord] = {}
        self.frame = "map"
        self.latest: dict[str, Out] = {}  # the last message of each LATCHED topic
        self._poses = PoseBuffer()
        self._last_pose: messages.Pose | None = None
        # Frames come before the first pose when the pose and the detector race: held for it.
        self._early: deque[messages.Observations] = deque(maxlen=EARLY_FRAMES)

    def _emit(self, topic: str, message: Any, ns: int) -> Out:
        out = Out(topic, message, ns)
        if topic in LATCHED:
            self.latest[topic] = out
        return out

    def map_reply(self, reply: MapReply) -> list[Out]:
        """The map as first fetched (with ``trajectory=true``): the walls and the path so far."""
        self.frame = reply.frame
        self.walls = {w.id: w for w in reply.walls}
        out = []
        keyframes = reply.trajectory or ()
        if keyframes:
            path = trajectory(keyframes, self.frame)
            out.append(self._emit(TRAJECTORY, path, nanoseconds(keyframes[-1][0])))
        if reply.stamp is not None and self.walls:
            out.append(self._walls(reply.stamp))
        return out

    def map_update(self, update: MapUpdate) -> list[Out]:
        """A map update: keep the latest record per id, drop the merged ids, send the whole map."""
        for wall in update.walls:
            self.walls[wall.id] = wall
        for gone in update.removed:
            self.walls.pop(gone, None)
        stamp = update.stamp if update.stamp is not None else 0.0
        return [self._walls(stamp)]

    def _walls(self, stamp: float) -> Out:
        ns = nanoseconds(stamp)
        return self._emit(WALLS, walls_scene(self.walls.values(), ns, self.frame), ns)

    def rooms(self, body: dict[str, Any]) -> list[Out]:
        """The rooms reply (fetched, or from ``map/rooms/updates``): every room and door again.

        Raises KeyError, TypeError or ValueError for a reply without the contract's fields.
        """
        stamp = body.get("stamp")
        ns = nanoseconds(float(stamp) if stamp is not None else 0.0)
        return [self._emit(ROOMS, rooms_scene(body, ns, str(body.get("frame", self.frame))), ns)]

    def pose(self, pose: messages.Pose) -> list[Out]:
        """A robot pose: as a pose (an arrow) and as the transform map -> base_link."""
        self._poses.add(pose)
        self._last_pose = pose
        ns = nanoseconds(pose.stamp)
        out = [
            self._emit(POSE, pose_in_frame(pose), ns),
            self._emit(TF, frame_transforms(pose), ns),
        ]
        while self._early:
            out += self.observations(self._early.popleft())
        return out

    def observations(self, obs: messages.Observations) -> list[Out]:
        """A frame's observations, placed with the pose at their stamp.

        When no pose covers the stamp yet (a pose source that lags), the latest pose stands in;
        before any pose there is nowhere to draw them: the latest ``EARLY_FRAMES`` wait for it.
        """
        pose = self._poses.lookup(obs.stamp)
        if not isinstance(pose, messages.Pose):
            pose = self._last_pose
        if pose is None:
            self._early.append(obs)
            return []
        return [self._emit(OBSERVATIONS, observations_scene(obs, pose), nanoseconds(obs.stamp))]
