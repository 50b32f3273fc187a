// The JSON API from the pages: the API key (typed once, kept in sessionStorage, sent as
// `Authorization: Bearer`), problem documents turned into errors, and polling.
// Every page gets its data through here, so a key sees in the pages exactly what it sees through the API.

const KEY = "owcsim.apiKey";

/** The API key of this browser tab ("" when none was given). */
export function getKey() {
  return sessionStorage.getItem(KEY) || "";
}

/** Keep `k` as the tab's API key (an empty one forgets it). */
export function setKey(k) {
  const key = (k || "").trim();
  if (key) sessionStorage.setItem(KEY, key);
  else sessionStorage.removeItem(KEY);
  document.dispatchEvent(new CustomEvent("owcsim:key", { detail: { set: Boolean(key) } }));
}

/** An answer that is not 2xx: `status` and the problem document (RFC 9457) the API sent. */
export class ApiError extends Error {
  constructor(status, problem) {
    super(formatError(problem));
    this.name = "ApiError";
    this.status = status;
    this.problem = problem;
  }
}

/** A problem document as one line of text: "Title: detail" (the located field errors are in `problem.errors`). */
export function formatError(problem) {
  if (!problem) return "no answer from the server";
  if (typeof problem === "string") return problem;
  if (problem instanceof Error && !(problem instanceof ApiError)) return problem.message;
  const title = problem.title || (problem.status ? `HTTP ${problem.status}` : "error");
  return problem.detail ? `${title}: ${problem.detail}` : title;
}

/** fetch() with the API key; resolves to the Response when 2xx, rejects with ApiError otherwise (a 401 also
 * fires the document event "owcsim:unauthorized", which the page's key prompt listens to). */
export async function apiFetch(path, options = {}) {
  const headers = new Headers(options.headers || {});
  const key = getKey();
  if (key) headers.set("Authorization", `Bearer ${key}`);
  let resp;
  try {
    resp = await fetch(path, { ...options, headers });
  } catch (err) {
    throw new ApiError(0, { title: "The server cannot be reached", detail: String(err.message || err) });
  }
  if (resp.ok) return resp;
  let problem;
  try {
    problem = await resp.json();
  } catch {
    problem = { status: resp.status, title: resp.statusText || `HTTP ${resp.status}` };
  }
  if (resp.status === 401) document.dispatchEvent(new CustomEvent("owcsim:unauthorized", { detail: problem }));
  throw new ApiError(resp.status, problem);
}

/** GET (or `options`) and parse the JSON answer (null for 204). */
export async function apiJson(path, options) {
  const resp = await apiFetch(path, options);
  return resp.status === 204 ? null : resp.json();
}

/** Send a JSON document (text or object) with `method` (POST by default); the parsed answer. */
export function apiSend(path, doc, { method = "POST", headers = {} } = {}) {
  const body = typeof doc === "string" ? doc : JSON.stringify(doc);
  return apiJson(path, { method, body, headers: { "Content-Type": "application/json", ...headers } });
}

/** Call `tick()` now and then every `intervalMs` after it settles (not while the tab is hidden); returns stop(). */
export function poll(tick, intervalMs = 1000) {
  let stopped = false;
  let timer = null;
  const run = async () => {
    timer = null;
    if (stopped) return;
    if (!document.hidden) {
      try {
        await tick();
      } catch (err) {
        console.error(err);
      }
    }
    if (!stopped) timer = setTimeout(run, intervalMs);
  };
  run();
  return () => {
    stopped = true;
    if (timer !== null) clearTimeout(timer);
  };
}

/** A random id (Idempotency-Key of a submission); crypto.randomUUID needs a secure context, this does not. */
export function randomId() {
  const bytes = crypto.getRandomValues(new Uint8Array(16));
  return Array.from(bytes, (b) => b.toString(16).padStart(2, "0")).join("");
}

/** A duration [s] for people: "0.84 s", "12.3 s", "4 min 05 s", "2 h 03 min". */
export function formatDuration(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "";
  if (s < 10) return `${s.toFixed(2)} s`;
  if (s < 60) return `${s.toFixed(1)} s`;
  const m = Math.floor(s / 60);
  if (m < 60) return `${m} min ${String(Math.round(s - 60 * m)).padStart(2, "0")} s`;
  return `${Math.floor(m / 60)} h ${String(m % 60).padStart(2, "0")} min`;
}

/** Bytes for people: "850 kB", "1.2 GB" (powers of 1000). */
export function formatBytes(b) {
  const units = ["B", "kB", "MB", "GB", "TB"];
  let i = 0;
  let v = b;
  while (v >= 1000 && i < units.length - 1) {
    v /= 1000;
    i += 1;
  }
  return `${v < 10 && i > 0 ? v.toFixed(1) : Math.round(v)} ${units[i]}`;
}

/** Text as HTML-safe text (for the few places that build markup from strings). */
export function escapeHtml(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
}
