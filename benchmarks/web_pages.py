"""Load time of the result page for a map of 2,500 points, in headless Chromium (issue 27: under 1 s on a 2-core
machine).

A real `owcsim serve` on 127.0.0.1 with an API key runs Komine & Nakagawa's room (examples/komine_map.json: four
lamps in one group, a 50 x 50 work-plane grid, here with a task area for U0 and few paths: the figure is the
page's, not the engine's). The page /ui/jobs/{id} is then opened `--runs` times in the system's Chromium; each
run is one navigation, timed from its start to the moment the page has drawn everything (the page sets
<body data-state="plotted"> and data-plotted-ms = performance.now(), whose origin is the navigation's start):
the job, the result document (JSON, gzip on the wire), the scene, the metrics, CIR, maps (2,500 SVG cells) and
the preview. "cold" runs clear the browser's cache first (every asset fetched), "warm" ones open the page again in the
same tab (assets from the cache, as when coming from the jobs list).

    .venv/bin/python benchmarks/web_pages.py [--runs 5] [--spacing 0.1] [--paths 100]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import httpx  # noqa: E402

from tests.server.helpers import ServerProcess  # noqa: E402
from tests.web.conftest import CHROMIUM, CHROMIUM_ARGS  # noqa: E402

KEY = "bench-key"
#: The page is drawn within this time [s] on a 2-core machine (issue 27).
TARGET_S = 1.0


def komine_doc(spacing: float, paths: int) -> dict:
    """examples/komine_map.json with few paths, K = 1, a binned window and a desk task area (U0)."""
    doc = json.loads((ROOT / "examples" / "komine_map.json").read_text())
    doc.pop("description")  # longer than the service accepts by default (max_text_chars)
    doc["receiver_grids"][0]["spacing"] = spacing
    doc["simulation"] = {"max_reflections": 1, "paths": paths, "seed": 1, "time_bin_s": 1e-9, "t_max_s": 4e-8}
    doc["lighting"] = {"task_areas": [{"name": "desk", "grid": "plane", "min": [1, 1, 0.85], "max": [4, 4, 0.85]}]}
    return doc


def run_job(base: str, doc: dict) -> dict:
    auth = {"Authorization": f"Bearer {KEY}"}
    r = httpx.post(f"{base}/v1/jobs", json=doc, headers=auth, timeout=120)
    if r.status_code != 202:
        raise SystemExit(f"the service refused the job: {r.text}")
    job = r.json()
    while job["status"] in ("queued", "running"):
        time.sleep(0.5)
        job = httpx.get(f"{base}{job['url']}", headers=auth).json()
    if job["status"] != "succeeded":
        raise SystemExit(f"the job did not succeed: {job}")
    return job


#: The phases of the result document in the page [ms since navigation]: its request and the end of its download
#: (resource timing), parsed and drawn (result.js's performance marks).
PHASES = """() => {
  const r = performance.getEntriesByType("resource").filter(e => e.name.endsWith("/result")).pop();
  const m = Object.fromEntries(performance.getEntriesByType("mark").map(e => [e.name, e.startTime]));
  return {requested: r.startTime, downloaded: r.responseEnd, ...m};
}"""


def page_times(base: str, job: dict, runs: int) -> dict[str, list[float]]:
    """Navigation-to-plotted times [s] of `runs` cold and `runs` warm loads of the job's result page."""
    from playwright.sync_api import sync_playwright

    url = f"{base}/ui/jobs/{job['id']}"
    out: dict[str, list[float]] = {"cold": [], "warm": [], "download": [], "parse": [], "draw": []}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        context = browser.new_context(viewport={"width": 1200, "height": 900})
        page = context.new_page()
        cdp = context.new_cdp_session(page)
        page.goto(url)  # first visit: no key yet (401), the page asks for it
        page.wait_for_selector("#api-key:visible, #result-key-input:visible")
        # the key straight into this tab's sessionStorage: api.js's setKey() also fires "owcsim:key", on which the
        # result page reloads itself, and that reload raced the first page.goto below ("navigation interrupted")
        page.evaluate("k => sessionStorage.setItem('owcsim.apiKey', k)", KEY)
        for _ in range(runs):
            for kind in ("cold", "warm"):
                if kind == "cold":
                    cdp.send("Network.clearBrowserCache")  # every asset fetched again
                page.goto(url)
                page.wait_for_selector("body[data-state=plotted]", timeout=60_000)
                if page.locator("#maps rect.cell").count() == 0:
                    raise SystemExit("the page drew no map")
                out[kind].append(float(page.get_attribute("body", "data-plotted-ms")) / 1000)
                marks = page.evaluate(PHASES)
                out["download"].append((marks["downloaded"] - marks["requested"]) / 1000)
                out["parse"].append((marks["owcsim:result-parsed"] - marks["downloaded"]) / 1000)
                out["draw"].append((marks["owcsim:result-drawn"] - marks["owcsim:result-parsed"]) / 1000)
        browser.close()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--spacing", type=float, default=0.1, help="grid spacing [m]: 0.1 gives 50 x 50 points")
    ap.add_argument("--paths", type=int, default=100, help="paths per receiver")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="owcsim-web-"))
    with ServerProcess(tmp / "jobs.sqlite", api_keys=KEY) as srv:
        t0 = time.perf_counter()
        job = run_job(srv.url, komine_doc(args.spacing, args.paths))
        t_job = time.perf_counter() - t0
        auth = {"Authorization": f"Bearer {KEY}"}
        raw = httpx.get(f"{srv.url}{job['urls']['result']}", headers=auth, timeout=120)
        result = raw.json()
        with httpx.stream("GET", f"{srv.url}{job['urls']['result']}", headers=auth, timeout=120) as r:
            r.read()
            wire = r.num_bytes_downloaded  # gzip on the wire, as the browser gets it
        points = sum(m["shape"][0] * m["shape"][1] for m in result["maps"])
        print(f"map points: {points}; links: {len(result['links'])}; job ran in {t_job:.1f} s")
        print(f"result document: {len(raw.content) / 1e6:.1f} MB of JSON" + f", {wire / 1e6:.2f} MB on the wire (gzip)")
        times = page_times(srv.url, job, args.runs)
    load = os.getloadavg()[0]
    print(
        f"result page, navigation to plotted over {args.runs} runs (target < {TARGET_S:g} s), load average {load:.1f}:"
    )
    for kind in ("cold", "warm"):
        ts = times[kind]
        runs = ", ".join(f"{t:.3f} s" for t in ts)
        print(f"  {kind}: median {statistics.median(ts):.3f} s, slowest {max(ts):.3f} s (runs: {runs})")
    phases = ", ".join(f"{k} {statistics.median(times[k]):.3f} s" for k in ("download", "parse", "draw"))
    print(f"  the result document, medians: {phases}")
    worst = max(max(times["cold"]), max(times["warm"]))
    print(f"slowest load {worst:.3f} s: {'within' if worst < TARGET_S else 'OVER'} the target")
    return 0


if __name__ == "__main__":
    sys.exit(main())
