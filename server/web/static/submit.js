// The submit page: a scene document from an example (GET /v1/examples), a file or the keyboard; "Check" runs
// the server's pre-flight (POST /v1/preflight: the checks of a submission, the memory and time estimate, what
// the job will model); "Submit job" (enabled once the text in the editor has passed) posts it to /v1/jobs and
// opens the job's page. Errors of a 422/400 problem document are shown next to the line of the field they name.

import { apiJson, apiSend, formatBytes, formatDuration, formatError, randomId } from "./api.js";
import { jsonLines, lineOf } from "./jsonlines.js";
import { initShell } from "./shell.js";

const $ = (id) => document.getElementById(id);
const doc = $("doc");
let checkedText = null; // the text the last successful pre-flight checked
let idempotency = { text: null, key: null }; // one key per document text: a double click queues one job
let examples = [];

function setState(text) {
  $("state").textContent = text;
}

function lineCount() {
  return doc.value.split("\n").length;
}

/** Line numbers in the gutter, the error lines marked. */
function drawGutter(bad = new Map()) {
  const gutter = $("gutter");
  gutter.replaceChildren();
  for (let n = 1; n <= lineCount(); n += 1) {
    const span = document.createElement("span");
    span.textContent = String(n);
    if (bad.has(n)) {
      span.className = "bad";
      span.title = bad.get(n).join("\n");
    }
    gutter.append(span);
  }
  syncScroll();
}

function syncScroll() {
  $("gutter").scrollTop = doc.scrollTop;
  $("notes-inner").style.transform = `translateY(${-doc.scrollTop}px)`;
}

function lineHeight() {
  return parseFloat(getComputedStyle(doc).lineHeight) || 18;
}

function clearErrors() {
  $("errors").replaceChildren();
  $("notes-inner").replaceChildren();
  $("problem").hidden = true;
  drawGutter();
}

/** A problem document on the page: its title and detail, and each located error next to its line. */
function showProblem(problem) {
  clearErrors();
  const errors = problem.errors || [];
  let lines = null;
  try {
    lines = jsonLines(doc.value);
  } catch {
    lines = null; // not JSON: the server's message gives the line
  }
  const bad = new Map();
  const top = parseFloat(getComputedStyle(doc).paddingTop) || 0;
  for (const e of errors) {
    let line = lines ? lineOf(lines, e.loc) : undefined;
    const m = /line (\d+)/.exec(e.msg);
    if (e.loc === "body" && m) line = Number(m[1]);
    const li = document.createElement("li");
    li.className = "field-error";
    li.dataset.loc = e.loc;
    if (line !== undefined) {
      li.dataset.line = String(line);
      bad.set(line, [...(bad.get(line) || []), e.msg]);
      const note = document.createElement("div");
      note.className = "note-error";
      note.dataset.loc = e.loc;
      note.dataset.line = String(line);
      note.style.top = `${top + (line - 1) * lineHeight()}px`;
      note.textContent = cliText(e);
      note.title = note.textContent;
      note.addEventListener("click", () => goToLine(line));
      $("notes-inner").append(note);
    }
    const where = line !== undefined ? `line ${line}: ` : "";
    li.textContent = `${where}${cliText(e)}`;
    li.addEventListener("click", () => line !== undefined && goToLine(line));
    $("errors").append(li);
  }
  if (!errors.length) {
    $("problem").textContent = formatError(problem);
    $("problem").hidden = false;
  }
  drawGutter(bad);
  if (bad.size) {
    doc.scrollTop = Math.max(0, (Math.min(...bad.keys()) - 5) * lineHeight()); // the first one in view
    syncScroll();
  }
}

/** An error as `owcsim validate` prints it: "receivers.0.fov_deg: Input should be ..." (the document's own
 * level, `body`, as "document"). */
function cliText(e) {
  return `${e.loc.replace(/^body\.?/, "") || "document"}: ${e.msg}`;
}

function goToLine(n) {
  const starts = [0];
  for (let i = 0; i < doc.value.length; i += 1) if (doc.value[i] === "\n") starts.push(i + 1);
  const at = starts[Math.min(n, starts.length) - 1];
  doc.focus();
  doc.setSelectionRange(at, doc.value.indexOf("\n", at) === -1 ? doc.value.length : doc.value.indexOf("\n", at));
  doc.scrollTop = Math.max(0, (n - 5) * lineHeight());
  syncScroll();
}

function showEstimate(est) {
  $("est-memory").textContent = formatBytes(est.memory_bytes);
  $("est-time").textContent = est.time_s === null ? "unknown" : `about ${formatDuration(est.time_s)}`;
  $("est-time").title = est.time_basis;
  $("est-time").dataset.seconds = est.time_s === null ? "" : String(est.time_s);
  const basis = document.createElement("span");
  basis.className = "note";
  basis.textContent = ` (${est.time_basis})`;
  $("est-time").append(basis);
  $("est-memory").dataset.bytes = String(est.memory_bytes);
  $("est-paths").textContent = est.paths === null ? "until the accuracy asked" : est.paths.toLocaleString();
  $("est-receivers").textContent = est.receivers.toLocaleString();
  $("est-triangles").textContent = est.triangles.toLocaleString();
  const dl = $("est-modeled");
  dl.replaceChildren();
  for (const [k, v] of Object.entries(est.modeled)) {
    const dt = document.createElement("dt");
    dt.textContent = k.replaceAll("_", " ");
    const dd = document.createElement("dd");
    dd.textContent = v;
    dd.dataset.key = k;
    dl.append(dt, dd);
  }
  $("estimate").hidden = false;
}

function edited() {
  const ok = checkedText !== null && doc.value === checkedText;
  $("submit").disabled = !ok;
  if (!ok) setState(doc.value.trim() ? "Check the document before submitting." : "");
}

async function check() {
  const text = doc.value;
  if (!text.trim()) {
    setState("The editor is empty: choose an example, open a file or paste a document.");
    return;
  }
  $("check").disabled = true;
  setState("Checking…");
  try {
    const est = await apiSend("/v1/preflight", text);
    if (doc.value !== text) return; // edited meanwhile
    clearErrors();
    checkedText = text;
    showEstimate(est);
    setState("The document passed every check: submit it.");
  } catch (err) {
    checkedText = null;
    $("estimate").hidden = true;
    if (err.status === 401) setState("Give the API key above, then check again.");
    else setState("The server refused the document: see below.");
    if (err.problem && err.status !== 401) showProblem(err.problem);
  } finally {
    $("check").disabled = false;
    edited();
  }
}

async function submit() {
  const text = doc.value;
  if (text !== checkedText) return;
  if (idempotency.text !== text) idempotency = { text, key: randomId() };
  $("submit").disabled = true;
  setState("Submitting…");
  try {
    const job = await apiSend("/v1/jobs", text, { headers: { "Idempotency-Key": idempotency.key } });
    setState(`Job ${job.id} queued.`);
    location.assign(`/ui/jobs/${encodeURIComponent(job.id)}`);
  } catch (err) {
    setState("The server refused the job: see below.");
    if (err.problem) showProblem(err.problem);
    $("submit").disabled = false;
  }
}

function load(text) {
  doc.value = text;
  doc.scrollTop = 0;
  checkedText = null;
  clearErrors();
  $("estimate").hidden = true;
  edited();
  check();
}

async function loadExamples() {
  try {
    examples = (await apiJson("/v1/examples")).items;
  } catch (err) {
    setState(`No examples: ${formatError(err.problem || err)}`);
    return;
  }
  for (const ex of examples) {
    const opt = document.createElement("option");
    opt.value = ex.id;
    opt.textContent = ex.name;
    $("example").append(opt);
  }
}

initShell("submit");
drawGutter();
doc.addEventListener("input", () => {
  drawGutter();
  edited();
});
doc.addEventListener("scroll", syncScroll);
$("check").addEventListener("click", check);
$("submit").addEventListener("click", submit);
$("example").addEventListener("change", () => {
  const ex = examples.find((e) => e.id === $("example").value);
  if (ex) load(JSON.stringify(ex.document, null, 2));
});
$("file").addEventListener("change", async () => {
  const f = $("file").files[0];
  if (f) load(await f.text());
});
document.addEventListener("owcsim:key", () => doc.value.trim() && check());
loadExamples();
