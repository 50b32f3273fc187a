"""The pages against hostile and unusual jobs (review of issue 27): text from a document or the server (a job's
name, device ids, group names, warnings, a failed job's error, located validation errors) renders as text and
runs no script on any page; another API key can neither see nor act on a job through the JSON the pages call;
a real timeline job draws its timeline, its smoke over time and the receiver's walk; a cancelled job shows its
partial result; a failed job its error.
"""

from __future__ import annotations

import json
import re
import sqlite3
import time

import httpx
import pytest

from tests.server.helpers import quick_doc
from tests.web.conftest import KEYS
from tests.web.test_result_page import map_doc

pytestmark = pytest.mark.filterwarnings("ignore:Session-scoped fixtures defined as instance methods")

KEY, OTHER_KEY = KEYS
WAIT_MS = 30_000

#: Markup that runs a script if any page puts it into the DOM as HTML (in text or in an attribute).
EVIL = '<img src=x onerror="window.__xss=1">"><svg onload="window.__xss=2"><script>window.__xss=3</script>'
#: How a page would show that a script ran, or that markup from the data became elements.
RAN = """() => ({ ran: window.__xss === undefined ? null : window.__xss,
    elements: document.querySelectorAll("main img, main script, [onerror], [onload]").length })"""


def _auth(key: str = KEY) -> dict:
    return {"Authorization": f"Bearer {key}"}


def submit(base: str, doc: dict, key: str = KEY) -> dict:
    r = httpx.post(f"{base}/v1/jobs", json=doc, headers=_auth(key), timeout=60)
    assert r.status_code == 202, r.text
    return r.json()


def wait(base: str, job: dict, key: str = KEY, timeout: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout
    while job["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, job
        time.sleep(0.2)
        job = httpx.get(f"{base}{job['url']}", headers=_auth(key), timeout=10).json()
    return job


def with_key(page, base: str, key: str = KEY) -> None:
    """The tab's API key, as the pages keep it (sessionStorage), set before any page of the server asks."""
    page.set_viewport_size({"width": 1200, "height": 900})
    page.goto(f"{base}/ui/static/base.css")
    page.evaluate("k => sessionStorage.setItem('owcsim.apiKey', k)", key)


def open_job(page, base: str, job_id: str) -> None:
    page.goto(f"{base}/ui/jobs/{job_id}")
    page.wait_for_selector("body[data-state=plotted], body[data-state=error]", timeout=WAIT_MS)


def assert_no_script_ran(page) -> None:
    page.wait_for_load_state("networkidle")
    page.wait_for_timeout(200)  # an <img onerror> fires after its (failed) load
    assert page.evaluate(RAN) == {"ran": None, "elements": 0}


@pytest.fixture(scope="module")
def hostile_job(web_server):
    """A finished job whose name, transmitter, receiver and group carry markup (a map with two groups too)."""
    doc = map_doc(n=3, paths=200)
    doc["name"] = "job " + EVIL
    doc["transmitters"][0]["id"] = "led1" + EVIL
    doc["transmitter_groups"] = [{"name": "group " + EVIL, "transmitters": ["led1" + EVIL, "led2"]}]
    doc["receivers"][0]["id"] = "desk" + EVIL
    doc["receiver_grids"][0]["id_prefix"] = "plane" + EVIL.replace(" ", "")
    doc["lighting"]["task_areas"][0]["grid"] = doc["receiver_grids"][0]["id_prefix"]
    doc["lighting"]["task_areas"][0]["name"] = "area " + EVIL
    job = wait(web_server.url, submit(web_server.url, doc))
    assert job["status"] == "succeeded", job
    return job


def test_markup_in_a_jobs_text_renders_as_text_on_the_jobs_list_and_its_page(page, web_server, hostile_job):
    with_key(page, web_server.url)
    page.goto(f"{web_server.url}/ui")
    row = page.locator(f'#jobs tr[data-job-id="{hostile_job["id"]}"]')
    row.wait_for(timeout=WAIT_MS)
    assert row.locator(".name a").inner_text() == hostile_job["name"]
    assert_no_script_ran(page)

    open_job(page, web_server.url, hostile_job["id"])
    assert page.get_attribute("body", "data-state") == "plotted"
    assert page.inner_text("#job-title") == hostile_job["name"]
    assert "desk" + EVIL in page.inner_text("#links-table") and "group " + EVIL in page.inner_text("#channels-table")
    assert page.locator("#map-select option").count() == 1 and EVIL in page.inner_text("#map-select")
    assert page.locator("#u0-table tr[data-part=task]").get_attribute("data-area") == "area " + EVIL
    assert page.locator("#preview svg[data-view=top] .luminaire").count() == 2
    assert page.locator("#preview svg[data-view=top] .luminaire").first.get_attribute("data-id") == "led1" + EVIL
    page.hover("#preview svg[data-view=top] .receiver")
    assert_no_script_ran(page)
    # long names stay inside the page: its menus do not widen it (a horizontal scroll bar for the whole page)
    assert page.evaluate("document.documentElement.scrollWidth") <= 1200
    for menu in ("#curve-source", "#map-select"):
        box = page.locator(menu).bounding_box()
        assert box["x"] + box["width"] <= 1200, menu


def test_a_failed_jobs_error_renders_as_text(page, web_server):
    """A failed job's page says why, as text (the error is set in the job store: a worker's own message)."""
    job = wait(web_server.url, submit(web_server.url, {**quick_doc(), "name": "fails"}))
    with sqlite3.connect(web_server.db) as con:
        con.execute("UPDATE jobs SET status = 'failed', error = ? WHERE id = ?", ("worker died: " + EVIL, job["id"]))
    with_key(page, web_server.url)
    open_job(page, web_server.url, job["id"])
    assert page.inner_text("#message") == "the job failed: worker died: " + EVIL
    assert page.locator("#metrics").is_hidden() and page.locator("#preview").is_visible()
    assert_no_script_ran(page)
    page.goto(f"{web_server.url}/ui?status=failed")
    page.locator(f'#jobs tr[data-job-id="{job["id"]}"]').wait_for(timeout=WAIT_MS)
    assert_no_script_ran(page)


def test_validation_errors_with_markup_render_as_text_on_the_submit_page(page, web_server):
    bad = quick_doc()
    bad["name"] = EVIL
    bad["receivers"][0]["fov_deg"] = EVIL  # its message quotes the value
    bad["receivers"][0][EVIL] = 1  # an unknown field: its location is the markup
    with_key(page, web_server.url)
    page.goto(f"{web_server.url}/ui/submit")
    page.fill("#doc", json.dumps(bad, indent=2))
    page.click("#check")
    page.locator("#errors li").first.wait_for(timeout=WAIT_MS)
    assert page.locator("#errors li").count() >= 2
    assert any(EVIL in t for t in page.locator("#errors li").all_inner_texts())
    assert_no_script_ran(page)


def test_another_key_can_neither_read_nor_act_on_a_job(web_server):
    """Every route the pages call, with the other tenant's key: 'not found'; the job is untouched."""
    job = wait(web_server.url, submit(web_server.url, {**quick_doc(), "name": "tenant A"}))
    url = f"{web_server.url}{job['url']}"
    calls = [
        ("GET", ""),
        ("GET", "/scene"),
        ("GET", "/result"),
        ("GET", "/result.csv"),
        ("GET", "/timeline"),
        ("GET", "/timeline.csv"),
        ("POST", "/cancel"),
        ("DELETE", ""),
    ]
    for method, tail in calls:
        r = httpx.request(method, url + tail, headers=_auth(OTHER_KEY), timeout=30)
        assert r.status_code == 404, (method, tail, r.status_code)
        assert "tenant A" not in r.text
    listed = httpx.get(f"{web_server.url}/v1/jobs", headers=_auth(OTHER_KEY), timeout=10).json()["items"]
    assert job["id"] not in {j["id"] for j in listed}
    mine = httpx.get(url, headers=_auth(), timeout=10).json()
    assert mine["status"] == "succeeded" and not mine["cancel_requested"]
    assert httpx.get(url + "/result", headers=_auth(), timeout=30).status_code == 200


def timeline_doc() -> dict:
    """Smoke thickening in the upper half over 30 s (inline frames) while the receiver walks across the room."""
    doc = quick_doc(paths=3000)
    doc["name"] = "smoke and a walk (web test)"
    doc["timeline"] = {
        "frames": {
            "type": "inline",
            "times": [0.0, 30.0],
            "min": [0, 0, 0],
            "max": [5, 5, 3],
            "shape": [1, 1, 2],
            "sigma_a": [0.0, [0.0, 1.0]],
            "sigma_s": [0.0, 0.0],
        },
        "times_s": [0.0, 10.0, 20.0, 30.0],
        "trajectories": [
            {"device": "rx", "waypoints": [[1.0, 1.0, 0.0], [4.0, 1.0, 0.0], [4.0, 4.0, 0.0]], "speed_m_s": 0.2}
        ],
        "outage": {"quantity": "dc_gain", "threshold": 1e-6},
    }
    return doc


def test_a_timeline_job_draws_its_timeline_smoke_over_time_and_walk(page, web_server):
    job = wait(web_server.url, submit(web_server.url, timeline_doc()))
    assert job["status"] == "succeeded", job
    result = httpx.get(f"{web_server.url}{job['urls']['result']}", headers=_auth(), timeout=30).json()
    link = result["timeline"]["links"][0]
    with_key(page, web_server.url)
    open_job(page, web_server.url, job["id"])
    assert page.locator("#timeline").is_visible()
    pts = page.locator("#timeline-plot .pt")
    got = pts.evaluate_all("els => els.map(e => e.dataset.value)")
    assert [float(v) if v else None for v in got] == link["dc_gain"]
    assert page.locator("#downloads a[data-key='timeline.csv']").count() == 1
    for view in ("top", "side"):
        svg = page.locator(f"#preview svg[data-view={view}]")
        assert svg.locator(".smoke").count() == 1, view  # the frames' grid: the smoke over time
        walk = svg.locator(".trajectory[data-device=rx]")
        assert walk.count() == 1, view
        assert len(walk.get_attribute("points").split()) == 3
    assert page.locator("#preview svg[data-view='3d'] .trajectory").count() == 1
    assert "smoke over time" in page.inner_text("#preview .preview-counts")


def test_a_cancelled_jobs_partial_result_is_drawn(page, web_server):
    job = submit(web_server.url, {**quick_doc(paths=200_000_000, batch_size=4096), "name": "cancelled (web test)"})
    base = web_server.url
    deadline = time.monotonic() + 60
    while httpx.get(f"{base}{job['url']}", headers=_auth(), timeout=10).json()["progress"]["paths"] == 0:
        assert time.monotonic() < deadline
        time.sleep(0.2)
    assert httpx.post(f"{base}{job['url']}/cancel", headers=_auth(), timeout=10).status_code == 202
    job = wait(base, job)
    assert job["status"] == "cancelled"
    result = httpx.get(f"{base}{job['urls']['result']}", headers=_auth(), timeout=30).json()
    with_key(page, base)
    open_job(page, base, job["id"])
    assert page.get_attribute("body", "data-state") == "plotted"
    assert page.inner_text("#job-status").startswith("cancelled")
    assert "stopped: cancelled" in page.inner_text("#metrics .run")
    cell = page.locator("#links-table td[data-field=dc_gain]")
    assert float(cell.get_attribute("data-value")) == result["links"][0]["dc_gain"]


def test_the_result_page_keeps_following_a_job_through_a_failed_poll(page, web_server):
    """While the job runs, two polls fail (503: a server restarting); the page says so, polls on, and draws the
    result once the job stops. A job that is gone while its page is open (404) ends the page with the error."""
    base = web_server.url
    job = submit(base, {**quick_doc(paths=200_000_000, batch_size=4096), "name": "followed (web test)"})
    failures = {"left": 0}

    def flaky(route):
        if failures["left"] > 0:
            failures["left"] -= 1
            problem = {"type": "about:blank", "title": "Service Unavailable", "status": 503, "detail": "restarting"}
            route.fulfill(status=503, content_type="application/problem+json", body=json.dumps(problem))
        else:
            route.continue_()

    page.route(re.compile(rf"/v1/jobs/{job['id']}$"), flaky)
    with_key(page, base)
    page.goto(f"{base}/ui/jobs/{job['id']}")
    page.wait_for_function("document.querySelector('#job-status').dataset.status === 'running'", timeout=WAIT_MS)
    failures["left"] = 2
    page.wait_for_function("document.querySelector('#message').textContent.includes('trying again')", timeout=WAIT_MS)
    deadline = time.monotonic() + 30
    while failures["left"] > 0:
        assert time.monotonic() < deadline
        page.wait_for_timeout(200)
    assert httpx.post(f"{base}{job['url']}/cancel", headers=_auth(), timeout=10).status_code == 202
    page.wait_for_selector("body[data-state=plotted], body[data-state=error]", timeout=WAIT_MS)
    assert page.get_attribute("body", "data-state") == "plotted"
    assert page.inner_text("#job-status").startswith("cancelled")
    assert page.locator("#metrics").is_visible() and page.locator("#message").is_hidden()

    # gone while followed: the page stops with the API's message
    job = submit(base, {**quick_doc(paths=200_000_000, batch_size=4096), "name": "gone (web test)"})
    gone = {"now": False}

    def deleted(route):
        if gone["now"]:
            problem = {"type": "about:blank", "title": "Not Found", "status": 404, "detail": f"no job '{job['id']}'"}
            route.fulfill(status=404, content_type="application/problem+json", body=json.dumps(problem))
        else:
            route.continue_()

    page.route(re.compile(rf"/v1/jobs/{job['id']}$"), deleted)
    page.goto(f"{base}/ui/jobs/{job['id']}")
    page.wait_for_function("document.querySelector('#job-status').dataset.status === 'running'", timeout=WAIT_MS)
    gone["now"] = True
    page.wait_for_selector("body[data-state=error]", timeout=WAIT_MS)
    assert "no job" in page.inner_text("#message")
    httpx.post(f"{base}{job['url']}/cancel", headers=_auth(), timeout=10)


def test_no_page_asks_for_a_file_the_server_does_not_have(page, web_server):
    """Every page names its icon (the server's own file): the browser does not ask for /favicon.ico, which is
    404 and an error in the console on every page."""
    logged = len(web_server.log.read_text())  # earlier tests opened other addresses (a CSS file has no icon)
    answers: list[tuple[str, int]] = []
    page.on("response", lambda r: answers.append((r.url, r.status)))
    for path in ("/ui", "/ui/submit", "/ui/jobs/0123"):
        page.goto(web_server.url + path)
        page.wait_for_load_state("networkidle")
    statics = [(u, s) for u, s in answers if "/v1/" not in u]
    assert statics and all(s == 200 for _, s in statics), statics
    log = web_server.log.read_text()[logged:]
    assert "/favicon.ico" not in log, [line for line in log.splitlines() if "favicon" in line][:3]
    icon = page.evaluate("() => document.querySelector('link[rel=icon]').href")
    assert httpx.get(icon, timeout=10).headers["content-type"].startswith("image/svg+xml")


def test_maps_of_several_grids_and_channels_each_draw_the_apis_values(page, web_server):
    """A floor plane and a wall grid, two transmitter groups: every (grid, channel) map is offered and draws its
    own shape, values and axes."""
    doc = map_doc(n=4, paths=200)
    doc["name"] = "two grids, two groups (web test)"
    doc["transmitter_groups"] = [
        {"name": "ceiling", "transmitters": ["led1", "led2"]},
        {"name": "left", "transmitters": ["led1"]},
    ]
    doc["receiver_grids"].append(
        {"id_prefix": "wall", "origin": [5.0, 0.5, 0.5], "u": [0, 1, 0], "v": [0, 0, 1], "size": [3.0, 2.0],
         "shape": [4, 3], "area": 1e-4, "fov_deg": 85}
    )  # fmt: skip
    job = wait(web_server.url, submit(web_server.url, doc))
    assert job["status"] == "succeeded", job
    result = httpx.get(f"{web_server.url}{job['urls']['result']}", headers=_auth(), timeout=30).json()
    maps = result["maps"]
    assert {(m["grid"], m["channel"]) for m in maps} == {(g, c) for g in ("plane", "wall") for c in ("ceiling", "left")}
    with_key(page, web_server.url)
    open_job(page, web_server.url, job["id"])
    assert page.locator("#map-select option").count() == len(maps)
    for k, m in enumerate(maps):
        page.select_option("#map-select", str(k))
        page.select_option("#quantity-select", "dc_gain")
        cells = page.locator("#map-plot rect.cell")
        nu, nv = m["shape"]
        assert cells.count() == nu * nv, (m["grid"], m["channel"])
        drawn = cells.evaluate_all("els => els.map(e => [+e.dataset.i, +e.dataset.j, e.dataset.value])")
        assert sorted((i, j) for i, j, _ in drawn) == [(i, j) for i in range(nu) for j in range(nv)]
        for i, j, v in drawn:
            assert (float(v) if v else None) == m["values"]["dc_gain"][i][j]
        labels = page.locator("#map-plot svg text").evaluate_all("els => els.map(e => e.textContent)")
        assert ("y [m]" in labels and "z [m]" in labels) if m["grid"] == "wall" else ("x [m]" in labels)
        # the first point of the grid sits at the low end of both axes: left of and below the last one
        first = page.locator("#map-plot rect.cell[data-i='0'][data-j='0']").bounding_box()
        last = page.locator(f"#map-plot rect.cell[data-i='{nu - 1}'][data-j='{nv - 1}']").bounding_box()
        assert first["x"] < last["x"] and first["y"] > last["y"]
        areas = [a for a in result["lighting"]["areas"] if a["grid"] == m["grid"] and a["channel"] == m["channel"]]
        assert page.locator("#u0-table").count() == (1 if areas else 0)
