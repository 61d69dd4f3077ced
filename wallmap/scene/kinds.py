"""Named benchmark scenes, each hard in one way: a plan recipe and a camera.

``non-manhattan``, ``tilted`` and ``noisy`` share the plan of a seed, so comparing them
shows the effect of the camera alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from wallmap.scene.floorplan import (
    DOORWAY,
    FloorPlan,
    Layout,
    generate_floorplan,
    junction_plan,
    with_counters,
    with_windows,
)
from wallmap.scene.render import Camera


@dataclass(frozen=True)
class SceneKind:
    """How to make one kind of scene; the seed picks the scene.

    Attributes:
        name: Short name, as on the benchmark's command line.
        description: What makes the scene hard, in a phrase.
        layout: Plan layout (see :func:`generate_floorplan`).
        glass_fraction: Share of walls that are glass.
        furniture_per_room: Boxes per room, all below the detector's height band.
        pillars_per_room: Free-standing 0.3 m pillars per room (four short walls each).
        doorway: The dividers' openings, narrowest and widest (m): wider than a door, passages.
        counters: Kitchen counters with appliances on them, along walls (``with_counters``).
        windows: Walls with a 2 m glass window across the band (``with_windows``).
        junction: The plan is ``junction_plan``'s (a T at the map origin), not a generated one.
        camera: Depth camera and mount.
    """

    name: str
    description: str
    layout: Layout = "rooms"
    glass_fraction: float = 0.15
    furniture_per_room: int = 2
    pillars_per_room: int = 0
    doorway: tuple[float, float] = DOORWAY
    counters: int = 0
    windows: int = 0
    junction: bool = False
    camera: Camera = field(default_factory=Camera)

    def plan(self, seed: int) -> FloorPlan:
        """The plan of this kind for ``seed``; the same seed always gives the same plan."""
        if self.junction:
            return junction_plan(seed)
        plan = generate_floorplan(
            seed,
            layout=self.layout,
            glass_fraction=self.glass_fraction,
            furniture_per_room=self.furniture_per_room,
            pillars_per_room=self.pillars_per_room,
            doorway=self.doorway,
        )
        if self.windows:
            plan = with_windows(plan, seed, self.windows)
        return with_counters(plan, seed, self.counters) if self.counters else plan


SCENE_KINDS: dict[str, SceneKind] = {
    kind.name: kind
    for kind in (
        SceneKind("non-manhattan", "three rooms, kinked walls at any angle (the default plan)"),
        SceneKind("corridor", "long kinked corridor, narrow doors, small side rooms", "corridor"),
        SceneKind(
            "open-plan",
            "three rooms joined by 2.6-2.9 m passages, too wide for doors",
            doorway=(2.6, 2.9),
        ),
        SceneKind("glass", "45 % of the walls are glass", glass_fraction=0.45),
        SceneKind(
            "clutter",
            "6 boxes per room below the band, a 0.3 m pillar per room",
            furniture_per_room=6,
            pillars_per_room=1,
        ),
        SceneKind(
            "tilted", "default plan, camera tilted up 8 degrees", camera=Camera(tilt_deg=8.0)
        ),
        SceneKind(
            "kitchen",
            "counters along the walls with appliances standing on them, up to 1.35 m",
            counters=4,
        ),
        SceneKind(
            "window",
            "3 walls with a 2 m glass window across the band: one wall each, not two pieces",
            windows=3,
        ),
        SceneKind(
            "junction",
            "two rooms, their divider meeting the outer wall in a T at the map origin",
            junction=True,
        ),
        SceneKind(
            "pitched",
            "default plan, a 640x480 camera pitched down 10 degrees (its band adapts)",
            camera=Camera(width=640, height=480, tilt_deg=-10.0),
        ),
        SceneKind(
            "noisy",
            "default plan, twice the Kinect depth noise",
            camera=Camera(noise_k=2 * Camera().noise_k),
        ),
    )
}
