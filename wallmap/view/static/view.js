// The live wall map of `wallmap view`: polls the server's JSON API and draws on a canvas.
// Map frame: x right, y up, metres. Screen: (ox + x * scale, oy - y * scale) in CSS pixels.
"use strict";

(() => {
  const POLL_MS = 500;
  const BAND_SIGMAS = 2; // as `wallmap plot`
  const BAND_CAP = 1.0; // m: the band of a line near the origin is unbounded
  const HOVER_PX = 6; // how near the pointer must be to a wall
  const LABEL_MIN_PX = 24; // a wall shorter than this on screen goes without its id
  const HALO_MAX = 400; // above this many ids, no white halo: it doubles the cost of the text
  const FIT_MARGIN_PX = 30;
  const SCALE_LIMITS = [1e-3, 1e4]; // px per m
  const COLOUR = {
    background: "#ffffff",
    wall: "#b3261e",
    band: "rgba(179, 38, 30, 0.22)",
    tentative: "#d08a2c",
    tentativeBand: "rgba(208, 138, 44, 0.16)",
    gap: "#d9908a",
    trajectory: "#2b6cb0",
    observation: "#138a36",
    label: "#202020",
    hover: "rgba(0, 0, 0, 0.55)",
    door: "#2f855a",
    rooms: ["#f6c85f", "#9dd866", "#6fb1d8", "#ca472f", "#a27ea8", "#ffa056", "#8dddd0"],
  };
  const ROOM_ALPHA = 0.28;

  const $ = (id) => document.getElementById(id);
  const canvas = $("map");
  const ctx = canvas.getContext("2d");
  const tip = $("tip");

  const map = {
    version: 0, walls: new Map(), trajectory: [], frames: 0, observations: 0, rooms: [], doors: [],
  };
  let latest = { pose: null, observations: null, status: null };
  let latestKey = "";
  const view = { scale: 40, ox: 0, oy: 0, follow: true }; // follow: refit as the map grows
  let visible = []; // the walls of the last frame, for hovering
  let hoveredId = null;
  let pointer = null; // {x, y} in canvas pixels while over the canvas
  let drag = null;
  let drawnKey = "";
  let frames = 0;
  let scheduled = false;

  // --- geometry, once per wall record ---------------------------------------------------------

  // Perpendicular standard deviation of the wall's line at (x, y), as wallmap/plot.py: moving
  // (u, v) by delta shifts the line's point at t along it by (n - (t / r) d) . delta.
  function lineSigma(rec, n, x, y) {
    const r = Math.hypot(rec.u, rec.v);
    const d = [-n[1], n[0]];
    const t = (x - r * n[0]) * d[0] + (y - r * n[1]) * d[1];
    const k = t / Math.max(r, 1e-9);
    const g0 = n[0] - k * d[0];
    const g1 = n[1] - k * d[1];
    const c = rec.cov;
    const variance = g0 * (c[0][0] * g0 + c[0][1] * g1) + g1 * (c[1][0] * g0 + c[1][1] * g1);
    return Math.sqrt(Math.max(variance, 0));
  }

  function halfWidth(rec, n, x, y) {
    const half = BAND_SIGMAS * lineSigma(rec, n, x, y);
    return Number.isFinite(half) ? Math.min(half, BAND_CAP) : BAND_CAP;
  }

  // Segments ordered along the wall, the gaps between them, the 2-sigma band around each, a
  // bounding box for culling and the numbers shown on hover.
  function geometry(rec) {
    let ax = rec.p1[0] - rec.p0[0];
    let ay = rec.p1[1] - rec.p0[1];
    const length = Math.hypot(ax, ay);
    [ax, ay] = length < 1e-12 ? [1, 0] : [ax / length, ay / length];
    const r = Math.hypot(rec.u, rec.v);
    const n = r > 1e-9 ? [rec.u / r, rec.v / r] : [ay, -ax];
    const along = (p) => p[0] * ax + p[1] * ay;
    const pieces = rec.segments
      .map(([a, b]) => (along(b) >= along(a) ? [a, b] : [b, a]))
      .sort((s, t) => along(s[0]) - along(t[0]));
    const gaps = [];
    for (let i = 1; i < pieces.length; i++) {
      if (along(pieces[i][0]) - along(pieces[i - 1][1]) > 1e-9) {
        gaps.push([pieces[i - 1][1], pieces[i][0]]);
      }
    }
    const box = [Infinity, Infinity, -Infinity, -Infinity];
    let maxHalf = 0;
    const bands = pieces.map(([a, b]) => {
      const upper = [];
      const lower = [];
      for (let i = 0; i <= 4; i++) { // five points: the band bulges between the ends
        const x = a[0] + (i / 4) * (b[0] - a[0]);
        const y = a[1] + (i / 4) * (b[1] - a[1]);
        const h = halfWidth(rec, n, x, y);
        maxHalf = Math.max(maxHalf, h);
        upper.push([x + h * n[0], y + h * n[1]]);
        lower.push([x - h * n[0], y - h * n[1]]);
      }
      const polygon = upper.concat(lower.reverse());
      for (const [x, y] of polygon) {
        box[0] = Math.min(box[0], x);
        box[1] = Math.min(box[1], y);
        box[2] = Math.max(box[2], x);
        box[3] = Math.max(box[3], y);
      }
      return polygon;
    });
    const first = pieces[0][0];
    const last = pieces[pieces.length - 1][1];
    return {
      rec,
      pieces,
      gaps,
      bands,
      box,
      maxHalf,
      n,
      middle: [(first[0] + last[0]) / 2, (first[1] + last[1]) / 2],
      extent: Math.hypot(last[0] - first[0], last[1] - first[1]),
      length, // |p1 - p0|, as `wallmap query`
      sigma: Math.sqrt(Math.max(rec.cov[0][0], rec.cov[1][1])), // as `wallmap query`
    };
  }

  // --- view -------------------------------------------------------------------------------------

  function shown(g) {
    return !g.rec.tentative || $("show-tentative").checked;
  }

  function contentBox() {
    const box = [Infinity, Infinity, -Infinity, -Infinity];
    const add = (x, y) => {
      box[0] = Math.min(box[0], x);
      box[1] = Math.min(box[1], y);
      box[2] = Math.max(box[2], x);
      box[3] = Math.max(box[3], y);
    };
    for (const g of map.walls.values()) {
      if (shown(g)) {
        add(g.box[0], g.box[1]);
        add(g.box[2], g.box[3]);
      }
    }
    for (const row of map.trajectory) add(row[1], row[2]);
    if (latest.pose) add(latest.pose.x, latest.pose.y);
    return box[0] <= box[2] ? box : null;
  }

  function fit() {
    const box = contentBox();
    if (!box) return;
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    const sx = (w - 2 * FIT_MARGIN_PX) / Math.max(box[2] - box[0], 1e-3);
    const sy = (h - 2 * FIT_MARGIN_PX) / Math.max(box[3] - box[1], 1e-3);
    view.scale = clampScale(Math.min(sx, sy));
    view.ox = w / 2 - ((box[0] + box[2]) / 2) * view.scale;
    view.oy = h / 2 + ((box[1] + box[3]) / 2) * view.scale;
  }

  function clampScale(s) {
    return Math.min(Math.max(s, SCALE_LIMITS[0]), SCALE_LIMITS[1]);
  }

  function schedule() {
    if (!scheduled) {
      scheduled = true;
      requestAnimationFrame(draw);
    }
  }

  // --- drawing ------------------------------------------------------------------------------------

  function draw() {
    scheduled = false;
    const t0 = performance.now();
    const dpr = window.devicePixelRatio || 1;
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr);
      canvas.height = Math.round(h * dpr);
    }
    if (view.follow) fit();
    const s = view.scale;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = COLOUR.background;
    ctx.fillRect(0, 0, w, h);

    // Only the walls whose box meets the window are drawn (and listed as drawn).
    const x0 = -view.ox / s;
    const x1 = (w - view.ox) / s;
    const y0 = (view.oy - h) / s;
    const y1 = view.oy / s;
    visible = [];
    for (const g of map.walls.values()) {
      const b = g.box;
      if (shown(g) && b[2] >= x0 && b[0] <= x1 && b[3] >= y0 && b[1] <= y1) visible.push(g);
    }
    const confirmed = visible.filter((g) => !g.rec.tentative);
    const tentative = visible.filter((g) => g.rec.tentative);

    // Map-frame drawing: a path per layer (a fill per band), widths in CSS pixels (1 / s m).
    ctx.setTransform(dpr * s, 0, 0, -dpr * s, dpr * view.ox, dpr * view.oy);
    const px = 1 / s;
    const wide = (g) => g.maxHalf * s >= 1; // narrower bands hide under the wall's line
    drawRooms();
    fillPolygons(confirmed.filter(wide).flatMap((g) => g.bands), COLOUR.band);
    fillPolygons(tentative.filter(wide).flatMap((g) => g.bands), COLOUR.tentativeBand);
    strokeLines(visible.flatMap((g) => g.gaps), COLOUR.gap, 1.2 * px);
    drawTrajectory(px);
    const hovered = visible.find((g) => g.rec.id === hoveredId);
    if (hovered) strokeLines(hovered.pieces, COLOUR.hover, 7 * px); // an outline under it
    strokeLines(confirmed.flatMap((g) => g.pieces), COLOUR.wall, 3 * px);
    ctx.setLineDash([6 * px, 4 * px]);
    strokeLines(tentative.flatMap((g) => g.pieces), COLOUR.tentative, 2 * px);
    ctx.setLineDash([]);
    strokeLines(map.doors.map((d) => [d.p0, d.p1]), COLOUR.door, 5 * px);
    drawLatest(px);

    // Screen drawing: text reads upright.
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    drawLabels(s);
    drawRoomLabels(s);
    drawScaleBar(s, h);
    report(t0);
    showTip(hovered);
  }

  // Rooms under everything, each its own colour by id; the mapper's outlines are in metres.
  function drawRooms() {
    ctx.globalAlpha = ROOM_ALPHA;
    for (const room of map.rooms) {
      if (room.polygon.length < 3) continue;
      fillPolygons([room.polygon], COLOUR.rooms[room.id % COLOUR.rooms.length]);
    }
    ctx.globalAlpha = 1;
  }

  function drawRoomLabels(s) {
    ctx.font = "12px sans-serif";
    ctx.textAlign = "center";
    ctx.textBaseline = "middle";
    ctx.fillStyle = COLOUR.label;
    for (const room of map.rooms) {
      const [x, y] = room.centroid;
      ctx.fillText(`room ${room.id}: ${room.area.toFixed(1)} m²`, view.ox + x * s, view.oy - y * s);
    }
  }

  // The room under the pointer (map-frame point in its outline), for the tip.
  function roomAt(mx, my) {
    const x = (mx - view.ox) / view.scale;
    const y = (view.oy - my) / view.scale;
    return map.rooms.find((room) => inside(x, y, room.polygon)) || null;
  }

  function inside(x, y, polygon) {
    let odd = false;
    for (let i = 0, j = polygon.length - 1; i < polygon.length; j = i++) {
      const [xi, yi] = polygon[i];
      const [xj, yj] = polygon[j];
      if (yi > y !== yj > y && x < xi + ((y - yi) * (xj - xi)) / (yj - yi)) odd = !odd;
    }
    return odd;
  }

  // One fill per polygon: a single path of thousands of overlapping polygons takes the
  // rasteriser ten times longer.
  function fillPolygons(polygons, colour) {
    ctx.fillStyle = colour;
    for (const polygon of polygons) {
      ctx.beginPath();
      ctx.moveTo(polygon[0][0], polygon[0][1]);
      for (let i = 1; i < polygon.length; i++) ctx.lineTo(polygon[i][0], polygon[i][1]);
      ctx.closePath();
      ctx.fill();
    }
  }

  function strokeLines(lines, colour, width) {
    ctx.beginPath();
    for (const [a, b] of lines) {
      ctx.moveTo(a[0], a[1]);
      ctx.lineTo(b[0], b[1]);
    }
    ctx.strokeStyle = colour;
    ctx.lineWidth = width;
    ctx.stroke();
  }

  // The mapper's keyframes, then the poses since the last of them, up to the robot.
  function drawTrajectory(px) {
    const path = map.trajectory.map((row) => [row[1], row[2]]).concat(latest.recent || []);
    if (path.length === 0) return;
    ctx.beginPath();
    ctx.moveTo(path[0][0], path[0][1]);
    for (const [x, y] of path) ctx.lineTo(x, y);
    ctx.strokeStyle = COLOUR.trajectory;
    ctx.lineWidth = 1.5 * px;
    ctx.lineJoin = "round";
    ctx.stroke();
    disc(path[0][0], path[0][1], 4 * px, COLOUR.trajectory); // where it started
  }

  function disc(x, y, radius, colour) {
    ctx.beginPath();
    ctx.arc(x, y, radius, 0, 2 * Math.PI);
    ctx.fillStyle = colour;
    ctx.fill();
  }

  // The detector's walls of the newest frame and the robot (a triangle pointing along its yaw).
  function drawLatest(px) {
    const obs = latest.observations;
    if (obs && obs.walls.length) {
      const lines = obs.walls.map((w) => [w.p0, w.p1]);
      strokeLines(lines, COLOUR.observation, 2.5 * px);
      for (const [a, b] of lines) {
        disc(a[0], a[1], 3 * px, COLOUR.observation);
        disc(b[0], b[1], 3 * px, COLOUR.observation);
      }
    }
    const pose = latest.pose;
    if (!pose) return;
    const c = Math.cos(pose.yaw);
    const sn = Math.sin(pose.yaw);
    const at = (f, l) => [pose.x + (f * c - l * sn) * px, pose.y + (f * sn + l * c) * px];
    const corners = [at(12, 0), at(-7, 7), at(-4, 0), at(-7, -7)];
    ctx.beginPath();
    ctx.moveTo(...corners[0]);
    for (const p of corners.slice(1)) ctx.lineTo(...p);
    ctx.closePath();
    ctx.fillStyle = COLOUR.trajectory;
    ctx.fill();
  }

  function drawLabels(s) {
    const labelled = visible.filter((g) => g.extent * s >= LABEL_MIN_PX);
    ctx.font = "11px sans-serif";
    ctx.textAlign = "center";
    ctx.textBaseline = "middle";
    ctx.lineJoin = "round";
    const halo = labelled.length <= HALO_MAX;
    for (const g of labelled) {
      // Beside the wall's middle, on the side its normal points to (away from the origin).
      const x = view.ox + g.middle[0] * s + 9 * g.n[0];
      const y = view.oy - g.middle[1] * s - 9 * g.n[1];
      const text = String(g.rec.id);
      if (halo) {
        ctx.strokeStyle = COLOUR.background;
        ctx.lineWidth = 3;
        ctx.strokeText(text, x, y);
      }
      ctx.fillStyle = COLOUR.label;
      ctx.fillText(text, x, y);
    }
  }

  // 1, 2 or 5 x 10^k metres, at least 60 px long.
  function drawScaleBar(s, h) {
    const exponent = Math.floor(Math.log10(60 / s));
    const metres = [1, 2, 5, 10].map((m) => m * 10 ** exponent).find((m) => m * s >= 60);
    const x = 12;
    const y = h - 14;
    ctx.fillStyle = COLOUR.label;
    ctx.fillRect(x, y - 1, metres * s, 3);
    ctx.textAlign = "left";
    ctx.fillText(`${+metres.toPrecision(3)} m`, x + metres * s + 6, y);
  }

  // Timings and the drawn ids, in the DOM for people and for scripts. The draw time is the
  // script's; the browser rasterises the canvas after it, so the frame time runs from the start
  // of the draw to the start of the next frame.
  function report(t0) {
    const ms = performance.now() - t0;
    frames += 1;
    Object.assign(canvas.dataset, {
      renderMs: ms.toFixed(2),
      frames,
      scale: view.scale,
      ox: view.ox,
      oy: view.oy,
    });
    const count = visible.length;
    requestAnimationFrame(() => {
      const frameMs = performance.now() - t0;
      canvas.dataset.frameMs = frameMs.toFixed(2);
      $("render").textContent =
        `${count} walls drawn in ${ms.toFixed(1)} ms, on screen in ${frameMs.toFixed(0)} ms`;
    });
    // A wall that only turns confirmed (or back) must be listed again too.
    const key = visible.map((g) => `${g.rec.id}${g.rec.tentative ? "t" : ""}`).join(",");
    if (key === drawnKey) return;
    drawnKey = key;
    $("drawn").replaceChildren(
      ...visible.map((g) => {
        const li = document.createElement("li");
        li.dataset.id = g.rec.id;
        li.dataset.tentative = g.rec.tentative;
        li.textContent = g.rec.id;
        return li;
      }),
    );
  }

  // --- hovering -----------------------------------------------------------------------------------

  function nearest(mx, my) {
    const s = view.scale;
    const x = (mx - view.ox) / s;
    const y = (view.oy - my) / s;
    let best = null;
    let bestDistance = HOVER_PX / s;
    for (const g of visible) {
      const b = g.box;
      if (x < b[0] - bestDistance || x > b[2] + bestDistance) continue;
      if (y < b[1] - bestDistance || y > b[3] + bestDistance) continue;
      for (const [a, c] of g.pieces) {
        const d = distanceToSegment(x, y, a, c);
        if (d < bestDistance) [best, bestDistance] = [g, d];
      }
    }
    return best;
  }

  function distanceToSegment(x, y, a, b) {
    const dx = b[0] - a[0];
    const dy = b[1] - a[1];
    const t = Math.max(0, Math.min(1, ((x - a[0]) * dx + (y - a[1]) * dy) / (dx * dx + dy * dy || 1)));
    return Math.hypot(x - a[0] - t * dx, y - a[1] - t * dy);
  }

  function showTip(g) {
    const room = !g && pointer && !drag ? roomAt(pointer.x, pointer.y) : null;
    if (room) {
      const doors = map.doors.filter((d) => room.doors.includes(d.id));
      tip.textContent = [
        `room ${room.id}${room.closed ? "" : " (open: not all of it seen)"}`,
        `area   ${room.area.toFixed(2)} m²`,
        `walls  ${room.walls.join(", ") || "-"}`,
        ...doors.map((d) => `door ${d.id}: ${d.width.toFixed(2)} m to ${d.rooms.filter((r) => r !== room.id).join(", ") || "unexplored"}`),
      ].join("\n");
      placeTip();
      return;
    }
    if (!g || !pointer || drag) {
      tip.hidden = true;
      return;
    }
    const r = g.rec;
    tip.textContent = [
      `wall ${r.id}${r.tentative ? " (tentative)" : ""}`,
      `u      ${r.u.toFixed(3)} m`,
      `v      ${r.v.toFixed(3)} m`,
      `sigma  ${g.sigma.toFixed(4)} m`,
      `n_obs  ${r.n_obs} (${r.n_views} views)`,
      `length ${g.length.toFixed(2)} m, ${g.pieces.length} segment${g.pieces.length > 1 ? "s" : ""}`,
    ].join("\n");
    placeTip();
  }

  function placeTip() {
    tip.hidden = false;
    const room = canvas.clientWidth - tip.offsetWidth - 4;
    tip.style.left = `${Math.min(pointer.x + 14, room)}px`;
    tip.style.top = `${pointer.y + 14}px`;
  }

  function zoomAt(mx, my, factor) {
    const s = clampScale(view.scale * factor);
    view.ox = mx - ((mx - view.ox) * s) / view.scale;
    view.oy = my - ((my - view.oy) * s) / view.scale;
    view.scale = s;
    view.follow = false;
    schedule();
  }

  function refit() {
    view.follow = true;
    schedule();
  }

  function canvasPoint(e) {
    const r = canvas.getBoundingClientRect();
    return { x: e.clientX - r.left, y: e.clientY - r.top };
  }

  canvas.addEventListener("pointerdown", (e) => {
    drag = canvasPoint(e);
    canvas.setPointerCapture(e.pointerId);
    canvas.classList.add("dragging");
  });
  canvas.addEventListener("pointermove", (e) => {
    pointer = canvasPoint(e);
    if (drag) {
      view.ox += pointer.x - drag.x;
      view.oy += pointer.y - drag.y;
      view.follow = false;
      drag = pointer;
      schedule();
      return;
    }
    const g = nearest(pointer.x, pointer.y);
    const id = g ? g.rec.id : null;
    if (id !== hoveredId) {
      hoveredId = id;
      schedule();
    } else {
      showTip(g);
    }
  });
  const endDrag = () => {
    drag = null;
    canvas.classList.remove("dragging");
  };
  canvas.addEventListener("pointerup", endDrag);
  canvas.addEventListener("pointercancel", endDrag);
  canvas.addEventListener("pointerleave", () => {
    pointer = null;
    hoveredId = null;
    schedule();
  });
  canvas.addEventListener(
    "wheel",
    (e) => {
      e.preventDefault();
      const p = canvasPoint(e);
      const step = e.deltaMode === WheelEvent.DOM_DELTA_LINE ? 0.05 : 0.0015;
      zoomAt(p.x, p.y, Math.exp(-e.deltaY * step));
    },
    { passive: false },
  );
  canvas.addEventListener("dblclick", refit);
  $("fit").addEventListener("click", refit);
  $("show-tentative").addEventListener("change", schedule);
  document.addEventListener("keydown", (e) => {
    const typing = e.target instanceof HTMLInputElement;
    if (e.key.toLowerCase() === "f" && !typing && !e.ctrlKey && !e.metaKey && !e.altKey) refit();
  });
  window.addEventListener("resize", schedule);

  // --- the feed -----------------------------------------------------------------------------------

  async function getJSON(path) {
    const response = await fetch(path, { cache: "no-store" });
    if (!response.ok) throw new Error(`${path}: HTTP ${response.status}`);
    return response.json();
  }

  // Fold in GET /api/map?since=N: the walls that changed and the ids that went (or everything).
  function applyMap(delta) {
    if (delta.version === map.version) return false;
    if (delta.full) map.walls.clear();
    for (const rec of delta.walls) map.walls.set(rec.id, geometry(rec));
    for (const id of delta.removed) map.walls.delete(id);
    if (delta.trajectory) map.trajectory = delta.trajectory;
    if (delta.rooms) Object.assign(map, { rooms: delta.rooms.rooms, doors: delta.rooms.doors });
    Object.assign(map, { version: delta.version, frames: delta.frames, observations: delta.observations });
    document.body.dataset.version = map.version;
    let tentative = 0;
    for (const g of map.walls.values()) tentative += g.rec.tentative ? 1 : 0;
    $("summary").textContent =
      `${map.walls.size} walls (${tentative} tentative), ${map.rooms.length} rooms, ` +
      `${map.doors.length} doors from ${map.frames} frames, ${map.observations} observations`;
    return true;
  }

  function applyLatest(now) {
    const key = JSON.stringify(now);
    if (key === latestKey) return false;
    latestKey = key;
    latest = now;
    return true;
  }

  function setStatus(text) {
    const status = $("status");
    status.textContent = text || "live";
    status.classList.toggle("warn", Boolean(text));
  }

  async function poll() {
    try {
      const [delta, now] = await Promise.all([
        getJSON(`api/map?since=${map.version}`),
        getJSON("api/latest"),
      ]);
      const changed = applyMap(delta);
      if (applyLatest(now) || changed) schedule();
      setStatus(now.status);
    } catch (err) {
      setStatus(`the view server does not answer (${err.message})`);
    }
    setTimeout(poll, POLL_MS);
  }

  poll();
})();
