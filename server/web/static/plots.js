// Small SVG plots of our own (no plotting library): line plots with error bands, bar charts with error bars,
// heatmaps with a colour bar, and the axes they share. Each function returns SVG markup (one string, set with
// innerHTML: fast for thousands of elements); every plotted number is kept in a data attribute (data-value,
// data-stderr, data-values) so that what is drawn can be checked against the API's numbers.

/** Escape text for HTML/SVG markup. */
export function esc(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
}

/** A number as the page prints it: `digits` significant digits, exponent form outside [1e-3, 1e5); "–" for null. */
export function fmt(x, digits = 4) {
  if (x === null || x === undefined || !Number.isFinite(x)) return "–";
  if (x === 0) return "0";
  const a = Math.abs(x);
  if (a >= 1e-3 && a < 1e5) return String(Number(x.toPrecision(digits)));
  return x.toExponential(digits - 1);
}

/** The exact number in an attribute: JavaScript's shortest round-trip form (parses back to the same double). */
export function attr(x) {
  return x === null || x === undefined || !Number.isFinite(x) ? "" : String(x);
}

/** `value ± stderr` as text (the error with 2 digits), or just the value. */
export function withError(value, stderr, digits = 4) {
  const v = fmt(value, digits);
  return stderr === null || stderr === undefined || !Number.isFinite(value) ? v : `${v} ± ${fmt(stderr, 2)}`;
}

/** Round tick positions covering [lo, hi] (about n of them). */
export function niceTicks(lo, hi, n = 5) {
  if (!(hi > lo)) return [lo];
  const raw = (hi - lo) / n;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((f) => f * mag).find((s) => s >= raw) || 10 * mag;
  const out = [];
  for (let t = Math.ceil(lo / step - 1e-9) * step; t <= hi + step * 1e-9; t += step) out.push(Math.abs(t) < step * 1e-9 ? 0 : t);
  return out;
}

/** Decades within [lo, hi] (lo > 0), thinned to at most ~8. */
export function logTicks(lo, hi) {
  const a = Math.ceil(Math.log10(lo) - 1e-9);
  const b = Math.floor(Math.log10(hi) + 1e-9);
  const every = Math.max(1, Math.ceil((b - a + 1) / 8));
  const out = [];
  for (let e = a; e <= b; e += every) out.push(10 ** e);
  return out;
}

/** A plot frame: pixel size, margins and the data -> pixel maps of both axes (y optionally logarithmic). */
export function frame({ width = 640, height = 280, xlim, ylim, logY = false, margin = {} }) {
  const m = { l: 70, r: 16, t: 12, b: 42, ...margin };
  const [x0, x1] = xlim[1] > xlim[0] ? xlim : [xlim[0] - 0.5, xlim[0] + 0.5];
  let [y0, y1] = ylim[1] > ylim[0] ? ylim : [ylim[0] - 0.5 * (Math.abs(ylim[0]) || 1), ylim[0] + 0.5 * (Math.abs(ylim[0]) || 1)];
  if (logY) [y0, y1] = [Math.log10(y0), Math.log10(y1)];
  const pw = width - m.l - m.r;
  const ph = height - m.t - m.b;
  const f = {
    width, height, m, logY, xlim: [x0, x1], ylim: logY ? [10 ** y0, 10 ** y1] : [y0, y1],
    x: (v) => m.l + ((v - x0) / (x1 - x0)) * pw,
    y: (v) => {
      const w = logY ? Math.log10(v > 0 ? v : 10 ** y0) : v;
      return m.t + ph - ((Math.min(Math.max(w, y0), y1) - y0) / (y1 - y0)) * ph;
    },
    xinv: (px) => x0 + ((px - m.l) / pw) * (x1 - x0),
  };
  return f;
}

const r2 = (v) => Math.round(v * 100) / 100;

/** Axes with ticks, grid lines and labels for a frame. */
export function axes(f, xlabel, ylabel) {
  const { m, width, height } = f;
  const bottom = height - m.b;
  const parts = [`<rect class="plot-area" x="${m.l}" y="${m.t}" width="${width - m.l - m.r}" height="${bottom - m.t}"/>`];
  for (const t of niceTicks(f.xlim[0], f.xlim[1], 6)) {
    const x = r2(f.x(t));
    parts.push(`<line class="grid" x1="${x}" x2="${x}" y1="${m.t}" y2="${bottom}"/>`);
    parts.push(`<text class="tick" x="${x}" y="${bottom + 14}" text-anchor="middle">${esc(fmt(t, 3))}</text>`);
  }
  const yt = f.logY ? logTicks(f.ylim[0], f.ylim[1]) : niceTicks(f.ylim[0], f.ylim[1], 5);
  for (const t of yt) {
    const y = r2(f.y(t));
    parts.push(`<line class="grid" x1="${m.l}" x2="${width - m.r}" y1="${y}" y2="${y}"/>`);
    parts.push(`<text class="tick" x="${m.l - 4}" y="${y + 4}" text-anchor="end">${esc(fmt(t, 3))}</text>`);
  }
  parts.push(`<text class="label" x="${(m.l + width - m.r) / 2}" y="${height - 6}" text-anchor="middle">${esc(xlabel)}</text>`);
  parts.push(
    `<text class="label" transform="translate(14 ${(m.t + bottom) / 2}) rotate(-90)" text-anchor="middle">${esc(ylabel)}</text>`,
  );
  return parts.join("");
}

function extent(arrays, positiveOnly) {
  let lo = Infinity;
  let hi = -Infinity;
  for (const a of arrays) {
    for (const v of a) {
      if (v === null || !Number.isFinite(v) || (positiveOnly && v <= 0)) continue;
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
  }
  return [lo, hi];
}

/**
 * Line plot of series against x, each with an optional error band (lo, hi) and markers carrying the plotted
 * numbers. series: [{y, lo?, hi?, cls, label, values?, stderr?, markers?}] (values/stderr: the API's numbers
 * kept on the markers, default y). bands: [{x0, x1, cls, attrs}] vertical shaded intervals (outages).
 * Returns the SVG markup; the frame is kept on the returned object for hover.
 */
export function linePlot({ x, series, xlabel, ylabel, logY = false, bands = [], width = 640, height = 280, floorRatio = 1e-6 }) {
  const ys = series.flatMap((s) => [s.y, s.hi || [], s.lo || []]);
  let [lo, hi] = extent(ys, logY);
  if (!Number.isFinite(lo)) [lo, hi] = logY ? [1e-12, 1] : [0, 1];
  if (logY) {
    lo = Math.max(lo, hi * floorRatio);
    lo /= 2;
    hi *= 2;
  } else {
    const pad = 0.05 * (hi - lo || Math.abs(hi) || 1);
    lo = Math.min(lo, 0) === 0 && lo >= 0 ? 0 : lo - pad;
    hi += pad;
  }
  const [xmin, xmax] = extent([x], false); // a loop, not Math.min(...x): a CIR may have 10^5 bins
  const f = frame({ width, height, xlim: [xmin, xmax], ylim: [lo, hi], logY });
  const parts = [`<svg xmlns="http://www.w3.org/2000/svg" class="plot line-plot" viewBox="0 0 ${width} ${height}" width="${width}" height="${height}">`];
  parts.push(axes(f, xlabel, ylabel));
  for (const b of bands) {
    const xa = r2(f.x(Math.max(b.x0, f.xlim[0])));
    const xb = r2(f.x(Math.min(b.x1, f.xlim[1])));
    parts.push(
      `<rect class="${esc(b.cls)}" x="${xa}" y="${f.m.t}" width="${Math.max(r2(xb - xa), 1)}" height="${height - f.m.t - f.m.b}" ${b.attrs || ""}/>`,
    );
  }
  for (const s of series) {
    if (s.lo && s.hi) {
      const up = [];
      const down = [];
      for (let i = 0; i < x.length; i++) {
        if (s.lo[i] === null || s.hi[i] === null || !Number.isFinite(s.lo[i]) || !Number.isFinite(s.hi[i])) continue;
        up.push(`${r2(f.x(x[i]))},${r2(f.y(s.hi[i]))}`);
        down.push(`${r2(f.x(x[i]))},${r2(f.y(s.lo[i]))}`);
      }
      if (up.length) parts.push(`<polygon class="band ${esc(s.cls)}-band" points="${up.concat(down.reverse()).join(" ")}"/>`);
    }
  }
  for (const s of series) {
    const pts = [];
    for (let i = 0; i < x.length; i++) {
      if (s.y[i] === null || !Number.isFinite(s.y[i])) continue;
      pts.push(`${r2(f.x(x[i]))},${r2(f.y(s.y[i]))}`);
    }
    const vals = s.values || s.y;
    parts.push(
      `<polyline class="line ${esc(s.cls)}" points="${pts.join(" ")}" data-label="${esc(s.label || "")}" data-values="${vals.map(attr).join(",")}"><title>${esc(s.label || "")}</title></polyline>`,
    );
  }
  for (const s of series.filter((t) => t.markers)) {
    const vals = s.values || s.y;
    const g = [`<g class="points ${esc(s.cls)}-points">`];
    for (let i = 0; i < x.length; i++) {
      const yv = s.y[i] === null || !Number.isFinite(s.y[i]) ? f.ylim[0] : s.y[i];
      const se = s.stderr ? s.stderr[i] : null;
      g.push(
        `<circle class="pt" cx="${r2(f.x(x[i]))}" cy="${r2(f.y(yv))}" r="2" data-i="${i}" data-x="${attr(x[i])}" data-value="${attr(vals[i])}" data-stderr="${attr(se)}"/>`,
      );
    }
    g.push("</g>");
    parts.push(g.join(""));
  }
  parts.push(`<line class="cursor" x1="0" x2="0" y1="${f.m.t}" y2="${height - f.m.b}" visibility="hidden"/>`);
  parts.push("</svg>");
  return { svg: parts.join(""), frame: f };
}

/**
 * Bar chart: one bar per label with its error bar (value ± stderr). Bars carry data-value and data-stderr.
 */
export function barPlot({ labels, values, errors = [], xlabel, ylabel, logY = false, width = 420, height = 240, cls = "bar" }) {
  const tops = values.map((v, i) => (v === null ? null : v + (errors[i] || 0)));
  const bots = values.map((v, i) => (v === null ? null : v - (errors[i] || 0)));
  let [lo, hi] = extent([values, tops, logY ? [] : bots], logY);
  if (!Number.isFinite(lo)) [lo, hi] = logY ? [1e-12, 1] : [0, 1];
  if (logY) [lo, hi] = [lo / 3, hi * 2];
  else [lo, hi] = [Math.min(0, lo), hi * 1.08 || 1];
  const n = labels.length;
  const f = frame({ width, height, xlim: [-0.5, n - 0.5], ylim: [lo, hi], logY, margin: { l: 70 } });
  const parts = [`<svg xmlns="http://www.w3.org/2000/svg" class="plot bar-plot" viewBox="0 0 ${width} ${height}" width="${width}" height="${height}">`];
  const { m } = f;
  const bottom = height - m.b;
  parts.push(`<rect class="plot-area" x="${m.l}" y="${m.t}" width="${width - m.l - m.r}" height="${bottom - m.t}"/>`);
  const yt = logY ? logTicks(f.ylim[0], f.ylim[1]) : niceTicks(f.ylim[0], f.ylim[1], 5);
  for (const t of yt) {
    const y = r2(f.y(t));
    parts.push(`<line class="grid" x1="${m.l}" x2="${width - m.r}" y1="${y}" y2="${y}"/>`);
    parts.push(`<text class="tick" x="${m.l - 4}" y="${y + 4}" text-anchor="end">${esc(fmt(t, 3))}</text>`);
  }
  const bw = ((width - m.l - m.r) / n) * 0.7;
  const base = logY ? bottom : f.y(0);
  for (let i = 0; i < n; i++) {
    const cx = f.x(i);
    const v = values[i];
    const se = errors[i];
    parts.push(`<text class="tick" x="${r2(cx)}" y="${bottom + 14}" text-anchor="middle">${esc(labels[i])}</text>`);
    if (v === null || !Number.isFinite(v)) {
      parts.push(`<rect class="${cls} null" x="${r2(cx - bw / 2)}" y="${r2(base)}" width="${r2(bw)}" height="0" data-label="${esc(labels[i])}" data-value="" data-stderr=""/>`);
      continue;
    }
    const yv = f.y(v);
    const top = Math.min(yv, base);
    const title = `${labels[i]}: ${withError(v, se)}`;
    parts.push(
      `<rect class="${cls}" x="${r2(cx - bw / 2)}" y="${r2(top)}" width="${r2(bw)}" height="${r2(Math.abs(base - yv))}" data-label="${esc(labels[i])}" data-value="${attr(v)}" data-stderr="${attr(se)}"><title>${esc(title)}</title></rect>`,
    );
    if (se !== null && se !== undefined && Number.isFinite(se) && se > 0) {
      const ya = r2(f.y(v + se));
      const yb = r2(f.y(logY ? Math.max(v - se, f.ylim[0]) : v - se));
      parts.push(
        `<path class="err" d="M${r2(cx)},${ya}V${yb}M${r2(cx - bw / 5)},${ya}H${r2(cx + bw / 5)}M${r2(cx - bw / 5)},${yb}H${r2(cx + bw / 5)}"/>`,
      );
    }
  }
  parts.push(`<text class="label" x="${(m.l + width - m.r) / 2}" y="${height - 6}" text-anchor="middle">${esc(xlabel)}</text>`);
  parts.push(`<text class="label" transform="translate(14 ${(m.t + bottom) / 2}) rotate(-90)" text-anchor="middle">${esc(ylabel)}</text>`);
  parts.push("</svg>");
  return parts.join("");
}

// Colour ramp: five anchor colours (dark blue - teal - green - yellow), interpolated in RGB.
const RAMP = [
  [68, 1, 84],
  [59, 82, 139],
  [33, 145, 140],
  [94, 201, 98],
  [253, 231, 37],
];

/** The ramp's colour at t in [0, 1] as #rrggbb. */
export function colour(t) {
  const u = Math.min(Math.max(Number.isFinite(t) ? t : 0, 0), 1) * (RAMP.length - 1);
  const k = Math.min(Math.floor(u), RAMP.length - 2);
  const w = u - k;
  const c = RAMP[k].map((a, i) => Math.round(a + w * (RAMP[k + 1][i] - a)));
  return `#${c.map((v) => v.toString(16).padStart(2, "0")).join("")}`;
}

/**
 * Heatmap of a grid of values[i][j] (i across, j up) at cell centres a[i] (across) and b[j] (up) [m], cells of
 * size da x db; null cells grey. One <rect> per cell with data-i, data-j, data-value (and data-stderr); hover is
 * handled by one listener on the SVG (heatmapHover). Returns {svg, frame, lo, hi}.
 */
export function heatmap({ values, stderr, a, b, da, db, xlabel, ylabel, unit, logColour = false, width = 560 }) {
  const nu = values.length;
  const nv = nu ? values[0].length : 0;
  const [lo, hi] = extent(values, logColour);
  const amin = Math.min(...a) - da / 2;
  const amax = Math.max(...a) + da / 2;
  const bmin = Math.min(...b) - db / 2;
  const bmax = Math.max(...b) + db / 2;
  const m = { l: 56, r: 92, t: 10, b: 42 };
  const pw = width - m.l - m.r;
  const ph = Math.max(60, Math.min(520, (pw * (bmax - bmin)) / (amax - amin)));
  const height = ph + m.t + m.b;
  const f = frame({ width, height, xlim: [amin, amax], ylim: [bmin, bmax], margin: m });
  const scale = (v) => {
    if (v === null || !Number.isFinite(v)) return null;
    if (logColour) return v > 0 ? (Math.log10(v) - Math.log10(lo)) / (Math.log10(hi) - Math.log10(lo) || 1) : 0;
    return (v - lo) / (hi - lo || 1);
  };
  const cw = (pw * da) / (amax - amin);
  const chh = (ph * db) / (bmax - bmin);
  const parts = [
    `<svg xmlns="http://www.w3.org/2000/svg" class="plot heatmap" viewBox="0 0 ${width} ${r2(height)}" width="${width}" height="${r2(height)}">`,
  ];
  parts.push(axes(f, xlabel, ylabel));
  parts.push('<g class="cells">');
  for (let i = 0; i < nu; i++) {
    const x = r2(f.x(a[i] - da / 2));
    for (let j = 0; j < nv; j++) {
      const v = values[i][j];
      const t = scale(v);
      const fill = t === null ? "#c8c8c8" : colour(t);
      const se = stderr ? stderr[i][j] : null;
      parts.push(
        `<rect class="cell${t === null ? " masked" : ""}" x="${x}" y="${r2(f.y(b[j] + db / 2))}" width="${r2(cw) + 0.4}" height="${r2(chh) + 0.4}" fill="${fill}" data-i="${i}" data-j="${j}" data-value="${attr(v)}" data-stderr="${attr(se)}"/>`,
      );
    }
  }
  parts.push("</g>");
  // colour bar
  const bx = width - m.r + 14;
  const stops = [0, 0.25, 0.5, 0.75, 1].map((t) => `<stop offset="${t}" stop-color="${colour(t)}"/>`).join("");
  parts.push(`<defs><linearGradient id="cbar" x1="0" y1="1" x2="0" y2="0">${stops}</linearGradient></defs>`);
  parts.push(`<rect class="colourbar" x="${bx}" y="${m.t}" width="14" height="${r2(ph)}" fill="url(#cbar)"/>`);
  if (Number.isFinite(lo)) {
    parts.push(`<text class="tick cbar-max" x="${bx + 18}" y="${m.t + 10}" data-value="${attr(hi)}">${esc(fmt(hi, 3))}</text>`);
    parts.push(`<text class="tick cbar-min" x="${bx + 18}" y="${r2(m.t + ph)}" data-value="${attr(lo)}">${esc(fmt(lo, 3))}</text>`);
  }
  parts.push(`<text class="tick" x="${bx}" y="${r2(m.t + ph + 28)}">${esc(unit || "")}</text>`);
  parts.push(`<rect class="hover-cell" x="0" y="0" width="${r2(cw)}" height="${r2(chh)}" visibility="hidden"/>`);
  parts.push("</svg>");
  return { svg: parts.join(""), frame: f, lo, hi, cell: [cw, chh] };
}

/**
 * Hover on a heatmap: one mousemove listener computes the cell under the pointer from its position (no listener
 * per cell) and calls show(i, j) (or show(null) outside the cells).
 */
export function heatmapHover(svgEl, f, a, b, da, db, show) {
  const nu = a.length;
  const nv = b.length;
  const hc = svgEl.querySelector(".hover-cell");
  const du = nu > 1 ? a[1] - a[0] : da;
  const dv = nv > 1 ? b[1] - b[0] : db;
  svgEl.addEventListener("mousemove", (ev) => {
    const r = svgEl.getBoundingClientRect();
    const px = ((ev.clientX - r.left) * f.width) / r.width;
    const py = ((ev.clientY - r.top) * f.height) / r.height;
    const av = f.xinv(px);
    const { m } = f;
    const ph = f.height - m.t - m.b;
    const bv = f.ylim[0] + ((f.height - m.b - py) / ph) * (f.ylim[1] - f.ylim[0]);
    const i = Math.round((av - a[0]) / du);
    const j = Math.round((bv - b[0]) / dv);
    if (i < 0 || j < 0 || i >= nu || j >= nv || Math.abs(av - a[i]) > da / 2 + 1e-12 || Math.abs(bv - b[j]) > db / 2 + 1e-12) {
      hc.setAttribute("visibility", "hidden");
      show(null);
      return;
    }
    hc.setAttribute("x", r2(f.x(a[i] - da / 2)));
    hc.setAttribute("y", r2(f.y(b[j] + db / 2)));
    hc.setAttribute("visibility", "visible");
    show(i, j);
  });
  svgEl.addEventListener("mouseleave", () => {
    hc.setAttribute("visibility", "hidden");
    show(null);
  });
}

/** Hover on a line plot: the index nearest the pointer along x, shown through show(i) (null when outside). */
export function lineHover(svgEl, f, x, show) {
  const cursor = svgEl.querySelector(".cursor");
  svgEl.addEventListener("mousemove", (ev) => {
    const r = svgEl.getBoundingClientRect();
    const px = ((ev.clientX - r.left) * f.width) / r.width;
    const xv = f.xinv(px);
    let best = -1;
    let dist = Infinity;
    // x is sorted: binary search for the nearest sample
    let lo = 0;
    let hi = x.length - 1;
    while (hi - lo > 1) {
      const mid = (lo + hi) >> 1;
      if (x[mid] < xv) lo = mid;
      else hi = mid;
    }
    for (const k of [lo, hi]) {
      if (Math.abs(x[k] - xv) < dist) [best, dist] = [k, Math.abs(x[k] - xv)];
    }
    if (best < 0 || px < f.m.l || px > f.width - f.m.r) {
      cursor.setAttribute("visibility", "hidden");
      show(null);
      return;
    }
    const cx = r2(f.x(x[best]));
    cursor.setAttribute("x1", cx);
    cursor.setAttribute("x2", cx);
    cursor.setAttribute("visibility", "visible");
    show(best);
  });
  svgEl.addEventListener("mouseleave", () => {
    cursor.setAttribute("visibility", "hidden");
    show(null);
  });
}
