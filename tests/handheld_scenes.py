"""The generated handheld recordings the unit and end-to-end tests share (one kitchen, 3 ways).

The camera is carried 1.4 m up, pitched down 25 degrees, rolling and pitching 10 degrees either
way and rising and falling 0.2 m; the trajectory is recorded in a frame tilted 30 degrees from
level whose floor lies 1.3 m below its origin; counters with appliances stand along the walls.
"""

from __future__ import annotations

from pathlib import Path

from wallmap.config import configured
from wallmap.evaluation import MapScore, evaluate_map
from wallmap.scene import (
    SCENE_KINDS,
    Camera,
    Handheld,
    SceneInfo,
    carry_camera,
    write_handheld_recording,
)

SEED = 41
CAMERA = Camera(width=128, height=96)
HANDHELD = Handheld(frame_tilt_deg=30.0, floor_z=-1.3)
STYLES = ("camera", "robot", "tum")
TUM = configured(  # how to read the TUM folder: its camera and depth units
    f"player.source.intrinsics={[CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy]}",
    "player.source.depth_scale=1000",
)


def write_all(folder: Path) -> dict[str, SceneInfo]:
    """The kitchen recorded as a 6-DoF tf bag, a robot's bag and a TUM folder."""
    plan = SCENE_KINDS["kitchen"].plan(SEED)
    take = carry_camera(seed=SEED, n_frames=500, plan=plan, handheld=HANDHELD, camera=CAMERA)
    return {
        style: write_handheld_recording(
            folder / (style if style == "tum" else f"{style}.bag"), take, style
        )
        for style in STYLES
    }


def score(info: SceneInfo, reply_walls) -> MapScore:
    """The map's score against the recording's truth, printed for the log."""
    result = evaluate_map(reply_walls, info.plan, info.seen_counts)
    print(f"\n{info.path.name}: {result.summary()}")
    return result
