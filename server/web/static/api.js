// STAND-IN of branch webresult for the `webjobs` branch's api.js (drop at merge, keep theirs): the same exports.
const KEY = "owcsim-api-key";

export function getKey() {
  return sessionStorage.getItem(KEY) || "";
}

export function setKey(k) {
  if (k) sessionStorage.setItem(KEY, k);
  else sessionStorage.removeItem(KEY);
}

export async function apiFetch(path, options = {}) {
  // as webjobs' api.js: the Response when 2xx, else an Error with `status` and the problem document
  const headers = new Headers(options.headers || {});
  const key = getKey();
  if (key) headers.set("Authorization", `Bearer ${key}`);
  const r = await fetch(path, { ...options, headers });
  if (r.ok) return r;
  const problem = await r.json().catch(() => null);
  const err = new Error(formatError(problem) || `HTTP ${r.status}`);
  err.status = r.status;
  err.problem = problem;
  throw err;
}

export async function apiJson(path) {
  return (await apiFetch(path)).json();
}

export function formatError(problem) {
  if (!problem) return "";
  const lines = [problem.detail || problem.title || ""];
  for (const e of problem.errors || []) lines.push(`${e.loc}: ${e.msg}`);
  return lines.filter(Boolean).join("\n");
}
