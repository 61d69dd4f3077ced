"""Pictures of a map reply, top-down in the map frame, as PNG (by Pillow) or SVG (by hand).

``render_map`` lays the picture out once, in pixels, as a list of primitives (filled polygons,
strokes, dots, labels); the PNG and SVG writers only paint those, so both show the same thing:
each wall (its segments, thin lines over the gaps between them), its 2-sigma band, its id, the
trajectory with a dot at its start, a scale bar and (SVG only) a title with the counts.

The PNG is painted with Pillow's ImageDraw on a canvas a few times larger than the picture,
then averaged down to it: anti-aliased edges without a plotting library's weight.
"""

from __future__ import annotations

import functools
import io
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape, quoteattr

import numpy as np
from PIL import Image, ImageColor, ImageDraw, ImageFilter, ImageFont, features

from wallmap.arg_types import picture_problem
from wallmap.common.map_records import MapReply, WallRecord

Array = np.ndarray

BAND_SIGMAS = 2.0
BAND_CAP = 1.0  # m: the widest band drawn; a line near the origin has an unbounded one
MARGIN = 40  # px around the drawing
TITLE_HEIGHT = 24  # px above it, for the title line
WORLD_PAD = 0.2  # m around the content

BACKGROUND = "#ffffff"
WALL_COLOUR = "#b3261e"
BAND_OPACITY = 0.22
GAP_COLOUR = "#d9908a"
TRAJECTORY_COLOUR = "#2b6cb0"
# A fleet's robots, each in its own colour (the first robot's is the one robot's colour).
TRAJECTORY_COLOURS = (TRAJECTORY_COLOUR, "#c05621", "#6b46c1", "#2c7a7b", "#b83280")
LABEL_COLOUR = "#202020"
SCALE_COLOUR = "#000000"
ROOM_COLOURS = ("#f6c85f", "#9dd866", "#6fb1d8", "#ca472f", "#a27ea8", "#ffa056", "#8dddd0")
ROOM_OPACITY = 0.28
DOOR_COLOUR = "#2f855a"
POINT_COLOUR = "#b8b8b8"

_PERP = np.array([[0.0, -1.0], [1.0, 0.0]])  # +90 degrees


@dataclass(frozen=True)
class Fill:
    """A filled polygon, in pixels."""

    points: Array  # (K, 2)
    colour: str
    opacity: float
    kind: str  # the SVG class


@dataclass(frozen=True)
class Stroke:
    """A polyline of a given width, in pixels."""

    points: Array  # (N, 2), N >= 2
    width: float
    colour: str
    kind: str


@dataclass(frozen=True)
class Dot:
    """A filled disc, in pixels."""

    centre: tuple[float, float]
    radius: float
    colour: str
    kind: str


@dataclass(frozen=True)
class Label:
    """Text centred on a point, in pixels; ``height`` is the glyph height."""

    centre: tuple[float, float]
    text: str
    height: float
    colour: str
    kind: str


Item = Fill | Stroke | Dot | Label


@dataclass
class Drawing:
    """A laid-out picture: primitives in painting order, plus the map-to-pixel transform."""

    width: int
    height: int
    scale: float  # px per m
    offset: tuple[float, float]  # pixel of the map origin
    title: str
    items: list[Item] = field(default_factory=list)

    def to_px(self, points: Array) -> Array:
        """Map-frame points (..., 2) to pixel coordinates (x right, y down)."""
        points = np.asarray(points, dtype=float)
        return np.stack(
            [
                self.offset[0] + points[..., 0] * self.scale,
                self.offset[1] - points[..., 1] * self.scale,
            ],
            axis=-1,
        )

    def to_svg(self) -> str:
        """The picture as an SVG document."""
        return _svg(self)

    def to_png(self) -> bytes:
        """The picture as an RGB PNG file."""
        out = io.BytesIO()
        _picture(self).save(out, "PNG")
        return out.getvalue()


# --- the band ---------------------------------------------------------------------------------


def line_sigma(u: float, v: float, cov: Array, points: Array, normal: Array | None = None) -> Array:
    """Perpendicular standard deviation of the wall's line at ``points`` (on or near the line).

    The line has closest point (u, v) to the origin: r = |(u, v)|, normal n = (u, v) / r and
    direction d = n turned by +90 degrees. A perturbation delta of (u, v) shifts the line along n
    by n . delta and turns it by (d . delta) / r about (u, v), so the point at position t along d
    moves along n by (n - (t / r) d) . delta = g . delta, whose variance is g' cov g.

    For r near 0 the turn is unbounded (as is the (u, v) covariance the mapper serves there): r
    is floored, so away from the foot point the result is huge but finite, for the caller to cap.
    ``normal`` gives the line's normal when r is 0, where (u, v) has no direction.
    """
    uv = np.array([u, v], dtype=float)
    r = float(np.hypot(u, v))
    if r > 1e-9 or normal is None:
        n = uv / r if r > 1e-9 else np.array([1.0, 0.0])
    else:
        n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    d = _PERP @ n
    t = (np.asarray(points, dtype=float) - r * n) @ d
    g = n[None, :] - (t / max(r, 1e-9))[:, None] * d[None, :]
    cov = np.asarray(cov, dtype=float)
    with np.errstate(invalid="ignore", over="ignore"):
        var = np.einsum("ij,jk,ik->i", g, cov, g)
    return np.sqrt(np.clip(var, 0.0, None))


def band_half_width(
    u: float,
    v: float,
    cov: Array,
    points: Array,
    normal: Array | None = None,
    *,
    sigmas: float = BAND_SIGMAS,
    cap: float = BAND_CAP,
) -> Array:
    """Half-width of the wall's ``sigmas``-sigma band at ``points``, at most ``cap`` metres."""
    half = sigmas * line_sigma(u, v, cov, points, normal)
    return np.where(np.isfinite(half), np.minimum(half, cap), cap)


# --- layout -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Wall:
    """A wall's geometry in the map frame, as drawn."""

    id: Any
    pieces: list[Array]  # (2, 2) segments, ordered along the wall
    gaps: list[Array]  # (2, 2) spans between consecutive pieces
    normal: Array  # unit, away from the map origin when the line is off it
    bands: list[Array]  # (2K, 2) polygons


def _wall_geometry(wall: WallRecord) -> _Wall:
    p0, p1 = np.asarray(wall.p0, dtype=float), np.asarray(wall.p1, dtype=float)
    along = p1 - p0
    if np.linalg.norm(along) < 1e-12:
        along = np.array([1.0, 0.0])
    along = along / np.linalg.norm(along)
    u, v = wall.u, wall.v
    r = math.hypot(u, v)
    normal = np.array([u, v]) / r if r > 1e-9 else _PERP.T @ along
    pieces = []
    for seg in wall.segments:
        a, b = np.asarray(seg, dtype=float)
        pieces.append(np.array([a, b]) if (b - a) @ along >= 0 else np.array([b, a]))
    pieces.sort(key=lambda s: float(s[0] @ along))
    gaps = [
        np.array([prev[1], nxt[0]])
        for prev, nxt in itertools.pairwise(pieces)
        if (nxt[0] - prev[1]) @ along > 1e-9
    ]
    bands = []
    for a, b in pieces:
        pts = a + np.linspace(0.0, 1.0, 5)[:, None] * (b - a)  # the band bulges between ends
        half = band_half_width(u, v, np.asarray(wall.cov), pts, normal)[:, None]
        bands.append(np.vstack([pts + half * normal, (pts - half * normal)[::-1]]))
    return _Wall(wall.id, pieces, gaps, normal, bands)


def _paths(reply: MapReply, trajectory: Array | list[Array] | None) -> list[Array]:
    """The paths to draw (N, 2): the reply's own, the one given, or each of a list (a fleet)."""
    if isinstance(trajectory, list):
        return [_trajectory_xy(reply, path) for path in trajectory]
    return [_trajectory_xy(reply, trajectory)]


def _trajectory_xy(reply: MapReply, trajectory: Array | None) -> Array:
    if trajectory is None:
        rows = reply.trajectory or ()
        return np.array([row[1:3] for row in rows], dtype=float).reshape(-1, 2)
    trajectory = np.asarray(trajectory, dtype=float)
    if trajectory.ndim != 2 or trajectory.shape[1] not in (2, 4):
        raise ValueError("trajectory: expected (N, 2) x, y or (N, 4) stamp, x, y, yaw rows")
    return trajectory[:, -3:-1] if trajectory.shape[1] == 4 else trajectory


def _scale_bar_length(scale: float, width: int) -> float:
    """1 m, unless that is under 40 px or over a third of the picture: then 1, 2 or 5 x 10^k m."""
    if 40 <= scale <= width / 3:
        return 1.0
    exponent = math.floor(math.log10(40 / scale))  # 10^(exponent + 1) m is >= 40 px
    nice = [m * 10.0**k for k in (exponent, exponent + 1) for m in (1.0, 2.0, 5.0)]
    return min(length for length in nice if length * scale >= 40)


def render_map(
    reply: MapReply,
    *,
    trajectory: Array | list[Array] | None = None,
    size: int = 1000,
    points: Array | None = None,
    rooms: dict[str, Any] | None = None,
) -> Drawing:
    """Lay out a map reply as a picture whose longer side is about ``size`` pixels.

    Args:
        reply: the map reply (its walls, and its counts for the title).
        trajectory: (N, 2) x, y or (N, 4) stamp, x, y, yaw in the map frame; by default the
            reply's own ``trajectory``, if it has one. A list of them: a fleet's robots' paths,
            each drawn in its own colour.
        size: pixels of the longer side; line widths and text scale with it.
        points: (N, 2) sensor points in the map frame, drawn grey under the walls (what the
            map should cover), one square per pixel they fall in.
        rooms: the mapper's rooms reply (``{prefix}/map/rooms``): each room filled under the
            walls and labelled with its id and area, each door drawn across its opening.
    """
    walls = [_wall_geometry(w) for w in reply.walls]
    room_list = [] if rooms is None else list(rooms.get("rooms", ()))
    door_list = [] if rooms is None else list(rooms.get("doors", ()))
    paths = _paths(reply, trajectory)
    cloud = np.zeros((0, 2)) if points is None else np.asarray(points, dtype=float)
    content = [*paths, cloud, *(np.vstack([*w.pieces, *w.bands]) for w in walls)]
    content += [np.asarray(r["polygon"], dtype=float) for r in room_list]
    title = f"{len(walls)} walls, {reply.frames} frames, {reply.observations} observations"
    drawing = _canvas(np.vstack([c.reshape(-1, 2) for c in content]), size, title)
    unit = size / 1000  # line widths and text grow with the picture
    items = drawing.items
    px = drawing.to_px
    for k, room in enumerate(room_list):
        colour = ROOM_COLOURS[room["id"] % len(ROOM_COLOURS)] if "id" in room else ROOM_COLOURS[k]
        items.append(Fill(px(np.asarray(room["polygon"], float)), colour, ROOM_OPACITY, "room"))
    if len(cloud):
        pixels = np.unique(np.floor(px(cloud)).astype(np.int64), axis=0)
        square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]) * max(1.0, unit)
        items.extend(Fill(p + square, POINT_COLOUR, 1.0, "points") for p in pixels)
    for w in walls:
        items.extend(Fill(px(b), WALL_COLOUR, BAND_OPACITY, "band") for b in w.bands)
    for w in walls:
        items.extend(Stroke(px(g), max(1.0, 1.2 * unit), GAP_COLOUR, "gap") for g in w.gaps)
    _draw_paths(drawing, paths, unit)
    for w in walls:
        items.extend(Stroke(px(p), max(2.0, 3 * unit), WALL_COLOUR, "wall") for p in w.pieces)
    for door in door_list:
        span = px(np.array([door["p0"], door["p1"]], dtype=float))
        items.append(Stroke(span, max(3.0, 5 * unit), DOOR_COLOUR, "door"))
    glyph = max(5.0, 5 * round(2 * unit))  # digit height, px; in steps of 5, as the SVG had
    _draw_labels(drawing, walls, room_list, glyph, unit)
    _draw_scale_bar(drawing, glyph, unit)
    return drawing


def _canvas(everything: Array, size: int, title: str) -> Drawing:
    """A drawing that holds ``everything`` (map points), its longer side about ``size`` px."""
    if len(everything) == 0:
        everything = np.array([[-1.0, -1.0], [1.0, 1.0]])
    lo, hi = everything.min(axis=0) - WORLD_PAD, everything.max(axis=0) + WORLD_PAD
    span = np.maximum(hi - lo, 1e-6)
    scale = min((size - 2 * MARGIN) / span[0], (size - 2 * MARGIN - TITLE_HEIGHT) / span[1])
    minimum = max(size // 3, 2 * MARGIN + 1)  # room for the title and the scale bar
    width = max(math.ceil(span[0] * scale) + 2 * MARGIN, minimum)
    height = max(math.ceil(span[1] * scale) + 2 * MARGIN + TITLE_HEIGHT, minimum)
    inner_x = (width - span[0] * scale) / 2
    inner_y = TITLE_HEIGHT + (height - TITLE_HEIGHT - span[1] * scale) / 2
    offset = (inner_x - lo[0] * scale, inner_y + hi[1] * scale)
    return Drawing(width, height, scale, offset, title)


def _draw_paths(drawing: Drawing, paths: list[Array], unit: float) -> None:
    """Each path (a fleet's robots': each in its own colour) and a dot at its start."""
    for k, path in enumerate(paths):
        colour = TRAJECTORY_COLOURS[k % len(TRAJECTORY_COLOURS)]
        if len(path) > 1:
            drawing.items.append(
                Stroke(drawing.to_px(path), max(1.2, 1.5 * unit), colour, "trajectory")
            )
        if len(path) > 0:
            start = drawing.to_px(path[0])
            drawing.items.append(Dot((start[0], start[1]), max(2.5, 4 * unit), colour, "start"))


def _draw_labels(
    drawing: Drawing, walls: list[_Wall], rooms: list[dict[str, Any]], glyph: float, unit: float
) -> None:
    """Each room's id and area at its centroid; each wall's id beside its middle."""
    px = drawing.to_px
    for room in rooms:
        centre = px(np.asarray(room["centroid"], dtype=float))
        text = f"R{room['id']} {room['area']:.1f} m²"
        drawing.items.append(Label((centre[0], centre[1]), text, glyph, LABEL_COLOUR, "room-label"))
    for w in walls:
        ends = np.array([w.pieces[0][0], w.pieces[-1][1]])
        middle = px(ends.mean(axis=0))
        side = np.array([w.normal[0], -w.normal[1]])  # pixel y points down
        centre = middle + side * (glyph + 3 * unit)
        drawing.items.append(Label((centre[0], centre[1]), str(w.id), glyph, LABEL_COLOUR, "label"))


def _draw_scale_bar(drawing: Drawing, glyph: float, unit: float) -> None:
    """A scale bar of a round length, bottom left."""
    length = _scale_bar_length(drawing.scale, drawing.width)
    x0, y = MARGIN, drawing.height - MARGIN / 2
    x1 = x0 + length * drawing.scale
    bar = np.array([[x0, y], [x1, y]])
    drawing.items.append(Stroke(bar, max(2.0, 2 * unit), SCALE_COLOUR, "scale"))
    text = f"{length:g} m"
    drawing.items.append(
        Label((x1 + 6 + 0.8 * glyph * len(text) / 2, y), text, glyph, SCALE_COLOUR, "scale")
    )


# --- SVG --------------------------------------------------------------------------------------


def _svg_points(points: Array) -> str:
    return " ".join(f"{x:.1f},{y:.1f}" for x, y in points)


def _svg(drawing: Drawing) -> str:
    w, h = drawing.width, drawing.height
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" '
        f'viewBox="0 0 {w} {h}" font-family="sans-serif">',
        f'<rect width="{w}" height="{h}" fill="{BACKGROUND}"/>',
        f'<text class="title" x="{MARGIN}" y="{TITLE_HEIGHT - 4}" font-size="14">'
        f"{escape(drawing.title)}</text>",
    ]
    for item in drawing.items:
        kind = quoteattr(item.kind)
        if isinstance(item, Fill):
            out.append(
                f'<polygon class={kind} points="{_svg_points(item.points)}" fill="{item.colour}" '
                f'fill-opacity="{item.opacity}" stroke="none"/>'
            )
        elif isinstance(item, Stroke) and len(item.points) == 2:
            (x0, y0), (x1, y1) = item.points
            out.append(
                f'<line class={kind} x1="{x0:.1f}" y1="{y0:.1f}" x2="{x1:.1f}" y2="{y1:.1f}" '
                f'stroke="{item.colour}" stroke-width="{item.width:.2f}" stroke-linecap="square"/>'
            )
        elif isinstance(item, Stroke):
            out.append(
                f'<polyline class={kind} points="{_svg_points(item.points)}" fill="none" '
                f'stroke="{item.colour}" stroke-width="{item.width:.2f}" stroke-linejoin="round"/>'
            )
        elif isinstance(item, Dot):
            x, y = item.centre
            out.append(
                f'<circle class={kind} cx="{x:.1f}" cy="{y:.1f}" r="{item.radius:.1f}" '
                f'fill="{item.colour}"/>'
            )
        else:
            x, y = item.centre
            out.append(
                f'<text class={kind} x="{x:.1f}" y="{y:.1f}" font-size="{item.height * 1.4:.1f}" '
                f'text-anchor="middle" dominant-baseline="central" fill="{item.colour}" '
                f'stroke="{BACKGROUND}" stroke-width="3" paint-order="stroke">'
                f"{escape(item.text)}</text>"
            )
    out.append("</svg>")
    return "\n".join(out) + "\n"


# --- PNG --------------------------------------------------------------------------------------

# The canvas is painted this many times larger, then averaged down: that average is the
# anti-aliasing (an edge pixel gets the share of it a shape covers).
SUPERSAMPLE = 3


def _canvas_xy(points: Array) -> list[float]:
    """Drawing pixels to the supersampled canvas's, flat [x0, y0, x1, ...] as ImageDraw takes.

    A drawing pixel spans [i, i + 1); Pillow puts a canvas pixel's centre on its integer
    coordinate, hence the half pixel.
    """
    return (np.asarray(points, dtype=float) * SUPERSAMPLE - 0.5).ravel().tolist()


@functools.cache
def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """Pillow's own font at ``size`` px (none need be installed); without FreeType, its bitmap."""
    if features.check("freetype2"):
        return ImageFont.load_default(size=size)
    return ImageFont.load_default()


PLAIN = {"²": "2"}  # spelt plainly where the font has no glyph for it (Pillow's own has none)


def _spelt(text: str, font: ImageFont.FreeTypeFont | ImageFont.ImageFont) -> str:
    """The text with each character the font lacks (it would draw a box) spelt plainly."""
    for char, plain in PLAIN.items():
        if char in text and not _has_glyph(font, char):
            text = text.replace(char, plain)
    return text


def _has_glyph(font: ImageFont.FreeTypeFont | ImageFont.ImageFont, char: str) -> bool:
    """Whether ``font`` draws ``char`` as itself, not as the box of a missing glyph."""
    if not isinstance(font, ImageFont.FreeTypeFont):
        return False  # the bitmap font: ASCII only
    drawn, box = font.getmask(char), font.getmask("\ue000")  # private use: drawn by no font
    return drawn.size != box.size or bytes(drawn) != bytes(box)


def _ink(
    text: str, font: ImageFont.FreeTypeFont | ImageFont.ImageFont, margin: int, stroke: int = 0
) -> Image.Image:
    """The text drawn white on black ("L"), its box widened by ``margin`` px each side."""
    left, top, right, bottom = font.getbbox(text)
    mask = Image.new("L", (right - left + 2 * margin, bottom - top + 2 * margin))
    ImageDraw.Draw(mask).text(
        (margin - left, margin - top), text, 255, font, stroke_width=stroke, stroke_fill=255
    )
    return mask


def _text_masks(text: str, size: int) -> tuple[Image.Image, Image.Image]:
    """The text's ink in a font of ``size`` px, and a halo of about a picture pixel around it.

    The bitmap font (no FreeType) has one size and draws no strokes: its ink is widened by a
    pixel at that size, then both are enlarged to about ``size``, so labels keep their place
    and size either way.
    """
    font = _font(size)
    text = _spelt(text, font)
    if isinstance(font, ImageFont.FreeTypeFont):
        pad = SUPERSAMPLE  # a picture pixel
        return _ink(text, font, pad), _ink(text, font, pad, stroke=pad)
    ink = _ink(text, font, 1)
    halo = ink.filter(ImageFilter.MaxFilter(3))
    zoom = max(1, round(size / font.getbbox("0")[3]))  # the bitmap font's line height
    ink, halo = (
        m.resize((m.width * zoom, m.height * zoom), Image.Resampling.NEAREST) for m in (ink, halo)
    )
    return ink, halo


def _paint_label(canvas: Image.Image, label: Label) -> None:
    """The label's text centred on its point, over a halo of background (legibility).

    The font size is the SVG's (1.4 x the glyph height): digits then stand ``height`` tall.
    """
    ink, halo = _text_masks(label.text, round(1.4 * label.height * SUPERSAMPLE))
    x, y = _canvas_xy(label.centre)
    left, top = round(x - ink.width / 2), round(y - ink.height / 2)
    box = (left, top, left + ink.width, top + ink.height)
    canvas.paste(BACKGROUND, box, halo)
    canvas.paste(label.colour, box, ink)


def _paint(canvas: Image.Image, draw: ImageDraw.ImageDraw, item: Item) -> None:
    """One item on the supersampled canvas; ``draw`` blends (its mode is RGBA)."""
    if isinstance(item, Label):
        _paint_label(canvas, item)
    elif isinstance(item, Fill):
        alpha = round(255 * item.opacity)  # overlapping translucent fills compound
        draw.polygon(_canvas_xy(item.points), fill=(*ImageColor.getrgb(item.colour), alpha))
    elif isinstance(item, Stroke):
        width = max(1, round(item.width * SUPERSAMPLE))
        points = _canvas_xy(item.points)
        draw.line(points, fill=item.colour, width=width, joint="curve")
        for x, y in (points[:2], points[-2:]):  # round caps: walls meet at closed corners
            draw.ellipse(_disc_box(x, y, width / 2), fill=item.colour)
    else:
        x, y = _canvas_xy(item.centre)
        draw.ellipse(_disc_box(x, y, item.radius * SUPERSAMPLE), fill=item.colour)


def _disc_box(x: float, y: float, radius: float) -> tuple[float, float, float, float]:
    return (x - radius, y - radius, x + radius, y + radius)


def _picture(drawing: Drawing) -> Image.Image:
    """Paint the drawing, anti-aliased: in order on a supersampled RGB canvas, averaged down."""
    size = (drawing.width * SUPERSAMPLE, drawing.height * SUPERSAMPLE)
    canvas = Image.new("RGB", size, BACKGROUND)
    draw = ImageDraw.Draw(canvas, "RGBA")
    for item in drawing.items:
        _paint(canvas, draw, item)
    return canvas.reduce(SUPERSAMPLE)


def rasterise(drawing: Drawing) -> Array:
    """Paint the drawing into an (H, W, 3) uint8 image (for reading pixels)."""
    return np.array(_picture(drawing))


# --- files ------------------------------------------------------------------------------------


def write_png(
    path: Path,
    reply: MapReply,
    trajectory: Array | list[Array] | None = None,
    size: int = 1000,
    points: Array | None = None,
    rooms: dict[str, Any] | None = None,
) -> None:
    """Draw a map reply to a PNG file (see ``render_map``)."""
    drawing = render_map(reply, trajectory=trajectory, size=size, points=points, rooms=rooms)
    Path(path).write_bytes(drawing.to_png())


def write_svg(
    path: Path,
    reply: MapReply,
    trajectory: Array | list[Array] | None = None,
    size: int = 1000,
    points: Array | None = None,
    rooms: dict[str, Any] | None = None,
) -> None:
    """Draw a map reply to an SVG file (see ``render_map``)."""
    svg = render_map(reply, trajectory=trajectory, size=size, points=points, rooms=rooms).to_svg()
    Path(path).write_text(svg, encoding="utf-8")


def write_picture(
    path: Path,
    reply: MapReply,
    trajectory: Array | list[Array] | None = None,
    size: int = 1000,
    points: Array | None = None,
    rooms: dict[str, Any] | None = None,
) -> None:
    """PNG or SVG by the file's suffix, for commands taking one ``--out``; ValueError else."""
    problem = picture_problem(Path(path))
    if problem is not None:
        raise ValueError(problem)
    writer = write_png if Path(path).suffix.lower() == ".png" else write_svg
    writer(path, reply, trajectory, size, points, rooms)
