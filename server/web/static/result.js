// The result page (/ui/jobs/{id}): the job's state, then its result drawn from the JSON API: the metrics table,
// the CIR with its error band, the per-order bars, the maps with values on hover and U0, the timeline, the
// downloads, and the scene preview. Everything comes from /v1/... with the API key of api.js. When the page is
// drawn, <body data-state="plotted"> is set and data-plotted-ms holds the time since navigation [ms].

import { apiFetch, formatError, setKey } from "./api.js";
import { attr, barPlot, esc, fmt, heatmap, heatmapHover, linePlot, lineHover, withError } from "./plots.js";
import { drawPreview } from "./preview.js";

const $ = (sel, root = document) => root.querySelector(sel);

/** GET a JSON document with the API key (api.js's apiFetch: the Response when 2xx; otherwise it throws an Error
 * with `status` and the problem document's text, or, from an older api.js, returns the failed Response). */
async function apiJson(path) {
  const r = await apiFetch(path);
  if (r.ok) return r.json();
  const body = await r.json().catch(() => null);
  const err = new Error((body && formatError(body)) || `HTTP ${r.status}`);
  err.status = r.status;
  throw err;
}

/** Readable names of the map quantities (shown with the map's own unit; the values are the API's). */
const QUANTITIES = {
  dc_gain: "DC gain H0",
  path_loss_db: "path loss",
  received_power_w: "received power",
  received_power_dbm: "received power",
  mean_delay_s: "mean delay",
  rms_delay_spread_s: "RMS delay spread",
  illuminance_lx: "illuminance E",
  illuminance_direct_lx: "direct illuminance",
  cylindrical_illuminance_direct_lx: "direct cylindrical illuminance",
  snr_db: "SNR",
  ber: "bit-error rate",
  max_bit_rate_bps: "bit rate 1/(10 tau_rms)",
  bandwidth_3db_hz: "3 dB bandwidth",
  dc_gain_rel_error: "relative error of H0",
  paths: "paths",
};

/** Columns of the metrics tables: [field, heading, stderr field, display scale]; optional ones only when present. */
const METRICS = [
  ["dc_gain", "H0", "dc_gain_stderr", 1, true],
  ["path_loss_db", "path loss [dB]", null, 1, true],
  ["rms_delay_spread_s", "τ_rms [ns]", "rms_delay_spread_s_stderr", 1e9, true],
  ["bandwidth_3db_hz", "B_3dB [MHz]", "bandwidth_3db_hz_stderr", 1e-6, true],
  ["received_power_w", "P_r [W]", null, 1, false],
  ["illuminance_lx", "E [lx]", "illuminance_lx_stderr", 1, false],
  ["snr_db", "SNR [dB]", null, 1, false],
  ["ber", "BER", null, 1, false],
];
const MAX_ROWS = 200;

function scaled(v, k) {
  return v === null || v === undefined ? null : v * k;
}

/** A metrics table over rows (links or channels): every cell carries the API's value and error. */
export function metricsTable(rows, label, id) {
  const cols = METRICS.filter(([f, , , , always]) => always || rows.some((r) => r[f] !== null && r[f] !== undefined));
  const head = `<tr><th>${esc(label)}</th>${cols.map((c) => `<th>${esc(c[1])}</th>`).join("")}</tr>`;
  const body = rows.slice(0, MAX_ROWS).map((r) => {
    const cells = cols.map(([f, , se, k]) => {
      const v = r[f];
      const e = se ? r[se] : null;
      return `<td class="num" data-field="${f}" data-value="${attr(v)}" data-stderr="${attr(e)}">${esc(withError(scaled(v, k), scaled(e, k)))}</td>`;
    });
    return `<tr data-index="${r._index}"><th scope="row">${esc(r._name)}</th>${cells.join("")}</tr>`;
  });
  const more = rows.length > MAX_ROWS ? `<p class="note">${rows.length - MAX_ROWS} more rows: see the downloads.</p>` : "";
  return `<table class="metrics" id="${id}"><thead>${head}</thead><tbody>${body.join("")}</tbody></table>${more}`;
}

function gridReceivers(result) {
  return new Set((result.receivers || []).filter((r) => r.grid).map((r) => r.id));
}

function renderMetrics(el, result) {
  const grid = gridReceivers(result);
  // rows of explicit receivers only (a map's thousands of grid links are drawn as maps)
  const links = [];
  result.links.forEach((l, k) => {
    if (!grid.has(l.receiver)) links.push({ ...l, _index: k, _name: `${l.transmitter} → ${l.receiver}` });
  });
  const channels = [];
  (result.channels || []).forEach((c, k) => {
    if (!grid.has(c.receiver)) channels.push({ ...c, _index: k, _name: `${c.group} → ${c.receiver}` });
  });
  const parts = [];
  if (links.length) parts.push(metricsTable(links, "link", "links-table"));
  if (channels.length) parts.push(`<h3>Transmitter groups</h3>${metricsTable(channels, "channel", "channels-table")}`);
  const nGrid = result.links.length - links.length;
  if (nGrid) parts.push(`<p class="note">${nGrid} links to receiver-grid points are shown as maps below.</p>`);
  const run = result.run;
  parts.push(
    `<p class="run">algorithm ${result.algorithm} (${esc(result.families)}); stopped: ${esc(run.stop_reason)}; ${run.paths_total.toLocaleString("en")} paths in ${fmt(run.wall_time_s, 3)} s on ${run.workers} worker(s)${run.max_dc_gain_rel_stderr !== null ? `; worst relative error of H0 ${fmt(run.max_dc_gain_rel_stderr, 2)}` : ""}</p>`,
  );
  if (result.warnings && result.warnings.length) parts.push(`<ul class="warnings">${result.warnings.map((w) => `<li>${esc(w)}</li>`).join("")}</ul>`);
  el.innerHTML = parts.join("");
  el.hidden = false;
}

/** Rows of the link selector: links and channels with a CIR or an order split (the first MAX_SOURCES). */
const MAX_SOURCES = 1000;
function curveSources(result) {
  const out = [];
  result.links.forEach((l, k) => {
    if (l.cir || l.dc_gain_by_reflection_order) out.push({ key: `link:${k}`, name: `${l.transmitter} → ${l.receiver}`, row: l });
  });
  (result.channels || []).forEach((c, k) => {
    if (c.cir) out.push({ key: `channel:${k}`, name: `group ${c.group} → ${c.receiver}`, row: c });
  });
  return out.slice(0, MAX_SOURCES);
}

function renderCurves(el, result) {
  const sources = curveSources(result);
  if (!sources.length) {
    el.hidden = true;
    return;
  }
  el.hidden = false;
  const sel = $("#curve-source", el);
  sel.innerHTML = sources.map((s) => `<option value="${esc(s.key)}">${esc(s.name)}</option>`).join("");
  const draw = () => {
    const src = sources.find((s) => s.key === sel.value) || sources[0];
    drawCir($("#cir-plot", el), result, src.row, $("#cir-log", el).checked);
    drawOrders($("#orders-plot", el), src.row, $("#orders-log", el).checked);
  };
  sel.onchange = draw;
  $("#cir-log", el).onchange = draw;
  $("#orders-log", el).onchange = draw;
  draw();
}

const MAX_MARKERS = 5000;

/** The CIR h(t) = power per bin / dt [1/s] against the delay [ns], with its ±1 standard error band. */
export function drawCir(el, result, row, logY) {
  const cir = row.cir;
  if (!cir) {
    el.innerHTML = '<p class="note">This link has no binned CIR (ask for it with outputs.cir).</p>';
    return;
  }
  const tb = result.time_bins;
  const dt = tb.time_bin_s;
  const t = cir.total.map((_, k) => 1e9 * (tb.t_min_s + dt * (k + 0.5)));
  const h = cir.total.map((v) => v / dt);
  const se = cir.total_stderr;
  const lo = cir.total.map((v, k) => (se[k] === null ? null : (v - se[k]) / dt));
  const hi = cir.total.map((v, k) => (se[k] === null ? null : (v + se[k]) / dt));
  const series = [];
  (cir.by_reflection_order || []).forEach((o, k) => {
    if (o.some((v) => v > 0)) series.push({ y: o.map((v) => v / dt), values: o, cls: `order order-${k % 8}`, label: `k = ${k}` });
  });
  // one marker per bin (its value in data-value) up to MAX_MARKERS bins; the line's data-values always hold them
  series.push({ y: h, lo, hi, values: cir.total, stderr: se, cls: "total", label: "total", markers: h.length <= MAX_MARKERS });
  const { svg, frame } = linePlot({ x: t, series, xlabel: "delay t [ns]", ylabel: "h(t) [1/s]", logY });
  const legend = series.map((s) => `<span class="key ${esc(s.cls)}">${esc(s.label)}</span>`).join(" ");
  const h0 = withError(row.dc_gain, row.dc_gain_stderr);
  el.innerHTML = `${svg}<p class="legend">${legend}; band: ±1 standard error of each bin. H0 = ${esc(h0)}${row.late_gain ? `; after the window: ${esc(fmt(row.late_gain, 3))}` : ""}</p><div class="readout" aria-live="polite"></div>`;
  const out = $(".readout", el);
  lineHover($("svg", el), frame, t, (k) => {
    if (k === null) {
      out.textContent = "";
      return;
    }
    out.dataset.value = attr(cir.total[k]);
    out.textContent = `t = ${fmt(t[k], 4)} ns: power in the bin ${withError(cir.total[k], se[k])} per W, h = ${fmt(h[k], 4)} 1/s`;
  });
}

/** Per reflection order and per scattering order: H0's parts with their error bars. */
export function drawOrders(el, row, logY) {
  const plots = [];
  if (row.dc_gain_by_reflection_order) {
    const v = row.dc_gain_by_reflection_order;
    plots.push(
      `<figure class="orders reflection"><figcaption>H0 per reflection order k</figcaption>${barPlot({
        labels: v.map((_, k) => String(k)),
        values: v,
        errors: row.dc_gain_by_reflection_order_stderr || [],
        xlabel: "reflection order k",
        ylabel: "H0 part",
        logY,
        cls: "bar reflection-bar",
      })}</figure>`,
    );
  }
  if (row.dc_gain_by_scattering_order && row.dc_gain_by_scattering_order.length > 1) {
    const v = row.dc_gain_by_scattering_order;
    plots.push(
      `<figure class="orders scattering"><figcaption>H0 per scattering order s</figcaption>${barPlot({
        labels: v.map((_, k) => String(k)),
        values: v,
        errors: row.dc_gain_by_scattering_order_stderr || [],
        xlabel: "scattering order s",
        ylabel: "H0 part",
        logY,
        cls: "bar scattering-bar",
      })}</figure>`,
    );
  }
  el.innerHTML = plots.length ? plots.join("") : '<p class="note">No order split for this link (ask for it with outputs.orders).</p>';
}

/** A map's axes: coordinates of its points across (u) and up (v) [m], named after the room axis they follow. */
export function mapAxes(map) {
  const [su, sv] = map.spacing_uv || [map.spacing, map.spacing];
  const [nu, nv] = map.shape;
  const axis = (dir, step, n) => {
    const k = dir.findIndex((c) => Math.abs(c) > 0.999999);
    const name = k >= 0 ? "xyz"[k] : null;
    const start = name ? map.origin[k] : 0;
    const sgn = name ? Math.sign(dir[k]) : 1;
    const coords = Array.from({ length: n }, (_, i) => start + sgn * i * step);
    return { coords, cell: step > 0 ? step : 1, label: name ? `${name} [m]` : "offset along the grid [m]" };
  };
  return [axis(map.u, su, nu), axis(map.v, sv, nv)];
}

function mapStats(values) {
  let n = 0;
  let sum = 0;
  let min = Infinity;
  let max = -Infinity;
  for (const row of values) {
    for (const v of row) {
      if (v === null || !Number.isFinite(v)) continue;
      n++;
      sum += v;
      if (v < min) min = v;
      if (v > max) max = v;
    }
  }
  return n ? { n, avg: sum / n, min, max } : null;
}

function renderMaps(el, result) {
  const maps = result.maps || [];
  if (!maps.length) {
    el.hidden = true;
    return;
  }
  el.hidden = false;
  const mapSel = $("#map-select", el);
  const qSel = $("#quantity-select", el);
  mapSel.innerHTML = maps.map((m, k) => `<option value="${k}">${esc(m.grid)} · ${esc(m.channel)}</option>`).join("");
  const fillQuantities = () => {
    const m = maps[Number(mapSel.value)];
    const keep = qSel.value;
    const names = Object.keys(m.values);
    const first = names.includes("illuminance_lx") ? "illuminance_lx" : names.includes(keep) ? keep : "dc_gain";
    qSel.innerHTML = names.map((q) => `<option value="${esc(q)}">${esc(QUANTITIES[q] || q)}${m.units[q] && m.units[q] !== "1" ? ` [${esc(m.units[q])}]` : ""}</option>`).join("");
    qSel.value = names.includes(keep) ? keep : first;
  };
  const draw = () => drawMap($("#map-plot", el), result, maps[Number(mapSel.value)], qSel.value, $("#map-log", el).checked);
  mapSel.onchange = () => {
    fillQuantities();
    draw();
  };
  qSel.onchange = draw;
  $("#map-log", el).onchange = draw;
  fillQuantities();
  draw();
}

/** One map quantity as a heatmap, with the value under the pointer, its min/avg/max and the lighting's U0. */
export function drawMap(el, result, map, q, logColour) {
  const values = map.values[q];
  const stderr = map.stderr ? map.stderr[q] : null;
  const unit = map.units[q] && map.units[q] !== "1" ? map.units[q] : "";
  const [au, av] = mapAxes(map);
  const hm = heatmap({ values, stderr, a: au.coords, b: av.coords, da: au.cell, db: av.cell, xlabel: au.label, ylabel: av.label, unit, logColour });
  const st = mapStats(values);
  const stats = st
    ? `<table class="map-stats"><tr><th>points</th><th>min</th><th>average</th><th>max</th><th>min / average</th></tr><tr><td>${st.n}</td><td class="num" data-stat="min" data-value="${attr(st.min)}">${fmt(st.min)}</td><td class="num" data-stat="avg" data-value="${attr(st.avg)}">${fmt(st.avg)}</td><td class="num" data-stat="max" data-value="${attr(st.max)}">${fmt(st.max)}</td><td class="num" data-stat="ratio" data-value="${attr(st.min / st.avg)}">${fmt(st.min / st.avg, 3)}</td></tr></table>`
    : "";
  const areas = ((result.lighting && result.lighting.areas) || []).filter((a) => a.grid === map.grid && a.channel === map.channel);
  const u0 = areas.length
    ? `<table class="u0" id="u0-table"><caption>EN 12464-1 figures (the result's lighting section)</caption><tr><th>area</th><th>part</th><th>E_avg [lx]</th><th>E_min [lx]</th><th>U0 = E_min / E_avg</th></tr>${areas
        .flatMap((a) =>
          ["task", "surround", "background"]
            .filter((p) => a[p])
            .map(
              (p) =>
                `<tr data-area="${esc(a.name)}" data-part="${p}"><th scope="row">${esc(a.name)}</th><td>${p}</td><td class="num" data-value="${attr(a[p].illuminance_avg_lx)}">${esc(withError(a[p].illuminance_avg_lx, a[p].illuminance_avg_lx_stderr))}</td><td class="num" data-value="${attr(a[p].illuminance_min_lx)}">${esc(withError(a[p].illuminance_min_lx, a[p].illuminance_min_lx_stderr))}</td><td class="num u0-value" data-value="${attr(a[p].uniformity_u0)}" data-stderr="${attr(a[p].uniformity_u0_stderr)}">${esc(withError(a[p].uniformity_u0, a[p].uniformity_u0_stderr, 3))}</td></tr>`,
            ),
        )
        .join("")}</table>`
    : "";
  el.innerHTML = `${hm.svg}<div class="readout map-readout" aria-live="polite">hover over the map for a point's value</div>${stats}${u0}`;
  const out = $(".map-readout", el);
  const name = QUANTITIES[q] || q;
  heatmapHover($("svg", el), hm.frame, au.coords, av.coords, au.cell, av.cell, (i, j) => {
    if (i === null) {
      delete out.dataset.i;
      out.textContent = "";
      return;
    }
    const v = values[i][j];
    const e = stderr ? stderr[i][j] : null;
    out.dataset.i = String(i);
    out.dataset.j = String(j);
    out.dataset.value = attr(v);
    out.dataset.stderr = attr(e);
    const where = `${au.label.split(" ")[0]} = ${fmt(au.coords[i], 4)} m, ${av.label.split(" ")[0]} = ${fmt(av.coords[j], 4)} m`;
    out.textContent = v === null ? `[${i}, ${j}] (${where}): masked` : `[${i}, ${j}] (${where}): ${name} = ${withError(v, e)}${unit ? " " + unit : ""}`;
  });
}

/** The timeline (a result with `timeline`): H0 against time with its band and the outage intervals. */
export function renderTimeline(el, timeline) {
  if (!timeline || !timeline.links || !timeline.links.length) {
    el.hidden = true;
    return;
  }
  el.hidden = false;
  const sel = $("#timeline-link", el);
  const name = (l, k) =>
    `${l.kind === "channel" ? "group " : ""}${l.tx || l.transmitter || "tx"} → ${l.rx || l.receiver || "rx"}` + (l.tx || l.transmitter ? "" : ` (${k})`);
  sel.innerHTML = timeline.links.map((l, k) => `<option value="${k}">${esc(name(l, k))}</option>`).join("");
  const draw = () => drawTimeline($("#timeline-plot", el), timeline, timeline.links[Number(sel.value)], $("#timeline-log", el).checked);
  sel.onchange = draw;
  $("#timeline-log", el).onchange = draw;
  draw();
}

export function drawTimeline(el, timeline, link, logY) {
  const t = timeline.times_s;
  const g = link.dc_gain;
  const se = link.dc_gain_stderr || [];
  const lo = g.map((v, k) => (v === null || se[k] === null || se[k] === undefined ? null : v - se[k]));
  const hi = g.map((v, k) => (v === null || se[k] === null || se[k] === undefined ? null : v + se[k]));
  const outages = link.outages || [];
  const bands = outages.map((o) => ({
    x0: o.start_s,
    x1: o.end_s === null || o.end_s === undefined ? t[t.length - 1] : o.end_s,
    cls: o.uncertain ? "outage uncertain" : "outage",
    attrs: `data-start="${attr(o.start_s)}" data-end="${attr(o.end_s)}" data-uncertain="${o.uncertain ? "true" : "false"}"`,
  }));
  const { svg, frame } = linePlot({
    x: t,
    series: [{ y: g, lo, hi, stderr: se, cls: "total timeline-h0", label: "H0", markers: true }],
    bands,
    xlabel: "time t [s]",
    ylabel: "H0",
    logY,
  });
  const first = link.time_to_first_outage_s;
  const note = outages.length
    ? `${outages.length} outage interval(s) shaded in red (orange: uncertain, the error bar straddles the threshold)${first !== null && first !== undefined ? `; first outage at ${fmt(first, 4)} s` : ""}`
    : "no outage";
  el.innerHTML = `${svg}<p class="legend">band: ±1 standard error; ${esc(note)}</p><div class="readout" aria-live="polite"></div>`;
  const out = $(".readout", el);
  lineHover($("svg", el), frame, t, (k) => {
    out.textContent = k === null ? "" : `t = ${fmt(t[k], 4)} s: H0 = ${withError(g[k], se[k])}`;
  });
}

/** Labels of the job's result links (JobPublic.urls); a key the page does not know is shown as it is. */
const DOWNLOADS = {
  result: ["result document", "JSON"],
  result_csv: ["binned CIR of every link", "CSV"],
  result_npz: ["numpy arrays", ".npz"],
  plot: ["h(t) plot", "PNG"],
  "timeline.csv": ["timeline, one row per link and time", "CSV"],
  "timeline.nc": ["timeline", "netCDF"],
  "timeline.svg": ["timeline plot", "SVG"],
};
/** Job links that are not downloads. */
const NOT_DOWNLOADS = new Set(["self", "cancel", "delete", "events", "scene"]);

/** Download links of every format the API offers for the job (its `urls`), and the scene document. */
export function renderDownloads(el, job, extra = {}) {
  const items = Object.entries(job.urls || {})
    .filter(([k, u]) => !NOT_DOWNLOADS.has(k) && typeof u === "string")
    .map(([k, u]) => [k, u, ...(DOWNLOADS[k] || [k.replaceAll("_", " "), u.split("/").pop()])]);
  items.push(["scene", `${job.url}/scene`, "scene document", "JSON"]);
  for (const [name, u] of Object.entries(extra)) items.push([name, u, ...(DOWNLOADS[name] || [name, name.split(".").pop()])]);
  el.innerHTML = `<ul class="downloads">${items
    .map(([k, u, what, fmtName]) => `<li><a class="download" href="${esc(u)}" data-key="${esc(k)}" data-href="${esc(u)}">${esc(what)} (${esc(fmtName)})</a></li>`)
    .join("")}</ul><p class="note">Downloads send your API key; the files are also at the URLs shown.</p>`;
  el.hidden = false;
  for (const a of el.querySelectorAll("a.download")) {
    a.addEventListener("click", async (ev) => {
      ev.preventDefault();
      let r;
      try {
        r = await apiFetch(a.dataset.href);
        if (!r.ok) throw new Error(formatError(await r.json().catch(() => null)) || `HTTP ${r.status}`);
      } catch (err) {
        showMessage(`download failed: ${err.message || err}`);
        return;
      }
      const blob = await r.blob();
      const cd = r.headers.get("Content-Disposition") || "";
      const m = /filename="([^"]+)"/.exec(cd);
      const ext = { result: "result.json", scene: "scene.json", plot: "plot.png" }[a.dataset.key] || a.dataset.href.split("/").pop();
      const link = document.createElement("a");
      link.href = URL.createObjectURL(blob);
      link.download = m ? m[1] : `${job.id}-${ext}`;
      document.body.appendChild(link);
      link.click();
      link.remove();
      setTimeout(() => URL.revokeObjectURL(link.href), 10000);
    });
  }
}

/** The files of a result's timeline (GET {job}/timeline lists them: {files: {name: url}}); none when the server
 * has no such route or the job no timeline. */
export async function timelineFiles(job) {
  try {
    return (await apiJson(`${job.url}/timeline`)).files || {};
  } catch {
    return {};
  }
}

/** Draw a whole result document (and its job's links) into the page; resolves once the downloads are listed. */
export async function renderResult(result, job) {
  renderMetrics($("#metrics"), result);
  performance.mark("owcsim:metrics");
  renderCurves($("#curves"), result);
  performance.mark("owcsim:curves");
  renderMaps($("#maps"), result);
  performance.mark("owcsim:maps");
  renderTimeline($("#timeline"), result.timeline);
  if (!job) return;
  renderDownloads($("#downloads"), job);
  if (result.timeline) renderDownloads($("#downloads"), job, await timelineFiles(job));
}

function showMessage(text, cls = "error") {
  const el = $("#message");
  el.className = cls;
  el.textContent = text;
  el.hidden = !text;
}

/** The pages' shared frame (shell.js: navigation and the key box) when the server has it; else null. */
let shell = null;

function askKey(text) {
  if (shell) return; // the shell's key box asks (api.js fires "owcsim:unauthorized")
  const el = $("#result-key-form");
  el.hidden = false;
  $("#result-key-reason", el).textContent = text;
  el.onsubmit = (ev) => {
    ev.preventDefault();
    setKey($("#result-key-input", el).value.trim());
    location.reload();
  };
}

function plotted() {
  document.body.dataset.plottedMs = String(Math.round(performance.now()));
  document.body.dataset.state = "plotted";
}

function describeJob(job) {
  const took = job.started_at && job.finished_at ? ` in ${fmt((Date.parse(job.finished_at) - Date.parse(job.started_at)) / 1000, 3)} s` : "";
  const p = job.progress || {};
  const running = job.status === "running" ? ` (${Math.round(100 * (p.fraction || 0))} %, ${(p.paths || 0).toLocaleString("en")} paths)` : "";
  return `${job.status}${running}${took}`;
}

async function loadJob(id) {
  const job = await apiJson(`/v1/jobs/${encodeURIComponent(id)}`);
  $("#job-title").textContent = job.name || `job ${job.id}`;
  $("#job-status").textContent = describeJob(job);
  $("#job-status").dataset.status = job.status;
  return job;
}

/** Poll a queued or running job every second until it stops; the stopped job, or null when it is gone (deleted:
 * 404) or the key no longer reaches it (401). A failed poll (the server restarting, the network) is said on the
 * page and tried again, so the page does not stop following the job. */
async function followJob(id, job) {
  let failed = false;
  while (job.status === "queued" || job.status === "running") {
    await new Promise((r) => setTimeout(r, 1000));
    try {
      job = await loadJob(id);
    } catch (err) {
      if (err.status === 404 || err.status === 401) {
        if (err.status === 401) askKey(err.message);
        showMessage(err.message || String(err));
        return null;
      }
      failed = true;
      showMessage(`cannot reach the job (${err.message || err}); trying again every second`, "info");
      continue;
    }
    if (failed) showMessage("");
    failed = false;
  }
  return job;
}

async function main() {
  const m = /^\/ui\/jobs\/([^/]+)\/?$/.exec(location.pathname);
  if (!m) return;
  shell = await import("./shell.js").catch(() => null);
  if (shell) {
    shell.initShell("result");
    document.addEventListener("owcsim:key", (ev) => {
      if (ev.detail && ev.detail.set) location.reload(); // a key was typed: draw the page with it
    });
  }
  const id = decodeURIComponent(m[1]);
  const base = `/v1/jobs/${encodeURIComponent(id)}`;
  // the scene and the result are asked for at once, beside the job (a job without a result answers 409)
  const sceneP = apiJson(`${base}/scene`);
  const resultP = apiJson(`${base}/result`);
  sceneP.catch(() => null);
  resultP.catch(() => null);
  let job;
  try {
    job = await loadJob(id);
  } catch (err) {
    if (err.status === 401) askKey(err.message);
    showMessage(err.message || String(err));
    document.body.dataset.state = "error";
    return;
  }
  const preview = sceneP
    .then((scene) => {
      drawPreview($("#preview-body"), scene);
      $("#preview").hidden = false;
    })
    .catch((err) => showMessage(`scene preview: ${err.message}`));
  job = await followJob(id, job);
  if (!job) {
    document.body.dataset.state = "error";
    return;
  }
  if (job.status === "failed") {
    showMessage(`the job failed: ${job.error || "no reason given"}`);
  } else {
    try {
      // asked for before the job ended (409): ask again
      const result = await resultP.catch((err) => (err.status === 409 ? apiJson(job.urls.result) : Promise.reject(err)));
      performance.mark("owcsim:result-parsed");
      const listed = renderResult(result, job);
      performance.mark("owcsim:result-drawn");
      await listed;
    } catch (err) {
      showMessage(err.message || String(err), err.status === 409 ? "info" : "error");
    }
  }
  await preview;
  plotted();
}

main();
