"""Pictures (PNG, SVG) and the GeoJSON export of a map reply."""

import functools
import io
import json
import time
import xml.etree.ElementTree as ET

import numpy as np
import PIL.features
import pytest
from PIL import Image, ImageFont

from wallmap import plot
from wallmap.common.map_records import MapReply
from wallmap.export import to_geojson, write_geojson

SVG = "{http://www.w3.org/2000/svg}"


def make_wall(wall_id, a, b, sigma=0.02, cov=None, segments=None):
    """A wall record as the mapper serves it, for the line through a and b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = (b - a) / np.linalg.norm(b - a)
    foot = a - (a @ d) * d  # closest point of the line to the origin
    wall = {
        "id": wall_id,
        "u": float(foot[0]),
        "v": float(foot[1]),
        "cov": (np.eye(2) * sigma**2 if cov is None else np.asarray(cov)).tolist(),
        "p0": a.tolist(),
        "p1": b.tolist(),
        "n_obs": 7,
        "first_seen": 10.0,
        "last_seen": 20.0,
    }
    if segments is not None:
        wall["segments"] = segments
    return wall


def make_reply(walls, trajectory=None):
    reply = {"v": 1, "frame": "map", "frames": 120, "observations": 400, "stamp": 20.0}
    reply |= {"walls": walls, "merges": []}
    if trajectory is not None:
        reply["trajectory"] = trajectory
    return MapReply.from_map(reply)


ROOM = [
    make_wall(0, (-4, -3), (5, -3), 0.01),
    make_wall(1, (5, -3), (5, 4), 0.03),
    make_wall(2, (5, 4), (-4, 4), 0.02, segments=[[[5, 4], [1, 4]], [[-1, 4], [-4, 4]]]),
    make_wall(3, (-4, 4), (-4, -3), 0.02),
]
TRAJECTORY = [[float(i), 0.1 * i - 2, 0.05 * i, 0.0] for i in range(40)]


def read_png(data: bytes) -> np.ndarray:
    """Decode a PNG with Pillow, checking it is one and 8-bit RGB."""
    with Image.open(io.BytesIO(data)) as image:
        assert (image.format, image.mode) == ("PNG", "RGB")
        return np.array(image)


def rgb(colour):
    return tuple(int(colour[i : i + 2], 16) for i in (1, 3, 5))


def mix(pixels, colour, under=plot.BACKGROUND):
    """How much of ``colour`` over ``under`` each pixel (..., 3) is, and how far it is off that mix.

    An anti-aliased edge of ``colour`` is a share t of it (its coverage) over what is below.
    """
    base, ink = np.array(rgb(under), float), np.array(rgb(colour), float)
    pixels = np.asarray(pixels, float)
    t = (pixels - base) @ (ink - base) / ((ink - base) @ (ink - base))
    off = np.linalg.norm(pixels - (base + t[..., None] * (ink - base)), axis=-1)
    return t, off


def test_png_is_valid_and_walls_are_where_they_should_be(tmp_path):
    reply = make_reply(ROOM, TRAJECTORY)
    path = tmp_path / "map.png"
    plot.write_png(path, reply, size=600)
    image = read_png(path.read_bytes())
    drawing = plot.render_map(reply, size=600)
    assert image.shape == (drawing.height, drawing.width, 3)
    assert max(image.shape[:2]) <= 600
    # on wall 0, away from labels; and in the middle of the room, away from everything
    for x in (-3.0, 1.0, 4.0):
        col, row = np.round(drawing.to_px([x, -3.0]) - 0.5).astype(int)
        assert tuple(image[row, col]) == rgb(plot.WALL_COLOUR)
    col, row = np.round(drawing.to_px([2.5, 2.0]) - 0.5).astype(int)
    assert tuple(image[row, col]) == rgb(plot.BACKGROUND)
    assert tuple(image[2, 2]) == rgb(plot.BACKGROUND)
    # the doorway of wall 2 is a thin gap line, not wall: across it, mostly gap colour
    col, row = np.round(drawing.to_px([0.0, 4.0]) - 0.5).astype(int)
    t, off = mix(image[row - 2 : row + 3, col], plot.GAP_COLOUR)
    assert t.max() > 0.5
    assert off.max() < 3
    # the trajectory's pixels are there
    t, off = mix(image, plot.TRAJECTORY_COLOUR)
    assert ((t > 0.5) & (off < 3)).sum() > 50


def test_png_edges_are_anti_aliased():
    diagonal = [[float(i), 0.1 * i, 0.07 * i, 0.0] for i in range(2)]  # one straight piece
    drawing = plot.render_map(make_reply([], diagonal), size=400)
    image = plot.rasterise(drawing)
    t, off = mix(image, plot.TRAJECTORY_COLOUR)
    line = off < 3  # background, trajectory, or a mix of the two: all but the start dot...
    edge = line & (t > 0.1) & (t < 0.9)
    assert edge.sum() > 30, "partly covered pixels along the line"
    # across the line, the coverage adds up to its width (a pixel and a half here)
    col = int(drawing.to_px([0.05, 0.035])[0])
    assert t[:, col][line[:, col]].sum() == pytest.approx(1.5 * np.hypot(1, 0.7), abs=0.4)


@pytest.mark.parametrize("freetype", [True, False])
def test_labels_are_drawn_at_their_points_at_their_height(monkeypatch, freetype):
    if freetype and not PIL.features.check("freetype2"):
        pytest.skip("this Pillow has no FreeType")
    monkeypatch.setattr(plot, "_font", functools.cache(plot._font.__wrapped__))  # fonts afresh
    if not freetype:  # as Pillow without FreeType: its one bitmap font
        monkeypatch.setattr(plot.features, "check", lambda name: False)
        monkeypatch.setattr(
            ImageFont, "load_default", lambda size=None: ImageFont.load_default_imagefont()
        )
    drawing = plot.render_map(make_reply(ROOM, TRAJECTORY), size=1000)
    labels = [item for item in drawing.items if isinstance(item, plot.Label)]
    assert [label.text for label in labels] == ["0", "1", "2", "3", "1 m"]
    with_labels = plot.rasterise(drawing).astype(int)
    drawing.items[:] = [item for item in drawing.items if not isinstance(item, plot.Label)]
    without = plot.rasterise(drawing).astype(int)
    changed = (with_labels != without).any(axis=2)
    ink = with_labels.sum(axis=2) < without.sum(axis=2) - 100  # the text is dark
    boxes = np.zeros_like(changed)
    for label in labels:
        (x, y), h = label.centre, label.height
        half_w, half_h = 0.6 * h * len(label.text) + 4, h + 4
        top, left = int(y - half_h), int(x - half_w)
        box = np.s_[top : int(y + half_h) + 1, left : int(x + half_w) + 1]
        boxes[box] = True
        rows, cols = np.nonzero(ink[box])
        assert len(rows) > 10, label.text
        assert top + (rows.min() + rows.max() + 1) / 2 == pytest.approx(y, abs=1.5), label.text
        assert left + (cols.min() + cols.max() + 1) / 2 == pytest.approx(x, abs=1.5), label.text
        assert 0.8 * h <= rows.max() - rows.min() + 1 <= 1.3 * h, label.text
    assert not (changed & ~boxes).any(), "text drawn only at the labels"


def band_pixels(image, drawing, x, y):
    """Non-background pixels in the column through (x, y), within 1 m of it."""
    col, row = np.round(drawing.to_px([x, y]) - 0.5).astype(int)
    reach = int(drawing.scale)
    column = image[row - reach : row + reach, col]
    return int((column != rgb(plot.BACKGROUND)).any(axis=1).sum())


def test_band_is_wider_for_a_larger_covariance():
    walls = [make_wall(0, (-2, 2), (2, 2), 0.01), make_wall(1, (-2, -2), (2, -2), 0.1)]
    drawing = plot.render_map(make_reply(walls), size=800)
    image = plot.rasterise(drawing)
    narrow, wide = band_pixels(image, drawing, 1.0, 2.0), band_pixels(image, drawing, 1.0, -2.0)
    assert wide > narrow + 20
    # 1 m from the foot point (0, -2), sigma grows by sqrt(1 + (1 / 2)^2): 2 sigma each side
    assert wide == pytest.approx(4 * 0.1 * np.sqrt(1.25) * drawing.scale, abs=3)


@pytest.mark.parametrize(
    ("u", "v", "cov", "t"),
    [
        (2.0, 0.0, [[1e-4, 0.0], [0.0, 4e-4]], 1.5),
        (1.0, 2.0, [[4e-4, 2e-4], [2e-4, 3e-4]], -3.0),  # correlated: the sign of g matters
        (-3.0, 1.0, [[2e-4, -1.5e-4], [-1.5e-4, 3e-4]], 2.0),
        (0.5, -0.5, [[1e-4, 0.0], [0.0, 1e-4]], 0.0),
    ],
)
def test_band_half_width_matches_monte_carlo(u, v, cov, t):
    uv = np.array([u, v])
    r = np.linalg.norm(uv)
    n = uv / r
    point = uv + t * np.array([-n[1], n[0]])
    rng = np.random.default_rng(1)
    moved = uv + rng.multivariate_normal(np.zeros(2), cov, size=100_000)
    radius = np.linalg.norm(moved, axis=1)
    displacement = radius - (moved / radius[:, None]) @ point  # along n, to the moved line
    expected = 2 * displacement.std()
    half = plot.band_half_width(u, v, cov, point[None, :])[0]
    assert half == pytest.approx(expected, rel=0.03)


def test_band_is_capped_for_a_line_through_the_origin():
    far = plot.band_half_width(0.0, 0.0, np.eye(2) * 1e-4, np.array([[1.0, 1.0]]), [1.0, -1.0])
    assert far[0] == plot.BAND_CAP
    at_foot = plot.band_half_width(0.0, 0.0, np.eye(2) * 1e-4, np.zeros((1, 2)), [1.0, -1.0])
    assert at_foot[0] == pytest.approx(0.02)


def test_a_wall_through_the_origin_draws(tmp_path):
    wall = make_wall(5, (-2, -2), (2, 2), 0.01) | {"u": 0.0, "v": 0.0}
    huge = make_wall(6, (-2, 2), (2, -2), cov=[[1e12, 0.0], [0.0, 1e12]])  # as served near 0
    reply = make_reply([wall, huge], TRAJECTORY)
    plot.write_png(tmp_path / "o.png", reply, size=300)
    plot.write_svg(tmp_path / "o.svg", reply, size=300)
    image = read_png((tmp_path / "o.png").read_bytes())
    assert (image == rgb(plot.WALL_COLOUR)).all(axis=2).any()
    ET.parse(tmp_path / "o.svg")


def test_svg_has_a_line_per_segment_and_a_label_per_wall(tmp_path):
    point = make_wall(7, (0, 0), (1, 0), 0.02) | {"p1": [0.0, 0.0]}  # a wall of length 0
    reply = make_reply([*ROOM, point], TRAJECTORY)
    path = tmp_path / "map.svg"
    plot.write_svg(path, reply, size=500)
    root = ET.parse(path).getroot()
    assert root.tag == f"{SVG}svg"

    def of_class(tag, kind):
        return [e for e in root.iter(f"{SVG}{tag}") if e.get("class") == kind]

    assert len(of_class("line", "wall")) == 6  # 5 walls, one with two segments
    assert len(of_class("line", "gap")) == 1
    assert len(of_class("polygon", "band")) == 6
    assert [e.text for e in of_class("text", "label")] == ["0", "1", "2", "3", "7"]
    assert len(of_class("polyline", "trajectory")) == 1
    assert len(of_class("circle", "start")) == 1
    assert of_class("text", "title")[0].text == "5 walls, 120 frames, 400 observations"
    assert [e.text for e in of_class("text", "scale")] == ["1 m"]


def test_picture_by_suffix_and_trajectory_argument(tmp_path):
    reply = make_reply(ROOM)
    xy = np.array([row[1:3] for row in TRAJECTORY])
    plot.write_picture(tmp_path / "a.png", reply, xy, size=300)
    read_png((tmp_path / "a.png").read_bytes())
    plot.write_picture(tmp_path / "a.svg", reply, np.array(TRAJECTORY), size=300)
    root = ET.parse(tmp_path / "a.svg").getroot()
    assert any(e.get("class") == "trajectory" for e in root.iter(f"{SVG}polyline"))
    with pytest.raises(ValueError, match="trajectory"):
        plot.render_map(reply, trajectory=np.zeros((3, 3)))
    for other in ("a.jpg", "a"):  # not an SVG under another name
        with pytest.raises(ValueError, match=r"a picture is drawn as \.png or \.svg"):
            plot.write_picture(tmp_path / other, reply)
        assert not (tmp_path / other).exists()


def test_empty_map_draws():
    drawing = plot.render_map(make_reply([]), size=200)
    read_png(drawing.to_png())
    ET.fromstring(drawing.to_svg())


def test_a_thousand_walls_render_quickly():
    rng = np.random.default_rng(0)
    walls = []
    for i in range(1000):
        centre, angle = rng.uniform(-25, 25, 2), rng.uniform(0, np.pi)
        half = rng.uniform(0.25, 3) * np.array([np.cos(angle), np.sin(angle)])
        walls.append(make_wall(i, centre - half, centre + half, rng.uniform(0.005, 0.1)))
    start = time.perf_counter()
    drawing = plot.render_map(make_reply(walls), size=1000)
    read_png(drawing.to_png())
    ET.fromstring(drawing.to_svg())
    assert time.perf_counter() - start < 5.0


def test_geojson_round_trips_with_features_and_properties(tmp_path):
    reply = make_reply(ROOM, TRAJECTORY)
    path = tmp_path / "map.geojson"
    write_geojson(path, reply)
    collection = json.loads(path.read_text())
    assert collection == json.loads(json.dumps(to_geojson(reply)))
    assert collection["type"] == "FeatureCollection"
    assert collection["properties"]["frame"] == "map"
    assert collection["properties"]["units"] == "m"
    assert collection["properties"]["frames"] == 120
    walls = [f for f in collection["features"] if f["properties"]["kind"] == "wall"]
    assert [f["id"] for f in walls] == [0, 1, 2, 3]
    first = walls[0]
    assert first["geometry"] == {
        "type": "MultiLineString",
        "coordinates": [[[-4.0, -3.0], [5.0, -3.0]]],
    }, "a wall is the segments seen, one here"
    props = first["properties"]
    assert props["u"] == pytest.approx(0.0, abs=1e-12)
    assert props["v"] == pytest.approx(-3.0)
    assert props["cov"] == ROOM[0]["cov"]
    assert props["length"] == pytest.approx(9.0)
    assert (props["n_obs"], props["first_seen"], props["last_seen"]) == (7, 10.0, 20.0)
    door = walls[2]
    assert door["geometry"]["type"] == "MultiLineString"
    assert door["geometry"]["coordinates"] == [[[5, 4], [1, 4]], [[-1, 4], [-4, 4]]]
    assert door["properties"]["length"] == pytest.approx(7.0)
    (path_feature,) = [f for f in collection["features"] if f["properties"]["kind"] == "trajectory"]
    assert path_feature["geometry"]["type"] == "LineString"
    assert path_feature["geometry"]["coordinates"][1] == [TRAJECTORY[1][1], TRAJECTORY[1][2]]
    assert path_feature["properties"]["stamps"] == [row[0] for row in TRAJECTORY]


def test_geojson_without_trajectory_or_walls():
    assert to_geojson(make_reply([]))["features"] == []
    single = to_geojson(make_reply([], TRAJECTORY[:1]))["features"][0]
    assert single["geometry"] == {"type": "Point", "coordinates": [-2.0, 0.0]}


ROOMS = {
    "rooms": [
        {
            "id": 3,
            "polygon": [[-4, -3], [5, -3], [5, 2], [-4, 2]],
            "area": 45.0,
            "centroid": [0.5, -0.5],
            "walls": [0, 1, 2, 3],
            "doors": [1],
            "closed": True,
        },
    ],
    "doors": [
        {
            "id": 1,
            "center": [5.0, 0.0],
            "width": 0.9,
            "p0": [5.0, -0.45],
            "p1": [5.0, 0.45],
            "wall": 1,
            "rooms": [3],
        }
    ],
}


def test_rooms_are_polygons_and_doors_lines_in_geojson_and_drawn_in_svg(tmp_path):
    reply = make_reply(ROOM, TRAJECTORY)
    features = to_geojson(reply, ROOMS)["features"]
    (room,) = [f for f in features if f["properties"]["kind"] == "room"]
    (door,) = [f for f in features if f["properties"]["kind"] == "door"]
    ring = room["geometry"]["coordinates"][0]
    assert room["geometry"]["type"] == "Polygon"
    assert ring[0] == ring[-1] == [-4.0, -3.0]
    assert (room["id"], room["properties"]["area"], room["properties"]["doors"]) == (
        "room-3",
        45.0,
        [1],
    )
    assert door["geometry"] == {"type": "LineString", "coordinates": [[5.0, -0.45], [5.0, 0.45]]}
    assert door["properties"]["rooms"] == [3]
    svg = tmp_path / "map.svg"
    plot.write_svg(svg, reply, size=400, rooms=ROOMS)
    text = svg.read_text()
    assert text.count('class="room"') == 1
    assert text.count('class="door"') == 1
    assert "R3 45.0 m" in text


def test_a_room_label_draws_no_missing_glyph_box() -> None:
    """Areas are in m²; a font without "²" (Pillow's own) gets "m2", never a box."""
    font = plot._font(40)
    assert not plot._has_glyph(font, "\ue001"), "a character no font has is seen as missing"
    text = plot._spelt("R0 32.4 m²", font)
    assert text in ("R0 32.4 m²", "R0 32.4 m2")
    assert all(plot._has_glyph(font, c) for c in text if not c.isspace())
