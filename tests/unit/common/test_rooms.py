"""Rooms and doors from a plan's true walls and the floor a robot driving its route sees.

The floor is what the detector's free rays give: from the sensor to the nearest wall that
returns depth (glass does not), every few centimetres of the route.
"""

from __future__ import annotations

import numpy as np
import pytest

from wallmap.common.free_space import FreeSpace
from wallmap.common.grid_labels import inside_polygon
from wallmap.common.rooms import (
    Opening,
    RoomsConfig,
    WallSegments,
    _crossing,
    _free_ends,
    _goes_on_along,
    _Grid,
    _joins,
    _Segments,
    door_span,
    find_rooms,
)
from wallmap.room_evaluation import iou
from wallmap.scene.floorplan import FloorPlan, Wall, free_rays, generate_floorplan, smooth_route


def _seen(plan: FloorPlan, route: np.ndarray) -> FreeSpace:
    free = FreeSpace()
    for at in route:
        free.add_rays(np.array([*at, 0.0]), np.zeros(2), free_rays(plan, at))
    return free


def _walls(walls: list[Wall]) -> list[WallSegments]:
    return [WallSegments(w.id, np.array([[w.p0, w.p1]])) for w in walls]


@pytest.mark.parametrize("seed", range(4))
def test_a_strip_of_rooms_gives_each_room_and_each_doorway(seed: int) -> None:
    plan = generate_floorplan(seed, glass_fraction=0.0)
    layout = find_rooms(_walls(list(plan.walls)), _seen(plan, smooth_route(plan.route)[::3]))
    assert len(layout.rooms) == len(plan.rooms), "no false, no split, no missed room"
    truth_of = {}
    for k, room in enumerate(layout.rooms):
        scores = [(iou(room.polygon, np.array(t.polygon)), t.id) for t in plan.rooms]
        best, truth_of[k] = max(scores)
        assert best >= 0.9
        assert room.closed
    assert len(set(truth_of.values())) == len(plan.rooms), "one to one"
    assert len(layout.doors) == len(plan.doors)
    for door in plan.doors:
        centre, width = np.add(door.p0, door.p1) / 2, np.hypot(*np.subtract(door.p1, door.p0))
        found = min(layout.doors, key=lambda d: np.hypot(*((d.p0 + d.p1) / 2 - centre)))
        assert np.hypot(*((found.p0 + found.p1) / 2 - centre)) < 0.1
        assert abs(np.hypot(*(found.p1 - found.p0)) - width) < 0.1
        assert sorted(truth_of[r] for r in found.rooms) == sorted(door.rooms)


def _l_room(gap: tuple[float, float] | None) -> list[Wall]:
    """An L-shaped room (8 x 6 m less a 4 x 3 m corner); its long wall split at ``gap``."""
    corners = [(0.0, 0.0), (8.0, 0.0), (8.0, 3.0), (4.0, 3.0), (4.0, 6.0), (0.0, 6.0)]
    walls = []
    for k, (p, q) in enumerate(zip(corners, corners[1:] + corners[:1], strict=True)):
        if k == 0 and gap is not None:
            walls += [Wall(10, p, (gap[0], 0.0)), Wall(11, (gap[1], 0.0), q)]
        else:
            walls.append(Wall(k, p, q))
    return walls


def test_an_l_shaped_room_is_one_closed_room_of_its_area() -> None:
    walls = _l_room(None)
    route = np.array(
        [[1.0 + 0.1 * k, 1.5] for k in range(60)] + [[2.0, 1.5 + 0.1 * k] for k in range(35)]
    )
    plan = FloorPlan(walls=tuple(walls))
    layout = find_rooms(_walls(walls), _seen(plan, route))
    assert len(layout.rooms) == 1
    assert not layout.doors
    assert layout.rooms[0].closed
    assert layout.rooms[0].area == pytest.approx(36.0, rel=0.03)


def test_a_stretch_never_seen_through_is_wall_not_a_door() -> None:
    """Glass across the band: the rays stop short of it (no return), the robot stays away."""
    walls = _l_room((3.0, 4.5))  # 1.5 m of the long wall returns nothing
    route = np.array([[1.0 + 0.1 * k, 1.5] for k in range(60)])
    plan = FloorPlan(walls=tuple(walls))
    layout = find_rooms(_walls(walls), _seen(plan, route))
    assert len(layout.rooms) == 1
    assert not layout.doors
    assert layout.rooms[0].closed, "the gap is closed as wall"


def test_an_open_plan_passage_wider_than_a_door_is_a_door_between_two_rooms() -> None:
    """Two 6 x 4 m rooms; the wall between them open over 3 m of its 4 (0.5 m each side)."""
    corners = [(0.0, 0.0), (12.0, 0.0), (12.0, 4.0), (0.0, 4.0)]
    walls = [
        Wall(k, p, q)
        for k, (p, q) in enumerate(zip(corners, corners[1:] + corners[:1], strict=True))
    ]
    walls += [Wall(4, (6.0, 0.0), (6.0, 0.5)), Wall(5, (6.0, 3.5), (6.0, 4.0))]
    route = np.array([[1.0 + 0.1 * k, 2.0] for k in range(100)])
    layout = find_rooms(_walls(walls), _seen(FloorPlan(walls=tuple(walls)), route))
    assert len(layout.rooms) == 2
    assert all(room.closed for room in layout.rooms)
    assert sorted(round(room.area) for room in layout.rooms) == [24, 24]
    (door,) = layout.doors
    assert np.hypot(*(door.p1 - door.p0)) == pytest.approx(3.0, abs=0.05)
    assert door.rooms == (0, 1)


def _two_rooms(divider: list[Wall], height: float = 4.0) -> list[Wall]:
    """Two 6 m rooms ``height`` deep side by side (x 0-12.1), divided at x = 6.05 by ``divider``.

    The divider runs down the middle of a column of cells, as a wall seldom lies on a cell's
    edge: floor right beside it, seen by rays along it, is then not the divider's own cells.
    """
    corners = [(0.0, 0.0), (12.1, 0.0), (12.1, height), (0.0, height)]
    sides = zip(corners, corners[1:] + corners[:1], strict=True)
    return [Wall(k, p, q) for k, (p, q) in enumerate(sides)] + divider


def _through_the_door(y: float) -> np.ndarray:
    """A drive from one room into the other through a door at height ``y`` of the divider."""
    return np.array(
        [[1.0 + 0.1 * k, 2.0] for k in range(40)]
        + [[5.0 + 0.3 * k, y] for k in range(7)]
        + [[7.0 + 0.1 * k, 2.0] for k in range(40)]
    )


def test_a_divider_glass_beyond_its_door_divides_and_the_door_is_where_the_robot_went() -> None:
    """Solid from the floor's edge to the door, glass from the door to the far wall (unmapped).

    The span from the solid piece's end to the far wall is 3 m, too wide for a door; the robot
    crossed its first metre, and nothing was seen through the rest.
    """
    solid, glass = Wall(4, (6.05, 0.0), (6.05, 1.0)), Wall(5, (6.05, 2.0), (6.05, 4.0), glass=True)
    plan = FloorPlan(walls=tuple(_two_rooms([solid, glass])))
    mapped = [w for w in plan.walls if not w.glass]
    layout = find_rooms(_walls(mapped), _seen(plan, _through_the_door(1.5)))
    assert sorted(round(room.area) for room in layout.rooms) == [24, 24]
    (door,) = layout.doors
    assert np.hypot(*(door.p1 - door.p0)) == pytest.approx(1.0, abs=0.2)
    assert np.mean([door.p0, door.p1], axis=0) == pytest.approx([6.05, 1.5], abs=0.15)


def test_a_patch_of_a_door_no_ray_crossed_is_still_door() -> None:
    """A 3 m divider span whose first 1.6 m is the door, the rest glass (never seen). The door
    was crossed but for 0.45 m in its middle (clutter seed 500: rays cross a door's floor
    sparsely): the door is all 1.6 m, not the 0.6 m before the patch."""
    y = np.arange(0.01, 1.6, 0.02)
    crossed = np.stack([np.full(len(y), 6.05), y], axis=1)[(y < 0.6) | (y > 1.05)]
    free = FreeSpace()
    free.add_points(np.concatenate([crossed, crossed]))  # twice: seen free
    span = Opening(4, np.array([6.05, 0.0]), np.array([6.05, 3.0]))
    p0, p1 = door_span(_Grid(free, _Segments.of([])), span, RoomsConfig().door_min)
    assert p0 == pytest.approx([6.05, 0.0])
    assert p1 == pytest.approx([6.05, 1.6], abs=0.06)


def test_a_patch_is_not_bridged_where_it_would_leave_no_wall_unseen() -> None:
    """Strip seed 2: a 3.4 m divider span, the door its first 1.6 m, the rest glass whose floor
    rays from the next room crossed. Unseen: 0.5 m after the first 0.1 m, and the last 0.2 m.
    Bridged, no unseen stretch would be left for the missing wall, and no divider; so only
    gaps up to 0.3 m are, and the 0.5 m patch stays the unseen end (the door found is wrong,
    but the span still divides the rooms)."""
    y = np.arange(0.01, 3.25, 0.02)
    crossed = np.stack([np.full(len(y), 6.05), y], axis=1)[(y < 0.1) | (y > 0.6)]
    free = FreeSpace()
    free.add_points(np.concatenate([crossed, crossed]))
    span = Opening(4, np.array([6.05, 0.0]), np.array([6.05, 3.44]))
    p0, p1 = door_span(_Grid(free, _Segments.of([])), span, RoomsConfig().door_min)
    assert [p0[1], p1[1]] == pytest.approx([0.6, 3.44], abs=0.06)


def test_a_passages_jamb_another_end_opens_onto_is_still_the_passages() -> None:
    """Open-plan seed 502: a 2.8 m passage in the divider (x = 6.05); beyond it the room's
    wall leaves the divider's foot at 45 degrees as 3 m of glass, and the solid wall after the
    glass opens onto the passage's near jamb (2.3 m), nearer than the divider's foot."""
    foot, after = (6.05, 0.0), (8.17, 2.12)
    walls = [
        Wall(0, (0.0, 0.0), foot),
        Wall(1, foot, (6.05, 1.2)),  # the divider, below the passage
        Wall(2, (6.05, 4.0), (6.05, 5.0)),  # ...and above it
        Wall(3, foot, after, glass=True),
        Wall(4, after, (12.1, 2.12)),
        Wall(5, (12.1, 2.12), (12.1, 5.0)),
        Wall(6, (12.1, 5.0), (0.0, 5.0)),
        Wall(7, (0.0, 5.0), (0.0, 0.0)),
    ]
    plan = FloorPlan(walls=tuple(walls))
    route = np.array(
        [[1.0 + 0.1 * k, 2.5] for k in range(40)]
        + [[5.0 + 0.3 * k, 2.6] for k in range(7)]
        + [[7.0 + 0.1 * k, 3.5] for k in range(40)]
    )
    layout = find_rooms(_walls([w for w in walls if not w.glass]), _seen(plan, route))
    assert len(layout.rooms) == 2, "the passage divides"
    (door,) = [d for d in layout.doors if abs(d.p0[0] - 6.05) + abs(d.p1[0] - 6.05) < 0.1]
    assert door.rooms == (0, 1)
    assert sorted([door.p0[1], door.p1[1]]) == pytest.approx([1.2, 4.0], abs=0.05)


def test_an_open_plan_passage_with_glass_beside_it_divides_two_rooms() -> None:
    """5.1 m deep rooms; the divider solid for 1 m, open for 2.8 m, then 1.3 m of glass: a
    span of 4.1 m from the solid piece's end, longer than a passage, its door by that end."""
    solid = Wall(4, (6.05, 0.0), (6.05, 1.0))
    glass = Wall(5, (6.05, 3.8), (6.05, 5.1), glass=True)
    plan = FloorPlan(walls=tuple(_two_rooms([solid, glass], height=5.1)))
    mapped = [w for w in plan.walls if not w.glass]
    layout = find_rooms(_walls(mapped), _seen(plan, _through_the_door(2.4)))
    assert sorted(round(room.area) for room in layout.rooms) == [31, 31]
    (door,) = layout.doors
    assert door.rooms == (0, 1)
    assert min(door.p0[1], door.p1[1]) == pytest.approx(1.0, abs=0.1), "from the solid piece"
    assert np.hypot(*(door.p1 - door.p0)) == pytest.approx(2.8, abs=0.3)


def test_a_span_seen_free_all_along_or_from_a_short_stub_divides_nothing() -> None:
    """The same 3 m span, crossed all along (open floor); then from a 0.5 m stub (a pillar)."""
    for divider in ([Wall(4, (6.05, 0.0), (6.05, 1.0))], [Wall(4, (6.05, 0.5), (6.05, 1.0))]):
        plan = FloorPlan(walls=tuple(_two_rooms(divider)))
        route = np.concatenate([_through_the_door(y) for y in (1.5, 2.5, 3.5)])
        layout = find_rooms(_walls(list(plan.walls)), _seen(plan, route))
        assert [round(room.area) for room in layout.rooms] == [48], divider


def test_a_span_in_line_with_a_wall_does_not_cross_it() -> None:
    """A passage between two pieces of one mapped wall (an open-plan scene, seed 501): the span
    and the far piece are in one line to rounding, and the test for crossing divided by almost
    nothing. In line is not across."""
    p = np.array([[-10.251154442329293, -10.497691235941629]])
    q = np.array([[-12.203132448423844, -8.705836259530985]])
    piece = np.array(
        [[-13.364139459202125, -7.640068006294861], [-12.203132448423844, -8.705836259530985]]
    )
    own = np.array([[-9.0, -11.6], [-10.251154442329293, -10.497691235941629]])
    across = np.array([[-11.0, -10.5], [-11.5, -8.5]])  # a wall across the span's middle
    a, b = np.array([own[0], piece[0], across[0]]), np.array([own[1], piece[1], across[1]])
    assert not _crossing(p, q, a[:2], b[:2], np.array([0]))[0]
    assert _crossing(p, q, a, b, np.array([0]))[0]


def test_an_outline_is_reused_only_for_a_room_whose_cells_did_not_change() -> None:
    plan = generate_floorplan(1, glass_fraction=0.0)
    route = smooth_route(plan.route)[::3]
    free = _seen(plan, route[: len(route) // 2])  # the robot halfway: the last room unseen
    outlines: dict = {}
    first = find_rooms(_walls(list(plan.walls)), free, outlines=outlines)
    assert len(outlines) == len(first.rooms)
    again = find_rooms(_walls(list(plan.walls)), free, outlines=outlines)
    assert [r.polygon.tolist() for r in again.rooms] == [r.polygon.tolist() for r in first.rooms]
    before = set(outlines)
    for at in route[len(route) // 2 :]:  # the rest of the drive: a room more, the last grows
        free.add_rays(np.array([*at, 0.0]), np.zeros(2), free_rays(plan, at))
    later = find_rooms(_walls(list(plan.walls)), free, outlines=outlines)
    fresh = find_rooms(_walls(list(plan.walls)), free)
    assert [r.polygon.tolist() for r in later.rooms] == [r.polygon.tolist() for r in fresh.rooms]
    assert [r.walls for r in later.rooms] == [r.walls for r in fresh.rooms]
    assert set(outlines) != before, "the grown room's outline is new"
    assert len(outlines) == len(later.rooms), "only this segmentation's rooms are kept"


def test_a_side_rooms_wall_at_its_door_does_not_cut_the_corridor() -> None:
    """A corridor 2 m wide; a side room's door in its right wall, the room's wall meeting the
    corridor's line 1.3 m past the door's jamb (the corridor's wall there unmapped: glass).
    That wall's end points across the corridor, 2 m: a door's width, but no door."""
    mapped = [
        Wall(0, (0.0, 2.0), (10.0, 2.0)),  # the corridor's left wall
        Wall(1, (0.0, 0.0), (4.0, 0.0)),  # its right wall, to the door's jamb
        Wall(2, (6.5, 0.0), (10.0, 0.0)),  # ...and on past the side room
        Wall(3, (5.3, 0.0), (5.3, -3.0)),  # the side room's walls
        Wall(4, (5.3, -3.0), (6.5, -3.0)),
        Wall(5, (6.5, -3.0), (6.5, 0.0)),
        Wall(6, (0.0, 0.0), (0.0, 2.0)),  # the corridor's ends
        Wall(7, (10.0, 0.0), (10.0, 2.0)),
    ]
    glass = Wall(8, (5.3, 0.0), (6.5, 0.0), glass=True)
    plan = FloorPlan(walls=(*mapped, glass))
    route = np.array([[0.55 + 0.1 * k, 1.05] for k in range(89)])
    layout = find_rooms(_walls(mapped), _seen(plan, route))
    ends = np.array([[1.0, 1.0], [9.0, 1.0]])
    corridor = [r for r in layout.rooms if inside_polygon(ends, r.polygon).any()]
    assert len(corridor) == 1, "one corridor, not cut at the side room's wall"
    assert inside_polygon(ends, corridor[0].polygon).all()


CORRIDOR = [(0.0, 0.05), (6.8, 0.05), (10.4, -1.63), (12.0, 2.0), (0.0, 2.0)]


def _corridor_with_a_closet(door: float = 1.0) -> tuple[FloorPlan, list[Wall]]:
    """A corridor 2 m wide, its right wall kinked by 25 degrees 6.8 m along; in that wall a
    ``door`` wide opening from x = 4 into a 1.5 x 1.5 m closet, then glass to the kink. The
    closet's walls return depth, but the map lacks them (seen only through the door), as it
    lacks the glass: the plan and the walls mapped. The right wall runs down the middle of a
    row of cells (``_two_rooms``)."""
    mapped = [
        Wall(0, (0.0, 0.05), (4.0, 0.05)),
        Wall(1, CORRIDOR[1], CORRIDOR[2]),
        Wall(2, CORRIDOR[2], CORRIDOR[3]),
        Wall(3, CORRIDOR[3], CORRIDOR[4]),
        Wall(4, CORRIDOR[4], CORRIDOR[0]),
    ]
    closet = [
        Wall(5, (4.0, 0.05), (4.0, -1.45)),
        Wall(6, (4.0, -1.45), (5.5, -1.45)),
        Wall(7, (5.5, -1.45), (5.5, 0.05)),
    ]
    glass = Wall(8, (4.0 + door, 0.05), CORRIDOR[1], glass=True)
    return FloorPlan(walls=(*mapped, *closet, glass)), mapped


def test_a_door_beside_glass_into_a_glimpse_keeps_the_glimpse_out_of_the_corridor() -> None:
    """The span from the door's jamb along the glass to the kink (2.8 m) is door and glass in
    one, and the corridor's wall goes on past it at 25 degrees: too far off the span's line
    for a passage between two pieces of one wall. Beyond the door, floor seen through it that
    makes no room (under 2.5 m^2), round whose walls the space leaks. The span divides: the
    corridor is closed, the closet not in it, and the door leads to unexplored space."""
    plan, mapped = _corridor_with_a_closet()
    route = np.array([[0.6 + 0.1 * k, 1.0] for k in range(100)])
    layout = find_rooms(_walls(mapped), _seen(plan, route))
    (corridor,) = layout.rooms
    assert corridor.closed
    assert iou(corridor.polygon, np.array(CORRIDOR)) >= 0.95
    assert not inside_polygon(np.array([[4.75, -0.7]]), corridor.polygon).any()
    (door,) = layout.doors
    assert door.rooms == (0,), "it leads to unexplored space"
    assert np.mean([door.p0, door.p1], axis=0) == pytest.approx([4.5, 0.05], abs=0.2)
    assert np.hypot(*(door.p1 - door.p0)) == pytest.approx(1.0, abs=0.3)


def test_a_crossing_narrower_than_a_door_beside_glass_is_no_door() -> None:
    """The same corridor with a 0.45 m slot for a door: under ``door_min``, no door. (With
    drifting poses two pieces of one wall can be mapped apart so that a span between them is
    crossed over such a sliver.)"""
    plan, mapped = _corridor_with_a_closet(door=0.45)
    route = np.array([[0.6 + 0.1 * k, 1.0] for k in range(100)])
    layout = find_rooms(_walls(mapped), _seen(plan, route))
    assert all(np.hypot(*(d.p1 - d.p0)) >= RoomsConfig().door_min for d in layout.doors)


def _free_ends_of(walls: list[Wall]):
    """The free ends of ``walls``, none of them free-standing."""
    segments, joint = _Segments.of(_walls(walls)), RoomsConfig().joint
    return _free_ends(segments, joint, _joins(segments, joint), np.zeros(len(segments.a), bool))


def test_only_a_span_going_on_along_a_wall_may_lead_into_a_glimpse() -> None:
    """The corridor's span above meets its wall going on at 25 degrees. One cutting a room's
    corner (window scene, seed 500: from a side wall's end where glass begins, to the end of
    the wall across the room) meets that wall at 77 degrees: what is seen beyond it is the
    room's own floor before the glass, not a space beyond a door."""
    _, mapped = _corridor_with_a_closet()
    ends = _free_ends_of(mapped)
    assert _goes_on_along(ends, Opening(0, np.array([4.0, 0.05]), np.array(CORRIDOR[1])))
    room = [Wall(0, (0.0, 0.0), (0.0, 2.0)), Wall(1, (0.7, 5.0), (8.0, 5.0))]
    ends = _free_ends_of(room)
    assert not _goes_on_along(ends, Opening(0, np.array([0.0, 2.0]), np.array([0.7, 5.0])))


def _pillar(x: float, y: float, side: float = 0.3) -> list[Wall]:
    """A square pillar with its lower left corner at (x, y): four faces, as the plan's walls."""
    c = [(x, y), (x + side, y), (x + side, y + side), (x, y + side)]
    return [Wall(20 + k, c[k], c[(k + 1) % 4]) for k in range(4)]


def test_a_pillar_in_a_room_makes_no_door_and_cuts_no_room() -> None:
    """Clutter seed 500: a pillar's two mapped faces left ends whose spans (1.7 m to the wall
    above, 1.25 m to the divider) cut a corner off the room, with two false doors. The robot
    saw round it: it stands free, and opens nothing."""
    solid = [Wall(4, (6.05, 0.0), (6.05, 0.5)), Wall(5, (6.05, 1.5), (6.05, 4.0))]
    plan = FloorPlan(walls=tuple(_two_rooms(solid) + _pillar(4.5, 2.0)))
    faces = [w for w in plan.walls if w.id in (20, 23)]  # its lower and left faces mapped
    route = np.array([[1.0 + 0.1 * k, 1.0] for k in range(100)])
    layout = find_rooms(_walls(_two_rooms(solid) + faces), _seen(plan, route))
    assert sorted(round(room.area) for room in layout.rooms) == [24, 24]
    (door,) = layout.doors
    assert door.rooms == (0, 1)


def test_a_divider_runs_along_its_own_line_to_a_leaning_wall() -> None:
    """Glass seed 501: the wall a divider meets leans, so the nearest point of it ahead of the
    divider's end (within 15 degrees) is its foot 0.3 m off the corner, in the next room. A span
    there took that room's floor for the door, and lost the divider: one room, not two. Along
    the divider's line, it meets the wall at the corner, and the door is where the robot went."""
    walls = [
        Wall(0, (0.0, 0.0), (12.1, 0.0)),
        Wall(1, (12.1, 0.0), (12.1, 4.0)),
        Wall(2, (12.1, 4.0), (6.05, 4.0)),
        Wall(3, (6.05, 4.0), (0.0, 3.4)),  # leans 5.7 degrees
        Wall(4, (0.0, 3.4), (0.0, 0.0)),
        Wall(5, (6.05, 0.0), (6.05, 1.0)),
        Wall(6, (6.05, 2.6), (6.05, 4.0), glass=True),
    ]
    route = np.array([[1.0 + 0.1 * k, 1.8] for k in range(100)])
    mapped = [w for w in walls if not w.glass]
    layout = find_rooms(_walls(mapped), _seen(FloorPlan(walls=tuple(walls)), route))
    assert sorted(round(room.area) for room in layout.rooms) == [22, 24]
    (door,) = layout.doors
    assert door.p0 == pytest.approx([6.05, 1.0], abs=0.05)
    assert door.p1 == pytest.approx([6.05, 2.6], abs=0.25)


def test_a_span_ends_at_the_corner_not_on_the_face_beside_it() -> None:
    """Clutter seed 500: the top wall kinks up where glass begins. Along the solid piece, the
    nearest point of the wall ahead is on its face, 0.5 m below the corner: a span there cut a
    sliver of seen floor off the room, and its edge was served as a door to nowhere. The corner
    is as near within 20 cm: the span ends there, along the glass, and is no door."""
    walls = [
        Wall(0, (0.0, 0.0), (8.0, 0.0)),
        Wall(1, (8.0, 0.0), (8.0, 4.5)),
        Wall(2, (8.0, 4.5), (5.8, 4.0), glass=True),
        Wall(3, (5.8, 4.0), (0.0, 4.0)),
        Wall(4, (0.0, 4.0), (0.0, 0.0)),
    ]
    route = np.array([[1.0 + 0.1 * k, 2.0] for k in range(60)])
    mapped = [w for w in walls if not w.glass]
    layout = find_rooms(_walls(mapped), _seen(FloorPlan(walls=tuple(walls)), route))
    (room,) = layout.rooms
    assert not layout.doors, [(d.p0, d.p1, d.rooms) for d in layout.doors]
    assert room.area == pytest.approx(32.55, rel=0.03)
