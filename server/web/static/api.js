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
  const headers = new Headers(options.headers || {});
  const key = getKey();
  if (key) headers.set("Authorization", `Bearer ${key}`);
  return fetch(path, { ...options, headers });
}

export async function apiJson(path) {
  const r = await apiFetch(path);
  const body = await r.json().catch(() => null);
  if (!r.ok) {
    const err = new Error(formatError(body) || `HTTP ${r.status}`);
    err.status = r.status;
    err.problem = body;
    throw err;
  }
  return body;
}

export function formatError(problem) {
  if (!problem) return "";
  const lines = [problem.detail || problem.title || ""];
  for (const e of problem.errors || []) lines.push(`${e.loc}: ${e.msg}`);
  return lines.filter(Boolean).join("\n");
}
