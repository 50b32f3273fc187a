// The jobs list: GET /v1/jobs every second (the API has no event stream), rows updated in place; cancel
// (POST .../cancel) and delete (DELETE /v1/jobs/{id}, asked twice); a filter by state.

import { apiFetch, apiJson, formatDuration, formatError, poll } from "./api.js";
import { initShell } from "./shell.js";

const LIMIT = 200; // newest jobs shown
const FINISHED = new Set(["succeeded", "failed", "cancelled"]);
const rows = new Map(); // job id -> <tr>
let generation = 0; // answers of an older filter are dropped

const $ = (id) => document.getElementById(id);

function timeTaken(job) {
  const start = job.started_at ? Date.parse(job.started_at) : null;
  if (start === null) return job.status === "queued" ? "waiting" : "";
  if (job.finished_at) return formatDuration((Date.parse(job.finished_at) - start) / 1000);
  return formatDuration(job.progress.elapsed_s || (Date.now() - start) / 1000);
}

function cell(cls) {
  const td = document.createElement("td");
  td.className = cls;
  return td;
}

function newRow(job) {
  const tr = document.createElement("tr");
  tr.dataset.jobId = job.id;
  const name = cell("name");
  const link = document.createElement("a");
  link.href = `/ui/jobs/${encodeURIComponent(job.id)}`;
  const id = document.createElement("code");
  id.textContent = job.id.slice(0, 8);
  name.append(link, " ", id);
  const status = cell("status");
  status.append(document.createElement("span"));
  const progress = cell("progress");
  const bar = document.createElement("progress");
  bar.max = 1;
  const pct = document.createElement("span");
  pct.className = "pct";
  progress.append(bar, pct);
  const actions = cell("actions");
  const cancel = button("Cancel", "cancel", () => cancelJob(job.id, cancel));
  const del = button("Delete", "delete", () => deleteJob(job.id, del));
  actions.append(cancel, del);
  tr.append(name, status, progress, cell("time"), cell("created"), actions);
  return tr;
}

function button(text, cls, onClick) {
  const b = document.createElement("button");
  b.type = "button";
  b.className = cls;
  b.textContent = text;
  b.addEventListener("click", onClick);
  return b;
}

function update(tr, job) {
  tr.dataset.status = job.status;
  tr.querySelector(".name a").textContent = job.name || "(no name)";
  const badge = tr.querySelector(".status span");
  badge.className = `badge ${job.status}`;
  badge.textContent = job.cancel_requested && job.status === "running" ? "stopping" : job.status;
  badge.title = job.error || (job.warnings || []).join("\n");
  const fraction = job.status === "succeeded" ? 1 : job.progress.fraction;
  const bar = tr.querySelector("progress");
  bar.value = fraction;
  const pct = tr.querySelector(".pct");
  pct.dataset.fraction = String(fraction);
  pct.textContent = `${Math.floor(100 * fraction)} %`;
  tr.querySelector(".progress").title = `${job.progress.paths.toLocaleString()} paths`;
  tr.querySelector(".time").textContent = timeTaken(job);
  const created = tr.querySelector(".created");
  created.textContent = new Date(job.created_at).toLocaleString();
  tr.querySelector("button.cancel").hidden = FINISHED.has(job.status) || job.cancel_requested;
  tr.querySelector("button.delete").hidden = !FINISHED.has(job.status);
}

async function refresh() {
  const mine = generation;
  const state = $("state-filter").value;
  const query = `?limit=${LIMIT}` + (state ? `&status=${state}` : "");
  let page;
  try {
    page = await apiJson(`/v1/jobs${query}`);
  } catch (err) {
    if (mine !== generation) return;
    showError(err.status === 401 ? "Give the API key above to see your jobs." : formatError(err.problem || err));
    return;
  }
  if (mine !== generation) return;
  showError("");
  const tbody = document.querySelector("#jobs tbody");
  const seen = new Set();
  page.items.forEach((job, i) => {
    seen.add(job.id);
    let tr = rows.get(job.id);
    if (!tr) {
      tr = newRow(job);
      rows.set(job.id, tr);
    }
    update(tr, job);
    if (tbody.children[i] !== tr) tbody.insertBefore(tr, tbody.children[i] || null);
  });
  for (const [id, tr] of rows) {
    if (!seen.has(id)) {
      tr.remove();
      rows.delete(id);
    }
  }
  $("jobs-empty").hidden = page.items.length > 0;
  $("list-note").textContent = page.next_cursor ? `the newest ${LIMIT} jobs` : "";
}

function showError(text) {
  $("jobs-error").textContent = text;
  $("jobs-error").hidden = !text;
}

async function cancelJob(id, btn) {
  btn.disabled = true;
  try {
    await apiFetch(`/v1/jobs/${encodeURIComponent(id)}/cancel`, { method: "POST" });
  } catch (err) {
    showError(formatError(err.problem || err));
  }
  btn.disabled = false;
  await refresh();
}

async function deleteJob(id, btn) {
  if (btn.dataset.armed !== "1") {
    // the first click asks; a second one within 4 s deletes
    btn.dataset.armed = "1";
    btn.textContent = "Delete?";
    btn.classList.add("armed");
    setTimeout(() => {
      btn.dataset.armed = "";
      btn.textContent = "Delete";
      btn.classList.remove("armed");
    }, 4000);
    return;
  }
  btn.disabled = true;
  try {
    await apiFetch(`/v1/jobs/${encodeURIComponent(id)}`, { method: "DELETE" });
  } catch (err) {
    showError(formatError(err.problem || err));
  }
  btn.disabled = false;
  await refresh();
}

function restart() {
  generation += 1;
  for (const tr of rows.values()) tr.remove();
  rows.clear();
  refresh();
}

initShell("jobs");
const params = new URLSearchParams(location.search);
if (params.get("status")) $("state-filter").value = params.get("status");
$("state-filter").addEventListener("change", () => {
  const state = $("state-filter").value;
  history.replaceState(null, "", state ? `?status=${state}` : location.pathname);
  restart();
});
document.addEventListener("owcsim:key", restart);
poll(refresh, 1000);
