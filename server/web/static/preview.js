// The scene preview: a scene document (the JSON `owcsim run` takes) drawn from above (x, y) and from the side
// (x, z) as two SVG views in metres with axes. Drawn: the room, furniture boxes, meshes (the bounding box of
// inline vertices), luminaires (transmitters) with an arrow along their normal, receivers (and angle-diversity
// receivers) with theirs, receiver grids (map planes), lighting task areas, and the smoke region (a medium's
// box or mesh region, a grid medium's box, or the whole room; a timeline's inline frames), and the moving receivers'
// trajectories (a timeline's waypoints or positions). Every device is one element with its class
// (luminaire, receiver) and data-id, so that tests can count them.

import { esc, fmt, niceTicks } from "./plots.js";

/** The two views: which scene axes go across and up. */
export const VIEWS = [
  { name: "top", title: "From above (x, y)", ax: 0, ay: 1, labels: ["x [m]", "y [m]"], depth: 2 },
  { name: "side", title: "From the side (x, z)", ax: 0, ay: 2, labels: ["x [m]", "z [m]"], depth: 1 },
];

const norm = (v) => {
  const n = Math.hypot(...v) || 1;
  return v.map((c) => c / n);
};
const add = (p, v, s = 1) => p.map((c, i) => c + s * v[i]);

/** Axis-aligned bounding box [min, max] of points. */
function bbox(points) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (const p of points) {
    for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], p[k]);
      hi[k] = Math.max(hi[k], p[k]);
    }
  }
  return [lo, hi];
}

/** The corners of a receiver grid's rectangle [m]. */
export function gridCorners(g) {
  const u = norm(g.u || [1, 0, 0]);
  const v = norm(g.v || [0, 1, 0]);
  const [su, sv] = g.size;
  return [g.origin, add(g.origin, u, su), add(add(g.origin, u, su), v, sv), add(g.origin, v, sv)];
}

/** Smoke over time (a timeline's `frames`, in place of `medium`): inline frames as their grid's box; frames read
 * from files are placed when the job runs, so they get a note and no box. Null without frames. */
function framesBox(scene) {
  const fr = scene.timeline && scene.timeline.frames;
  if (!fr) return null;
  if (fr.min && fr.max) return { box: [fr.min, fr.max], note: `smoke over time: ${(fr.times || []).length} ${fr.type} frames on a grid` };
  return { box: null, note: `smoke over time from ${fr.type} frames (placed when the job reads them; not drawn)` };
}

/** The medium's region as a box [min, max] (null: not drawn) and a note, or null without a medium. */
export function smokeBox(scene, roomBox) {
  const med = scene.medium;
  if (!med) return framesBox(scene);
  if (med.min && med.max) return { box: [med.min, med.max], note: `${med.type} medium` };
  const reg = med.region || { type: "scene" };
  if (reg.type === "box") return { box: [reg.min, reg.max], note: `${med.type} medium, box region` };
  if (reg.type === "mesh" && reg.vertices) return { box: bbox(reg.vertices), note: `${med.type} medium, mesh region (its bounding box)` };
  return roomBox ? { box: roomBox, note: `${med.type} medium in the whole scene` } : null;
}

/** What the preview draws, in scene coordinates: one list per kind (used by both views). */
export function sceneParts(scene) {
  const room = scene.room ? [scene.room.origin || [0, 0, 0], (scene.room.origin || [0, 0, 0]).map((o, k) => o + scene.room.size[k])] : null;
  const furniture = (scene.furniture || []).map((b, k) => ({ box: [b.min, b.max], name: b.name || `furniture[${k}]` }));
  const meshes = [];
  const fileMeshes = [];
  (scene.meshes || []).forEach((m, k) => {
    const name = m.name || `meshes[${k}]`;
    if (m.vertices && m.vertices.length) meshes.push({ box: bbox(m.vertices), name });
    else fileMeshes.push(name);
  });
  const tx = (scene.transmitters || []).map((t, k) => ({ id: t.id || `tx${k}`, p: t.position, n: norm(t.normal) }));
  const rx = (scene.receivers || []).map((r, k) => ({ id: r.id || `rx${k}`, p: r.position, n: norm(r.normal) }));
  const adr = (scene.angle_diversity_receivers || []).map((r, k) => ({ id: r.id || `adr${k}`, p: r.position, n: norm(r.normal || [0, 0, 1]) }));
  const grids = (scene.receiver_grids || []).map((g) => ({ id: g.id_prefix || "grid", corners: gridCorners(g) }));
  const areas = ((scene.lighting && scene.lighting.task_areas) || []).map((a) => ({ box: [a.min, a.max], name: a.name }));
  const smoke = smokeBox(scene, room);
  // moving receivers (a timeline's trajectories): the points they pass through, in order
  const walks = ((scene.timeline && scene.timeline.trajectories) || [])
    .map((t) => ({ device: t.device, pts: t.waypoints || t.positions || [] }))
    .filter((w) => w.pts.length);
  return { room, furniture, meshes, fileMeshes, tx, rx, adr, grids, areas, smoke, walks };
}

function extentOf(parts) {
  const pts = [];
  const boxes = [parts.room, ...parts.furniture.map((b) => b.box), ...parts.meshes.map((b) => b.box), ...parts.areas.map((b) => b.box)];
  if (parts.smoke) boxes.push(parts.smoke.box);
  for (const b of boxes) if (b) pts.push(b[0], b[1]);
  for (const d of [...parts.tx, ...parts.rx, ...parts.adr]) pts.push(d.p);
  for (const g of parts.grids) pts.push(...g.corners);
  for (const w of parts.walks) pts.push(...w.pts);
  return bbox(pts.length ? pts : [[0, 0, 0], [1, 1, 1]]);
}

/** One view's SVG markup. */
export function viewSvg(parts, view, width = 440) {
  const [lo, hi] = extentOf(parts);
  const { ax, ay } = view;
  const span = Math.max(hi[ax] - lo[ax], hi[ay] - lo[ay], 1e-3);
  const pad = 0.06 * span;
  const x0 = lo[ax] - pad;
  const x1 = hi[ax] + pad;
  const y0 = lo[ay] - pad;
  const y1 = hi[ay] + pad;
  const m = { l: 44, r: 12, t: 12, b: 38 };
  const s = (width - m.l - m.r) / (x1 - x0);
  const height = Math.round(m.t + m.b + s * (y1 - y0));
  const X = (p) => Math.round((m.l + (p[ax] - x0) * s) * 100) / 100;
  const Y = (p) => Math.round((height - m.b - (p[ay] - y0) * s) * 100) / 100;
  const rect = (box, cls, name) => {
    const [a, b] = box;
    const xa = Math.min(X(a), X(b));
    const ya = Math.min(Y(a), Y(b));
    return `<rect class="${cls}" x="${xa}" y="${ya}" width="${Math.max(Math.abs(X(b) - X(a)), 1)}" height="${Math.max(Math.abs(Y(b) - Y(a)), 1)}" data-name="${esc(name)}"><title>${esc(name)}</title></rect>`;
  };
  const out = [`<svg xmlns="http://www.w3.org/2000/svg" class="preview-view" data-view="${view.name}" viewBox="0 0 ${width} ${height}" width="${width}" height="${height}">`];
  out.push(
    '<defs><marker id="arrow-' + view.name + '" viewBox="0 0 10 10" refX="8" refY="5" markerWidth="6" markerHeight="6" orient="auto-start-reverse"><path d="M0,0L10,5L0,10z" class="arrowhead"/></marker></defs>',
  );
  // axes in metres
  const tx = niceTicks(x0, x1, 6);
  const ty = niceTicks(y0, y1, 5);
  out.push(`<g class="axes"><rect class="frame" x="${m.l}" y="${m.t}" width="${width - m.l - m.r}" height="${height - m.t - m.b}"/>`);
  for (const t of tx) {
    const p = [0, 0, 0];
    p[ax] = t;
    out.push(`<line class="tickmark" x1="${X(p)}" x2="${X(p)}" y1="${height - m.b}" y2="${height - m.b + 4}"/><text class="tick" x="${X(p)}" y="${height - m.b + 15}" text-anchor="middle">${fmt(t, 3)}</text>`);
  }
  for (const t of ty) {
    const p = [0, 0, 0];
    p[ay] = t;
    out.push(`<line class="tickmark" x1="${m.l - 4}" x2="${m.l}" y1="${Y(p)}" y2="${Y(p)}"/><text class="tick" x="${m.l - 6}" y="${Y(p) + 4}" text-anchor="end">${fmt(t, 3)}</text>`);
  }
  out.push(`<text class="label" x="${(m.l + width - m.r) / 2}" y="${height - 4}" text-anchor="middle">${view.labels[0]}</text>`);
  out.push(`<text class="label" transform="translate(12 ${(m.t + height - m.b) / 2}) rotate(-90)" text-anchor="middle">${view.labels[1]}</text></g>`);
  if (parts.room) out.push(rect(parts.room, "room", "room"));
  if (parts.smoke && parts.smoke.box) out.push(rect(parts.smoke.box, "smoke", parts.smoke.note));
  for (const g of parts.grids) {
    const pts = g.corners.map((c) => `${X(c)},${Y(c)}`).join(" ");
    out.push(`<polygon class="map-plane" points="${pts}" data-grid="${esc(g.id)}"><title>receiver grid ${esc(g.id)}</title></polygon>`);
  }
  for (const a of parts.areas) out.push(rect(a.box, "task-area", `task area ${a.name}`));
  for (const b of parts.furniture) out.push(rect(b.box, "furniture", b.name));
  for (const b of parts.meshes) out.push(rect(b.box, "mesh", `${b.name} (bounding box)`));
  for (const w of parts.walks) {
    const pts = w.pts.map((c) => `${X(c)},${Y(c)}`).join(" ");
    out.push(`<polyline class="trajectory" points="${pts}" data-device="${esc(w.device)}"><title>${esc(`${w.device} moves through ${w.pts.length} point(s)`)}</title></polyline>`);
  }
  const L = 0.08 * span; // arrow length [m]
  const device = (d, cls, shape) => {
    const tip = add(d.p, d.n, L);
    const dx = X(tip) - X(d.p);
    const dy = Y(tip) - Y(d.p);
    const label = `${d.id} at (${d.p.map((c) => fmt(c, 4)).join(", ")}) m, normal (${d.n.map((c) => fmt(c, 3)).join(", ")})`;
    const g = [`<g class="${cls}" data-id="${esc(d.id)}"><title>${esc(label)}</title>`];
    if (Math.hypot(dx, dy) > 0.2 * L * s) {
      g.push(`<line class="normal" x1="${X(d.p)}" y1="${Y(d.p)}" x2="${X(tip)}" y2="${Y(tip)}" marker-end="url(#arrow-${view.name})"/>`);
    } else {
      // the normal points at or away from the viewer: a dot (towards) or a cross (away), as in drawings
      const toward = d.n[view.depth] * (view.name === "side" ? -1 : 1) > 0;
      const c = `${X(d.p)},${Y(d.p)}`;
      g.push(toward ? `<circle class="normal toward" cx="${X(d.p)}" cy="${Y(d.p)}" r="9"/>` : `<path class="normal away" d="M${X(d.p) - 9},${Y(d.p) - 9}l18,18m0,-18l-18,18" data-at="${c}"/>`);
    }
    g.push(shape(X(d.p), Y(d.p)));
    g.push("</g>");
    return g.join("");
  };
  for (const d of parts.tx) out.push(device(d, "luminaire", (x, y) => `<circle class="mark" cx="${x}" cy="${y}" r="5"/>`));
  for (const d of parts.rx) out.push(device(d, "receiver", (x, y) => `<rect class="mark" x="${x - 4}" y="${y - 4}" width="8" height="8"/>`));
  for (const d of parts.adr) out.push(device(d, "receiver adr", (x, y) => `<path class="mark" d="M${x},${y - 6}L${x + 6},${y + 5}L${x - 6},${y + 5}z"/>`));
  out.push("</svg>");
  return out.join("");
}

/** The 12 edges of a box [min, max] as pairs of corners. */
function boxEdges([a, b]) {
  const c = (i) => [i & 1 ? b[0] : a[0], i & 2 ? b[1] : a[1], i & 4 ? b[2] : a[2]];
  const out = [];
  for (let i = 0; i < 8; i++) for (const bit of [1, 2, 4]) if (!(i & bit)) out.push([c(i), c(i | bit)]);
  return out;
}

/**
 * The 3D view: an orthographic projection turned by `azimuth` about z and tilted by `elevation` [rad] (own
 * projection, no library): wireframes of the room, furniture, meshes' boxes and the smoke, the map planes, and
 * every device with its normal. Same classes and data-id as the two flat views.
 */
export function view3dSvg(parts, azimuth, elevation, width = 440, height = 340) {
  const [lo, hi] = extentOf(parts);
  const centre = lo.map((v, k) => (v + hi[k]) / 2);
  const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-3);
  const [ca, sa, ce, se] = [Math.cos(azimuth), Math.sin(azimuth), Math.cos(elevation), Math.sin(elevation)];
  const s = (0.62 * Math.min(width, height)) / span;
  const P = (p) => {
    const [x, y, z] = p.map((v, k) => v - centre[k]);
    const u = ca * x - sa * y;
    const w = sa * x + ca * y;
    const r2 = (v) => Math.round(v * 100) / 100;
    return [r2(width / 2 + s * u), r2(height / 2 - s * (ce * z + se * w))]; // w: away from the viewer (right-handed)
  };
  const line = (a, b, cls) => {
    const [pa, pb] = [P(a), P(b)];
    return `<line class="${cls}" x1="${pa[0]}" y1="${pa[1]}" x2="${pb[0]}" y2="${pb[1]}"/>`;
  };
  const out = [`<svg xmlns="http://www.w3.org/2000/svg" class="preview-view view3d" data-view="3d" viewBox="0 0 ${width} ${height}" width="${width}" height="${height}">`];
  out.push('<defs><marker id="arrow-3d" viewBox="0 0 10 10" refX="8" refY="5" markerWidth="6" markerHeight="6" orient="auto-start-reverse"><path d="M0,0L10,5L0,10z" class="arrowhead"/></marker></defs>');
  // the axes at the scene's lowest corner, one metre long
  const o = lo;
  for (const [k, name] of [[0, "x"], [1, "y"], [2, "z"]]) {
    const e = [...o];
    e[k] += Math.min(1, span / 3);
    const pe = P(e);
    out.push(`${line(o, e, `axis axis-${name}`)}<text class="tick" x="${pe[0] + 3}" y="${pe[1] - 3}">${name}</text>`);
  }
  if (parts.room) out.push(`<g class="room">${boxEdges(parts.room).map(([a, b]) => line(a, b, "edge")).join("")}</g>`);
  if (parts.smoke && parts.smoke.box) out.push(`<g class="smoke"><title>${esc(parts.smoke.note)}</title>${boxEdges(parts.smoke.box).map(([a, b]) => line(a, b, "edge")).join("")}</g>`);
  for (const g of parts.grids) {
    out.push(`<polygon class="map-plane" points="${g.corners.map((c) => P(c).join(",")).join(" ")}" data-grid="${esc(g.id)}"><title>receiver grid ${esc(g.id)}</title></polygon>`);
  }
  for (const b of parts.furniture) out.push(`<g class="furniture" data-name="${esc(b.name)}"><title>${esc(b.name)}</title>${boxEdges(b.box).map(([a, c]) => line(a, c, "edge")).join("")}</g>`);
  for (const b of parts.meshes) out.push(`<g class="mesh" data-name="${esc(b.name)}"><title>${esc(b.name)}</title>${boxEdges(b.box).map(([a, c]) => line(a, c, "edge")).join("")}</g>`);
  for (const w of parts.walks) out.push(`<polyline class="trajectory" points="${w.pts.map((c) => P(c).join(",")).join(" ")}" data-device="${esc(w.device)}"><title>${esc(w.device)}</title></polyline>`);
  const L = 0.08 * span;
  const device = (d, cls, r) => {
    const [px, py] = P(d.p);
    return `<g class="${cls}" data-id="${esc(d.id)}"><title>${esc(d.id)}</title><line class="normal" x1="${px}" y1="${py}" x2="${P(add(d.p, d.n, L))[0]}" y2="${P(add(d.p, d.n, L))[1]}" marker-end="url(#arrow-3d)"/><circle class="mark" cx="${px}" cy="${py}" r="${r}"/></g>`;
  };
  for (const d of parts.tx) out.push(device(d, "luminaire", 5));
  for (const d of parts.rx) out.push(device(d, "receiver", 4));
  for (const d of parts.adr) out.push(device(d, "receiver adr", 4));
  out.push("</svg>");
  return out.join("");
}

/** Draw the 3D view into `box` and let the pointer turn it (drag: azimuth and elevation). */
function mount3d(box, parts) {
  let az = -0.6;
  let el = 0.45;
  const draw = () => {
    box.innerHTML = view3dSvg(parts, az, el);
  };
  draw();
  let drag = null;
  box.addEventListener("pointerdown", (ev) => {
    drag = [ev.clientX, ev.clientY, az, el];
    box.setPointerCapture(ev.pointerId);
  });
  box.addEventListener("pointermove", (ev) => {
    if (!drag) return;
    az = drag[2] + (ev.clientX - drag[0]) * 0.01;
    el = Math.min(Math.max(drag[3] + (ev.clientY - drag[1]) * 0.01, -1.5), 1.5);
    draw();
  });
  box.addEventListener("pointerup", () => {
    drag = null;
  });
}

/** Draw the preview of `scene` into `container`: the two views, the 3D view, a legend and what is not drawn. */
export function drawPreview(container, scene) {
  const parts = sceneParts(scene);
  const views = VIEWS.map((v) => `<figure class="preview-fig"><figcaption>${v.title}</figcaption>${viewSvg(parts, v)}</figure>`);
  views.push('<figure class="preview-fig"><figcaption>3D (drag to turn)</figcaption><div class="view3d-box"></div></figure>');
  const notes = [];
  if (parts.fileMeshes.length) notes.push(`meshes given as files are not drawn: ${parts.fileMeshes.map(esc).join(", ")}`);
  if (parts.smoke) notes.push(`smoke: ${esc(parts.smoke.note)}`);
  const counts = `${parts.tx.length} luminaire(s), ${parts.rx.length + parts.adr.length} receiver(s), ${parts.grids.length} receiver grid(s)`;
  container.innerHTML = `<div class="preview-views">${views.join("")}</div>
<p class="legend"><span class="key luminaire-key">● luminaire (arrow: its normal)</span>
<span class="key receiver-key">■ receiver</span> <span class="key grid-key">▭ receiver grid</span>
<span class="key furniture-key">▭ furniture</span> <span class="key smoke-key">▭ smoke</span>${parts.walks.length ? ' <span class="key trajectory-key">⟶ receiver\'s walk</span>' : ""}
<span class="key">⊗ / ⊙ normal into / out of the view</span></p>
<p class="preview-counts">${counts}${notes.length ? "; " + notes.join("; ") : ""}</p>`;
  mount3d(container.querySelector(".view3d-box"), parts);
  return parts;
}
