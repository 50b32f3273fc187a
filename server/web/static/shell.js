// The frame every page shares: the navigation and the API key box. Call initShell("jobs" | "submit" | "result")
// from a page's module; it fills <header id="shell">. The key box asks for a key when the server answers 401
// (event "owcsim:unauthorized" from api.js) and keeps it for the tab (sessionStorage).

import { apiFetch, getKey, setKey } from "./api.js";

const LINKS = [
  ["jobs", "/ui", "Jobs"],
  ["submit", "/ui/submit", "Submit"],
  ["api", "/v1/docs", "API"],
];

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "text") e.textContent = v;
    else e.setAttribute(k, v);
  }
  e.append(...children);
  return e;
}

/** Build the header; `active` names the current page's link. */
export function initShell(active) {
  let header = document.getElementById("shell");
  if (!header) {
    header = el("header", { id: "shell" });
    document.body.prepend(header);
  }
  header.replaceChildren();
  const nav = el("nav", { class: "nav" }, el("a", { href: "/ui", class: "brand", text: "owcsim" }));
  for (const [name, href, label] of LINKS) {
    nav.append(el("a", { href, text: label, ...(name === active ? { "aria-current": "page" } : {}) }));
  }
  header.append(nav, keyBox());
  // no key yet: ask the API whether it needs one (a 401 opens the prompt)
  if (!getKey()) apiFetch("/v1/jobs?limit=1").catch(() => {});
}

function keyBox() {
  const box = el("div", { class: "key-box", id: "key-box" });
  const message = el("span", { class: "key-message", id: "key-message" });
  const input = el("input", {
    type: "password",
    id: "api-key",
    name: "api-key",
    placeholder: "API key",
    autocomplete: "off",
    "aria-label": "API key",
  });
  const form = el("form", { id: "key-form" }, message, input, el("button", { type: "submit", text: "Use key" }));
  const status = el("span", { id: "key-status" });
  const forget = el("button", { type: "button", id: "key-forget", class: "link", text: "forget key" });
  const show = (asking, text = "") => {
    form.hidden = !asking;
    status.hidden = forget.hidden = asking || !getKey();
    status.textContent = getKey() ? "API key set" : "";
    message.textContent = text;
    box.classList.toggle("asking", asking);
    if (asking) input.focus();
  };
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    const key = input.value;
    input.value = "";
    setKey(key); // the page reloads its data on "owcsim:key"
    show(false);
  });
  forget.addEventListener("click", () => {
    setKey("");
    show(true, "Key forgotten.");
  });
  document.addEventListener("owcsim:unauthorized", (ev) => {
    const detail = (ev.detail && ev.detail.detail) || "";
    show(true, getKey() ? "This key is not valid on this server:" : "This server needs an API key:");
    box.title = detail;
  });
  box.append(form, status, forget);
  show(false);
  return box;
}
