"""The result page and the scene preview (issue 27, items 3 and 4) in headless Chromium: the plotted numbers
equal the API's (every plotted number carries its value in a data attribute), hover shows a map point's value,
U0, downloads, the preview draws every device, a timeline renders from an injected result. The tests write the
docs' screenshots (docs/figures/web-result.png, web-map.png, web-preview.png).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import httpx
import pytest

from tests.web.conftest import KEYS

ROOT = Path(__file__).resolve().parents[2]
FIGURES = ROOT / "docs" / "figures"
KEY, OTHER_KEY = KEYS

#: A small smoky room: one luminaire, two receivers (CIR and order split by default), a desk, smoke in a box.
CIR_DOC = {
    "name": "smoky office (web test)",
    "room": {"size": [5.0, 4.0, 3.0], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": 0.7}},
    "furniture": [{"name": "desk", "min": [0.6, 0.6, 0.0], "max": [1.8, 1.4, 0.75], "reflectance": 0.5}],
    "transmitters": [
        {"id": "lamp", "position": [2.5, 2.0, 3.0], "normal": [0, 0, -1], "lambertian_order": 1},
        {"id": "wall-lamp", "position": [0.0, 2.0, 2.0], "normal": [1, 0, 0], "lambertian_order": 2},
    ],
    "receivers": [
        {"id": "desk-rx", "position": [1.2, 1.0, 0.75], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 85},
        {"id": "wall-rx", "position": [5.0, 2.0, 1.2], "normal": [-1, 0, 0], "area": 1e-4, "fov_deg": 85},
    ],
    "medium": {
        "type": "homogeneous",
        "sigma_a": 0.02,
        "sigma_s": 0.1,
        "phase": {"type": "hg", "g": 0.5},
        "region": {"type": "box", "min": [0.0, 0.0, 2.0], "max": [5.0, 4.0, 3.0]},
    },
    "simulation": {
        "algorithm": 5,
        "max_reflections": 2,
        "max_scattering": 2,
        "time_bin_s": 1e-9,
        "t_max_s": 4e-8,
        "paths": 3000,
        "seed": 3,
    },
}


def map_doc(n: int = 6, paths: int = 300) -> dict:
    """Two lamps with a luminous flux, an n x n work-plane grid with a task area (U0), one explicit receiver with
    a link budget (SNR, BER)."""
    lamp = {"normal": [0, 0, -1], "half_power_semi_angle_deg": 60, "power": 10.0}
    return {
        "name": "lit office map (web test)",
        "room": {"size": [5.0, 5.0, 3.0], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": 0.8}},
        "transmitters": [
            {"id": "led1", "position": [1.5, 2.5, 3.0], "luminous_output": {"luminous_flux": 3000.0}, **lamp},
            {"id": "led2", "position": [3.5, 2.5, 3.0], "luminous_output": {"luminous_flux": 3000.0}, **lamp},
        ],
        "transmitter_groups": [{"name": "ceiling", "transmitters": ["led1", "led2"]}],
        "receivers": [{"id": "desk", "position": [2.5, 1.0, 0.85], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 85}],
        "receiver_grids": [
            {
                "id_prefix": "plane",
                "origin": [0.5, 0.5, 0.85],
                "size": [4.0, 4.0],
                "shape": [n, n],
                "area": 1e-4,
                "fov_deg": 85,
            }
        ],
        "lighting": {
            "task_areas": [{"name": "desk area", "grid": "plane", "min": [1.0, 1.0, 0.85], "max": [4.0, 4.0, 0.85]}]
        },
        "link_budget": {"responsivity": 0.5, "bit_rate": 1e7},
        "simulation": {"max_reflections": 1, "paths": paths, "seed": 2, "time_bin_s": 1e-9, "t_max_s": 4e-8},
    }


def _auth(key: str = KEY) -> dict:
    return {"Authorization": f"Bearer {key}"}


def run_job(base: str, doc: dict, key: str = KEY, timeout: float = 120.0) -> tuple[dict, dict]:
    """Submit `doc`, wait for it, return (job, result) as the API gives them."""
    r = httpx.post(f"{base}/v1/jobs", json=doc, headers=_auth(key), timeout=60)
    assert r.status_code == 202, r.text
    job = r.json()
    deadline = time.monotonic() + timeout
    while job["status"] not in ("succeeded", "failed", "cancelled"):
        assert time.monotonic() < deadline, job
        time.sleep(0.2)
        job = httpx.get(f"{base}{job['url']}", headers=_auth(key)).json()
    assert job["status"] == "succeeded", job
    result = httpx.get(f"{base}{job['urls']['result']}", headers=_auth(key), timeout=60).json()
    return job, result


@pytest.fixture(scope="module")
def cir_job(web_server):
    return run_job(web_server.url, CIR_DOC)


@pytest.fixture(scope="module")
def map_job(web_server):
    return run_job(web_server.url, map_doc())


def open_result(page, base: str, job_id: str, key: str = KEY) -> None:
    """Open the job's page, type the API key into its prompt, wait until the page says it has drawn."""
    page.set_viewport_size({"width": 1200, "height": 900})
    page.goto(f"{base}/ui/jobs/{job_id}")
    type_key(page, key)
    page.wait_for_selector("body[data-state=plotted], body[data-state=error]", timeout=30_000)


def type_key(page, key: str) -> None:
    """Type the API key into the prompt the page shows on 401: the pages' shared key box (server/web/static/
    shell.js) when the server has it, else the result page's own."""
    prompt = page.locator("#api-key:visible, #result-key-input:visible")
    prompt.wait_for()
    prompt.fill(key)
    prompt.press("Enter")


def floats(values) -> list[float | None]:
    """data-value strings as numbers (empty: None)."""
    return [float(v) if v not in ("", None) else None for v in values]


def printed_matches(text: str, value: float, digits: int = 4) -> bool:
    """The printed number (before any ±) equals `value` to its printed significant digits."""
    shown = float(text.split("±")[0].strip())
    if value == 0:
        return shown == 0
    unit = 10 ** (math.floor(math.log10(abs(value))) - digits + 1)
    return abs(shown - value) <= 0.5 * unit * (1 + 1e-9)


def test_metrics_table_shows_the_apis_figures(page, web_server, cir_job):
    job, result = cir_job
    open_result(page, web_server.url, job["id"])
    rows = page.locator("#links-table tbody tr")
    assert rows.count() == len(result["links"]) == 4
    for k, link in enumerate(result["links"]):
        row = page.locator(f"#links-table tbody tr[data-index='{k}']")
        assert row.locator("th").inner_text() == f"{link['transmitter']} → {link['receiver']}"
        for field, se in (("dc_gain", "dc_gain_stderr"), ("rms_delay_spread_s", "rms_delay_spread_s_stderr")):
            cell = row.locator(f"td[data-field={field}]")
            assert float(cell.get_attribute("data-value")) == link[field]
            assert float(cell.get_attribute("data-stderr")) == link[se]
        gain = row.locator("td[data-field=dc_gain]").inner_text()
        assert printed_matches(gain, link["dc_gain"]), (gain, link["dc_gain"])
        assert printed_matches(gain.split("±")[1], link["dc_gain_stderr"], digits=2)
        loss = row.locator("td[data-field=path_loss_db]").inner_text()
        assert printed_matches(loss, link["path_loss_db"])
        tau = row.locator("td[data-field=rms_delay_spread_s]").inner_text()  # shown in ns
        assert printed_matches(tau, link["rms_delay_spread_s"] * 1e9)
    page.screenshot(path=str(FIGURES / "web-result.png"), full_page=True)


def test_cir_points_equal_the_apis_cir(page, web_server, cir_job):
    job, result = cir_job
    open_result(page, web_server.url, job["id"])
    options = page.locator("#curve-source option")
    assert options.count() == len(result["links"])
    for k, link in enumerate(result["links"]):
        page.select_option("#curve-source", f"link:{k}")
        pts = page.locator("#cir-plot .total-points .pt")
        values = floats(pts.evaluate_all("els => els.map(e => e.dataset.value)"))
        stderr = floats(pts.evaluate_all("els => els.map(e => e.dataset.stderr)"))
        assert values == link["cir"]["total"]
        assert stderr == link["cir"]["total_stderr"]
        assert len(values) == result["time_bins"]["n_bins"]
        line = page.locator("#cir-plot polyline.total").get_attribute("data-values")
        assert floats(line.split(",")) == link["cir"]["total"]
        for order, row in enumerate(link["cir"]["by_reflection_order"]):
            if any(v > 0 for v in row):
                drawn = page.locator(f"#cir-plot polyline[data-label='k = {order}']").get_attribute("data-values")
                assert floats(drawn.split(",")) == row
    # the band: +-1 standard error drawn around h = total / dt. On a linear scale, at every bin with an error the
    # band's upper and lower edges sit the same distance above and below the point, in proportion to the error.
    page.uncheck("#cir-log")
    link = result["links"][0]
    page.select_option("#curve-source", "link:0")
    band = page.locator("#cir-plot polygon.band")
    assert band.count() == 1
    pts = [tuple(map(float, p.split(","))) for p in band.get_attribute("points").split()]
    n = len(pts) // 2
    upper, lower = pts[:n], pts[n:][::-1]
    cx_cy = page.locator("#cir-plot .total-points .pt").evaluate_all(
        "els => els.map(e => [+e.getAttribute('cx'), +e.getAttribute('cy')])"
    )
    with_err = [k for k, e in enumerate(link["cir"]["total_stderr"]) if e is not None]
    assert len(with_err) == n
    span = []
    for (x_hi, y_hi), (x_lo, y_lo), k in zip(upper, lower, with_err):
        cx, cy = cx_cy[k]
        assert x_hi == x_lo == cx
        assert y_hi - 0.02 <= cy <= y_lo + 0.02 and abs((y_lo - cy) - (cy - y_hi)) <= 0.03
        span.append((y_lo - y_hi, link["cir"]["total_stderr"][k]))
    # the y axis's pixels per unit of h from two points, and the band's height 2 stderr / dt on it
    total, dt = link["cir"]["total"], result["time_bins"]["time_bin_s"]
    a, b = total.index(max(total)), total.index(min(total))
    scale = (cx_cy[b][1] - cx_cy[a][1]) / ((total[a] - total[b]) / dt)
    for px, err in span:
        assert px == pytest.approx(2 * err / dt * scale, abs=0.05)


def test_order_bars_equal_the_apis_order_split(page, web_server, cir_job):
    job, result = cir_job
    open_result(page, web_server.url, job["id"])
    for k, link in enumerate(result["links"]):
        page.select_option("#curve-source", f"link:{k}")
        for kind in ("reflection", "scattering"):
            bars = page.locator(f"#orders-plot .{kind}-bar")
            assert floats(bars.evaluate_all("els => els.map(e => e.dataset.value)")) == link[f"dc_gain_by_{kind}_order"]
            assert (
                floats(bars.evaluate_all("els => els.map(e => e.dataset.stderr)"))
                == link[f"dc_gain_by_{kind}_order_stderr"]
            )
    assert len(result["links"][0]["dc_gain_by_scattering_order"]) == 3  # S = 2: orders 0, 1, 2 drawn


def test_map_hover_shows_the_apis_value_and_u0(page, web_server, map_job):
    job, result = map_job
    open_result(page, web_server.url, job["id"])
    m = result["maps"][0]
    assert page.locator("#map-select option").count() == len(result["maps"])
    assert page.input_value("#quantity-select") == "illuminance_lx"
    q = "illuminance_lx"
    cells = page.locator("#map-plot rect.cell")
    nu, nv = m["shape"]
    assert cells.count() == nu * nv
    drawn = cells.evaluate_all("els => els.map(e => [+e.dataset.i, +e.dataset.j, e.dataset.value])")
    for i, j, v in drawn:
        assert (float(v) if v else None) == m["values"][q][i][j]
    for i, j in ((0, 0), (nu - 1, 0), (2, 3), (nu - 1, nv - 1)):
        page.locator(f"#map-plot rect.cell[data-i='{i}'][data-j='{j}']").hover()  # scrolled into view, its centre
        out = page.locator("#map-plot .map-readout")
        assert (out.get_attribute("data-i"), out.get_attribute("data-j")) == (str(i), str(j))
        assert float(out.get_attribute("data-value")) == m["values"][q][i][j]
        shown = out.inner_text().split("=")[-1].replace("lx", "")
        assert printed_matches(shown, m["values"][q][i][j]), (shown, m["values"][q][i][j])
    # U0 of the task area, as the result's lighting section gives it
    area = next(a for a in result["lighting"]["areas"] if a["grid"] == m["grid"] and a["channel"] == m["channel"])
    u0 = page.locator("#u0-table tr[data-part=task] .u0-value")
    assert float(u0.get_attribute("data-value")) == area["task"]["uniformity_u0"]
    assert printed_matches(u0.inner_text(), area["task"]["uniformity_u0"], digits=3)
    # the metrics table: only the explicit receiver's links, with SNR and BER (a link budget is given)
    table = page.locator("#links-table")
    assert table.locator("tbody tr").count() == 2
    for field in ("snr_db", "ber"):
        cells = table.locator(f"td[data-field={field}]")
        assert floats(cells.evaluate_all("els => els.map(e => e.dataset.value)")) == [
            lk[field] for lk in result["links"] if lk["receiver"] == "desk"
        ]
    # another quantity
    page.select_option("#quantity-select", "dc_gain")
    values = page.locator("#map-plot rect.cell").evaluate_all("els => els.map(e => e.dataset.value)")
    assert floats(values) == [m["values"]["dc_gain"][i][j] for i in range(nu) for j in range(nv)]
    page.select_option("#quantity-select", "illuminance_lx")
    page.locator("#map-plot rect.cell[data-i='2'][data-j='3']").hover()
    page.locator("#maps").screenshot(path=str(FIGURES / "web-map.png"))


def test_downloads_offer_every_format_and_answer(page, web_server, cir_job):
    job, _ = cir_job
    open_result(page, web_server.url, job["id"])
    links = page.locator("#downloads a.download")
    keys = links.evaluate_all("els => els.map(e => e.dataset.key)")
    assert set(keys) == (set(job["urls"]) - {"self", "cancel"}) | {"scene"}
    for k in range(links.count()):
        a = links.nth(k)
        href = a.get_attribute("data-href")
        assert httpx.get(f"{web_server.url}{href}", headers=_auth(), timeout=60).status_code == 200
        with page.expect_download() as info:
            a.click()
        download = info.value
        assert download.failure() is None
        path = download.path()
        assert path is not None and Path(path).stat().st_size > 0
        if a.get_attribute("data-key") == "result":
            assert json.loads(Path(path).read_text())["links"][0]["dc_gain"] is not None


def test_preview_draws_every_device(page, web_server, cir_job):
    job, result = cir_job
    open_result(page, web_server.url, job["id"])
    scene = result["scene"]
    for view in ("top", "side", "3d"):
        svg = page.locator(f"#preview svg[data-view='{view}']")
        assert svg.locator(".luminaire").count() == len(scene["transmitters"]) == 2
        assert svg.locator(".receiver").count() == len(scene["receivers"]) == 2
        ids = svg.locator(".luminaire, .receiver").evaluate_all("els => els.map(e => e.dataset.id)")
        assert sorted(ids) == sorted([t["id"] for t in scene["transmitters"]] + [r["id"] for r in scene["receivers"]])
        assert svg.locator(".room").count() == 1
        assert svg.locator(".furniture").count() == 1
        assert svg.locator(".smoke").count() == 1
    # the lamp faces down: from the side an arrow, from above a cross (its normal points away from the viewer)
    side = page.locator("#preview svg[data-view=side] .luminaire[data-id=lamp] line.normal")
    assert side.count() == 1
    y1, y2 = float(side.get_attribute("y1")), float(side.get_attribute("y2"))
    assert y2 > y1  # down on the screen
    assert page.locator("#preview svg[data-view=top] .luminaire[data-id=lamp] .normal.away").count() == 1
    # the wall lamp faces +x: an arrow to the right in both views
    for view in ("top", "side"):
        arrow = page.locator(f"#preview svg[data-view='{view}'] .luminaire[data-id=wall-lamp] line.normal")
        assert float(arrow.get_attribute("x2")) > float(arrow.get_attribute("x1"))
    page.locator("#preview").screenshot(path=str(FIGURES / "web-preview.png"))
    # the 3D view turns when dragged, and still draws every device
    lamp = page.locator("#preview svg[data-view='3d'] .luminaire[data-id=lamp] circle")
    before = (lamp.get_attribute("cx"), lamp.get_attribute("cy"))
    page.locator("#preview .view3d-box").scroll_into_view_if_needed()
    box = page.locator("#preview .view3d-box").bounding_box()
    page.mouse.move(box["x"] + 100, box["y"] + 100)
    page.mouse.down()
    page.mouse.move(box["x"] + 160, box["y"] + 120, steps=4)
    page.mouse.up()
    assert (lamp.get_attribute("cx"), lamp.get_attribute("cy")) != before
    assert page.locator("#preview svg[data-view='3d'] .luminaire, #preview svg[data-view='3d'] .receiver").count() == 4


def test_preview_of_a_map_draws_its_plane(page, web_server, map_job):
    job, result = map_job
    open_result(page, web_server.url, job["id"])
    top = page.locator("#preview svg[data-view=top]")
    assert top.locator(".map-plane[data-grid=plane]").count() == 1
    assert top.locator(".luminaire").count() == 2
    assert top.locator(".receiver").count() == 1  # the grid's points are the plane, not devices
    assert top.locator(".task-area").count() == 1


#: A hand-made timeline (the shape the timeline branch's result carries: times_s, links[] with dc_gain, its
#: stderr and outages).
TIMELINE = {
    "times_s": [0.0, 10.0, 20.0, 30.0, 40.0, 50.0],
    "method": "independent",
    "links": [
        {
            "tx": "lamp",
            "rx": "walker",
            "dc_gain": [1.0e-5, 9.0e-6, 4.0e-6, 1.5e-6, 8.0e-7, 2.0e-6],
            "dc_gain_stderr": [1e-7, 1e-7, 2e-7, 3e-7, 1e-7, 2e-7],
            "outages": [
                {"start_s": 24.0, "end_s": 33.0, "uncertain": True},
                {"start_s": 33.0, "end_s": 47.5, "uncertain": False},
            ],
            "time_to_first_outage_s": 24.0,
        },
        {
            "tx": "lamp",
            "rx": "door",
            "dc_gain": [2e-6, 2e-6, 2e-6, 2e-6, 2e-6, 2e-6],
            "dc_gain_stderr": [1e-8] * 6,
            "outages": [],
            "time_to_first_outage_s": None,
        },
    ],
}


def test_timeline_renders_from_an_injected_result(page, web_server, cir_job):
    job, result = cir_job
    open_result(page, web_server.url, job["id"])
    assert page.locator("#timeline").is_hidden()  # this result has no timeline
    page.evaluate(
        "async t => (await import('/ui/static/result.js')).renderTimeline(document.querySelector('#timeline'), t)",
        TIMELINE,
    )
    assert page.locator("#timeline").is_visible()
    assert page.locator("#timeline-link option").count() == 2
    link = TIMELINE["links"][0]
    pts = page.locator("#timeline-plot .pt")
    assert floats(pts.evaluate_all("els => els.map(e => e.dataset.value)")) == link["dc_gain"]
    assert floats(pts.evaluate_all("els => els.map(e => e.dataset.stderr)")) == link["dc_gain_stderr"]
    assert floats(pts.evaluate_all("els => els.map(e => e.dataset.x)")) == TIMELINE["times_s"]
    bands = page.locator("#timeline-plot rect.outage")
    got = bands.evaluate_all("els => els.map(e => [+e.dataset.start, +e.dataset.end, e.dataset.uncertain])")
    assert got == [[o["start_s"], o["end_s"], "true" if o["uncertain"] else "false"] for o in link["outages"]]
    assert page.locator("#timeline-plot rect.outage.uncertain").count() == 1
    # an outage band spans its interval on the time axis: x of 24 s and 33 s on a 0..50 s axis
    first = bands.nth(0).bounding_box()
    second = bands.nth(1).bounding_box()
    assert first["x"] < second["x"] and abs(first["x"] + first["width"] - second["x"]) < 1.5
    assert first["width"] == pytest.approx(second["width"] * 9.0 / 14.5, rel=0.03)
    page.select_option("#timeline-link", "1")
    assert floats(page.locator("#timeline-plot .pt").evaluate_all("els => els.map(e => e.dataset.value)")) == [2e-6] * 6
    assert page.locator("#timeline-plot rect.outage").count() == 0


def test_another_tenants_job_is_not_shown(page, web_server, cir_job):
    job, _ = cir_job
    open_result(page, web_server.url, job["id"], key=OTHER_KEY)
    assert page.get_attribute("body", "data-state") == "error"
    assert "no job" in page.inner_text("#message")
    assert page.locator("#metrics").is_hidden() and page.locator("#preview").is_hidden()


def test_scene_route_returns_the_jobs_document(web_server, cir_job):
    job, result = cir_job
    url = f"{web_server.url}{job['url']}/scene"
    r = httpx.get(url, headers=_auth())
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/json")
    scene = r.json()
    assert scene["transmitters"] == result["scene"]["transmitters"]
    assert scene["medium"] == result["scene"]["medium"] and scene["furniture"] == result["scene"]["furniture"]
    other = httpx.get(url, headers=_auth(OTHER_KEY))
    assert other.status_code == 404 and other.headers["content-type"] == "application/problem+json"
    assert httpx.get(url).status_code == 401


def test_a_running_job_shows_its_preview_then_its_result(page, web_server):
    """Before a result exists the page polls the job and draws the scene from GET /v1/jobs/{id}/scene; once the
    job stops (here cancelled, keeping its partial result) the result is drawn."""
    doc = {**CIR_DOC, "name": "long job (web test)", "simulation": {**CIR_DOC["simulation"], "paths": 200_000_000}}
    doc["simulation"]["batch_size"] = 4096
    r = httpx.post(f"{web_server.url}/v1/jobs", json=doc, headers=_auth(), timeout=60)
    assert r.status_code == 202, r.text
    job = r.json()
    try:
        page.set_viewport_size({"width": 1200, "height": 900})
        page.goto(f"{web_server.url}/ui/jobs/{job['id']}")
        type_key(page, KEY)
        page.wait_for_selector("#preview:not([hidden])", timeout=30_000)
        page.wait_for_selector("#job-status[data-status=running]", timeout=30_000)
        assert page.get_attribute("body", "data-state") == "loading"
        assert page.locator("#preview svg[data-view=top] .luminaire").count() == 2
        assert page.locator("#metrics").is_hidden()
    finally:
        httpx.post(f"{web_server.url}{job['urls']['cancel']}", headers=_auth(), timeout=30)
    page.wait_for_selector("body[data-state=plotted]", timeout=60_000)
    assert page.get_attribute("#job-status", "data-status") == "cancelled"
    status = httpx.get(f"{web_server.url}{job['urls']['result']}", headers=_auth(), timeout=60).status_code
    if status == 200:  # stopped with a partial result: drawn
        assert page.locator("#links-table tbody tr").count() == 4
    else:
        assert status == 409 and "no result" in page.inner_text("#message")


#: A scene document with what the two jobs above lack: a grid medium, inline and file meshes, an angle-diversity
#: receiver, a wall grid (drawn by preview.js as given; the page draws any document the API returns).
HAND_MADE_SCENE = {
    "room": {"size": [6.0, 4.0, 3.0], "origin": [1.0, 0.0, 0.0]},
    "meshes": [
        {"name": "shelf", "vertices": [[2, 1, 0], [3, 1, 0], [3, 1.5, 2], [2, 1.5, 2]], "faces": [[0, 1, 2]]},
        {"name": "chair", "file": "chair.obj"},
    ],
    "transmitters": [{"id": "t", "position": [4, 2, 3], "normal": [0, 0, -1]}],
    "receivers": [],
    "angle_diversity_receivers": [{"id": "adr", "position": [2.5, 2, 1.0], "normal": [0, 0, 1]}],
    "receiver_grids": [
        {"id_prefix": "wall", "origin": [7.0, 0.5, 0.5], "u": [0, 1, 0], "v": [0, 0, 1], "size": [3, 2]}
    ],
    "medium": {"type": "grid", "min": [1.0, 0.0, 2.0], "max": [7.0, 4.0, 3.0], "shape": [2, 2, 2]},
}


def test_preview_draws_meshes_grid_media_and_wall_grids(page, web_server, cir_job):
    job, _ = cir_job
    open_result(page, web_server.url, job["id"])
    note = page.evaluate(
        """async scene => {
             const m = await import('/ui/static/preview.js');
             const div = document.createElement('div');
             div.id = 'hand-made';
             document.body.appendChild(div);
             m.drawPreview(div, scene);
             return div.querySelector('.preview-counts').textContent;
           }""",
        HAND_MADE_SCENE,
    )
    assert "chair" in note and "grid medium" in note
    top = page.locator("#hand-made svg[data-view='top']")
    side = page.locator("#hand-made svg[data-view='side']")
    assert top.locator(".receiver.adr[data-id=adr]").count() == 1
    assert top.locator(".mesh").count() == 1  # the file mesh is listed, not drawn
    # the inline mesh's bounding box x 2..3 m, y 1..1.5 m, z 0..2 m; the smoke box z 2..3 m, the room's x 1..7 m
    room = top.locator(".room").bounding_box()
    shelf, smoke = top.locator(".mesh").bounding_box(), side.locator(".smoke").bounding_box()
    px_per_m = room["width"] / 6.0
    assert shelf["width"] == pytest.approx(1.0 * px_per_m, abs=1.5)
    assert shelf["height"] == pytest.approx(0.5 * px_per_m, abs=1.5)
    assert shelf["x"] - room["x"] == pytest.approx(1.0 * px_per_m, abs=1.5)
    side_room = side.locator(".room").bounding_box()
    assert smoke["height"] == pytest.approx(side_room["height"] / 3.0, abs=1.5) and smoke["y"] == pytest.approx(
        side_room["y"], abs=1.5
    )
    # the wall grid (the plane x = 7 m, 3 m along y, 2 m along z) is seen edge-on in both views: a line (its stroke)
    plane = top.locator(".map-plane[data-grid=wall]").bounding_box()
    assert plane["width"] <= 5 and plane["height"] == pytest.approx(3.0 * px_per_m, abs=5)
    plane = side.locator(".map-plane[data-grid=wall]").bounding_box()
    assert plane["width"] <= 5 and plane["height"] == pytest.approx(2.0 * px_per_m, abs=5)


def test_a_timeline_results_files_are_offered_for_download(page, web_server, cir_job):
    """A result with a timeline: the page lists the files GET {job}/timeline names (the timeline branch's route;
    answered here by the test) beside the job's own, and downloads them with the key."""
    job, result = cir_job
    open_result(page, web_server.url, job["id"])
    base = f"{web_server.url}{job['url']}"
    files = {name: f"{job['url']}/{name}" for name in ("timeline.csv", "timeline.nc", "timeline.svg")}
    seen: list[str | None] = []

    def listing(route):
        seen.append(route.request.headers.get("authorization"))
        route.fulfill(json={"files": files})

    page.route(f"{base}/timeline", listing)
    page.route(f"{base}/timeline.nc", lambda route: route.fulfill(body=b"CDF\x01 netcdf bytes", status=200))
    page.evaluate(
        "async ([r, j]) => (await import('/ui/static/result.js')).renderResult(r, j)",
        [{**result, "timeline": TIMELINE}, job],
    )
    keys = page.locator("#downloads a.download").evaluate_all("els => els.map(e => e.dataset.key)")
    assert set(keys) == (set(job["urls"]) - {"self", "cancel"}) | {"scene"} | set(files)
    assert seen == [f"Bearer {KEY}"]
    with page.expect_download() as info:
        page.click("#downloads a.download[data-key='timeline.nc']")
    assert Path(info.value.path()).read_bytes() == b"CDF\x01 netcdf bytes"
    assert page.locator("#timeline-plot .pt").count() == len(TIMELINE["times_s"])
