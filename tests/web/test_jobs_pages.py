"""The jobs list and the submit page in headless Chromium (issue 27, items 1, 2, 5): the key prompt, an example
submitted through the page and watched to the end with its progress, a validation error next to the line of the
field it names, cancel and delete, and another tenant's job out of reach. The tests write the docs' screenshots
(docs/figures/web-jobs.png, web-submit.png, web-submit-error.png; docs/web.md)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.server.helpers import long_doc, quick_doc
from tests.web.conftest import KEYS

#: pytest-base-url (a dependency of pytest-playwright) defines `base_url` in a way pytest 9 warns about; not ours.
pytestmark = pytest.mark.filterwarnings("ignore:Session-scoped fixtures defined as instance methods")

FIGURES = Path(__file__).resolve().parents[2] / "docs" / "figures"
KEY_A, KEY_B = KEYS
#: Browser waits [ms]: generous for a 2-core machine shared with other work.
WAIT_MS = 20_000


def auth(key: str) -> dict:
    return {"Authorization": f"Bearer {key}"}


def submit_api(server, doc: dict, key: str) -> dict:
    r = httpx.post(f"{server.url}/v1/jobs", json=doc, headers=auth(key), timeout=60)
    assert r.status_code == 202, r.text
    return r.json()


def give_key(page: Page, key: str) -> None:
    """Type the key into the header's prompt (it opens on the first 401)."""
    expect(page.locator("#key-form")).to_be_visible(timeout=WAIT_MS)
    page.fill("#api-key", key)
    page.click("#key-form button[type=submit]")
    expect(page.locator("#key-status")).to_have_text("API key set")


def open_with_key(page: Page, server, path: str, key: str) -> None:
    page.goto(server.url + path)
    give_key(page, key)


def row(page: Page, job_id: str):
    return page.locator(f'#jobs tbody tr[data-job-id="{job_id}"]')


def test_the_pages_and_their_files_are_served_without_a_key(web_server):
    """The pages hold no data: they load without a key (the API behind them asks for one)."""
    for path in ("/", "/ui", "/ui/submit", "/ui/jobs/0123", "/ui/static/api.js", "/ui/static/base.css"):
        r = httpx.get(web_server.url + path, timeout=10)
        assert r.status_code == 200, path
    assert httpx.get(web_server.url + "/v1/jobs", timeout=10).status_code == 401
    assert httpx.get(web_server.url + "/ui/static/../pages.py", timeout=10).status_code == 404


def test_the_key_prompt_asks_once_and_keeps_the_key_for_the_tab(page: Page, web_server):
    page.goto(web_server.url + "/ui")
    expect(page.locator("#key-message")).to_have_text("This server needs an API key:", timeout=WAIT_MS)
    expect(page.locator("#jobs-error")).to_contain_text("API key")
    page.fill("#api-key", "not-a-key")
    page.click("#key-form button[type=submit]")
    expect(page.locator("#key-message")).to_have_text("This key is not valid on this server:", timeout=WAIT_MS)
    give_key(page, KEY_A)
    expect(page.locator("#jobs-error")).to_be_hidden(timeout=WAIT_MS)
    assert page.evaluate("sessionStorage.getItem('owcsim.apiKey')") == KEY_A
    page.goto(web_server.url + "/ui/submit")  # another page of the tab: no prompt, the key is sent
    expect(page.locator("#key-status")).to_have_text("API key set")
    expect(page.locator("#key-form")).to_be_hidden()
    page.click("#key-forget")
    assert page.evaluate("sessionStorage.getItem('owcsim.apiKey')") is None


def test_submit_an_example_and_watch_it_finish(page: Page, web_server):
    """Example -> pre-flight estimate -> submit -> the job's page; on the jobs list its progress rises to 100 %."""
    page.set_viewport_size({"width": 1200, "height": 900})
    open_with_key(page, web_server, "/ui/submit", KEY_A)
    examples = httpx.get(web_server.url + "/v1/examples", timeout=10).json()["items"]
    page.select_option("#example", "barry-config-a")
    expect(page.locator("#estimate")).to_be_visible(timeout=WAIT_MS)
    example = next(e["document"] for e in examples if e["id"] == "barry-config-a")
    assert json.loads(page.input_value("#doc")) == example
    expected = httpx.post(web_server.url + "/v1/preflight", json=example, headers=auth(KEY_A), timeout=60).json()
    assert page.locator("#est-memory").get_attribute("data-bytes") == str(expected["memory_bytes"])
    expect(page.locator('#est-modeled dd[data-key="max_reflections"]')).to_have_text(
        expected["modeled"]["max_reflections"]
    )
    page.screenshot(path=str(FIGURES / "web-submit.png"), full_page=True)
    # more paths (typed over the example), so that the list shows the job while it runs
    doc = {**example, "name": "watched", "simulation": {**example["simulation"], "paths": 3_000_000}}
    page.fill("#doc", json.dumps(doc, indent=2))
    expect(page.locator("#submit")).to_be_disabled()  # edited: not checked yet
    page.click("#check")
    expect(page.locator("#submit")).to_be_enabled(timeout=WAIT_MS)
    page.click("#submit")
    page.wait_for_url(re.compile(r"/ui/jobs/[0-9a-f]{32}$"), timeout=WAIT_MS)
    job_id = page.url.rsplit("/", 1)[1]

    page.goto(web_server.url + "/ui")
    tr = row(page, job_id)
    expect(tr).to_be_visible(timeout=WAIT_MS)
    page.evaluate(
        """id => { window.seen = [];
        const pct = document.querySelector(`tr[data-job-id="${id}"] .pct`);
        const note = () => window.seen.push(Number(pct.dataset.fraction));
        note(); new MutationObserver(note).observe(pct, {attributes: true, attributeFilter: ["data-fraction"]}); }""",
        job_id,
    )
    expect(tr).to_have_attribute("data-status", "succeeded", timeout=60_000)
    seen = page.evaluate("window.seen")
    assert any(0 < f < 1 for f in seen), f"no progress between 0 and 1 shown: {seen}"
    assert seen == sorted(seen) and seen[-1] == 1.0
    job = httpx.get(f"{web_server.url}/v1/jobs/{job_id}", headers=auth(KEY_A), timeout=10).json()
    assert job["status"] == "succeeded" and job["name"] == "watched"
    expect(tr.locator(".pct")).to_have_text("100 %")
    expect(tr.locator(".time")).to_have_text(re.compile(r"^\d+(\.\d+)? s$|min"))
    expect(tr.locator("a")).to_have_attribute("href", f"/ui/jobs/{job_id}")
    page.screenshot(path=str(FIGURES / "web-jobs.png"))


def fov_line(text: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if '"fov_deg"' in line)


def test_a_validation_error_is_shown_next_to_the_field_it_names(page: Page, web_server, tmp_path):
    page.set_viewport_size({"width": 1200, "height": 800})
    open_with_key(page, web_server, "/ui/submit", KEY_A)
    doc = quick_doc()
    doc["receivers"][0]["fov_deg"] = 200
    text = json.dumps(doc, indent=2)
    problem = httpx.post(web_server.url + "/v1/preflight", content=text, headers=auth(KEY_A), timeout=60).json()
    (error,) = problem["errors"]
    assert error["loc"] == "body.receivers.0.fov_deg"
    page.fill("#doc", text)
    page.click("#check")
    note = page.locator(f'.note-error[data-loc="{error["loc"]}"]')
    expect(note).to_be_visible(timeout=WAIT_MS)
    line = fov_line(text)
    assert note.get_attribute("data-line") == str(line)
    # the text `owcsim validate` prints for the same document
    scene = tmp_path / "scene.json"
    scene.write_text(text)
    cli = subprocess.run([sys.executable, "-m", "owcsim", "validate", str(scene)], capture_output=True, text=True)
    assert cli.returncode == 2
    cli_line = cli.stderr.splitlines()[-1].strip()
    assert error["msg"] in cli_line
    expect(note).to_have_text(cli_line)
    gutter_mark = page.locator(f"#gutter span:nth-child({line})")
    expect(gutter_mark).to_have_class("bad")
    expect(gutter_mark).to_have_text(str(line))
    # beside its line, in view: the note's top is the line's top in the (scrolled) editor
    box, editor = note.bounding_box(), page.locator("#doc").bounding_box()
    scrolled = page.eval_on_selector("#doc", "e => e.scrollTop")
    line_top = editor["y"] + 6 + (line - 1) * 18 - scrolled  # padding 6 px, line height 18 px (base.css)
    assert abs(box["y"] - line_top) < 2, (box, line_top)
    assert editor["y"] <= box["y"] and box["y"] + box["height"] <= editor["y"] + editor["height"]
    assert box["x"] >= editor["x"] + editor["width"] - 1  # right of the text
    mark = gutter_mark.bounding_box()
    assert abs(mark["y"] - box["y"]) < 2, (mark, box)  # the line's number is marked on the same row
    expect(page.locator("#errors li")).to_have_text(f"line {line}: {cli_line}")
    expect(page.locator("#submit")).to_be_disabled()
    expect(page.locator("#estimate")).to_be_hidden()
    page.screenshot(path=str(FIGURES / "web-submit-error.png"))

    # not JSON: the server's message names the line, the note goes there
    broken = text.replace('"paths": 2000', '"paths": 2000,,')
    page.fill("#doc", broken)
    page.click("#check")
    bad_line = next(i for i, s in enumerate(broken.splitlines(), 1) if ",," in s)
    expect(page.locator('.note-error[data-loc="body"]')).to_have_attribute("data-line", str(bad_line), timeout=WAIT_MS)

    # fixed: the errors go, the estimate comes, the job can be submitted
    page.fill("#doc", json.dumps(quick_doc(), indent=2))
    page.click("#check")
    expect(page.locator("#submit")).to_be_enabled(timeout=WAIT_MS)
    expect(page.locator(".note-error")).to_have_count(0)


def test_cancel_and_delete_from_the_list(page: Page, web_server):
    running = submit_api(web_server, {**long_doc(), "name": "to cancel"}, KEY_A)
    open_with_key(page, web_server, "/ui", KEY_A)
    tr = row(page, running["id"])
    expect(tr).to_have_attribute("data-status", re.compile("queued|running"), timeout=WAIT_MS)
    expect(tr.locator("button.delete")).to_be_hidden()  # a job is cancelled before it is deleted
    tr.locator("button.cancel").click()
    expect(tr).to_have_attribute("data-status", "cancelled", timeout=30_000)
    expect(tr.locator("button.cancel")).to_be_hidden()

    page.select_option("#state-filter", "cancelled")  # the filter keeps it, and hides the others
    expect(page.locator("#jobs tbody tr")).not_to_have_count(0, timeout=WAIT_MS)
    for status in page.locator("#jobs tbody tr").evaluate_all("rows => rows.map(r => r.dataset.status)"):
        assert status == "cancelled"
    page.select_option("#state-filter", "succeeded")
    expect(tr).to_be_hidden(timeout=WAIT_MS)
    page.select_option("#state-filter", "")

    tr = row(page, running["id"])
    tr.locator("button.delete").click()
    expect(tr.locator("button.delete")).to_have_text("Delete?")  # asked once more
    tr.locator("button.delete").click()
    expect(tr).to_have_count(0, timeout=WAIT_MS)
    r = httpx.get(f"{web_server.url}/v1/jobs/{running['id']}", headers=auth(KEY_A), timeout=10)
    assert r.status_code == 404


def test_another_tenants_job_is_out_of_reach(page: Page, web_server):
    theirs = submit_api(web_server, {**quick_doc(), "name": "tenant A's job"}, KEY_A)
    mine = submit_api(web_server, {**quick_doc(), "name": "tenant B's job"}, KEY_B)
    open_with_key(page, web_server, "/ui", KEY_B)
    expect(row(page, mine["id"])).to_be_visible(timeout=WAIT_MS)
    expect(row(page, theirs["id"])).to_have_count(0)
    expect(page.locator("#jobs")).not_to_contain_text("tenant A's job")

    # its address: whatever the page asks the API about the job is refused (404), nothing of it is shown
    answers: list[int] = []
    page.on("response", lambda r: theirs["id"] in r.url and "/v1/" in r.url and answers.append(r.status))
    page.goto(f"{web_server.url}/ui/jobs/{theirs['id']}")
    page.wait_for_load_state("networkidle")
    assert all(status == 404 for status in answers), answers
    expect(page.locator("body")).not_to_contain_text("tenant A's job")
    fetch = """async id => { const api = await import("/ui/static/api.js");
        try { return (await api.apiJson(`/v1/jobs/${id}`)).name; } catch (e) { return e.status; } }"""
    assert page.evaluate(fetch, theirs["id"]) == 404
    page.evaluate("k => sessionStorage.setItem('owcsim.apiKey', k)", KEY_A)  # the owner's key reaches it
    assert page.evaluate(fetch, theirs["id"]) == "tenant A's job"


@pytest.mark.parametrize("path", ["/ui", "/ui/submit"])
def test_the_pages_load_no_file_from_elsewhere(page: Page, web_server, path: str):
    """Offline: every request of the page goes to the server itself."""
    urls: list[str] = []
    page.on("request", lambda req: urls.append(req.url))
    page.goto(web_server.url + path)
    page.wait_for_load_state("networkidle")
    assert urls and all(u.startswith(web_server.url) for u in urls), urls


def test_playwright_leaves_the_other_tests_alone(pytestconfig):
    """pytest-playwright parametrizes by browser any test with a `page` parameter; outside tests/web it must not
    (tests/test_docs.py's `page` is a documentation page, its ids must stay "[README.md]"): conftest.py keeps the
    plugin's test generation to tests/web."""
    plugin = pytestconfig.pluginmanager.get_plugin("playwright")
    (generate,) = [i.function for i in pytestconfig.hook.pytest_generate_tests.get_hookimpls() if i.plugin is plugin]
    root = Path(__file__).resolve().parents[2]
    for test_file, expected in ((root / "tests" / "test_docs.py", []), (Path(__file__), ["browser_name"])):
        calls: list[str] = []
        metafunc = SimpleNamespace(
            fixturenames=["page"],
            definition=SimpleNamespace(path=test_file),
            config=pytestconfig,
            parametrize=lambda name, *args, calls=calls, **kwargs: calls.append(name),
        )
        generate(metafunc)
        assert calls == expected, test_file
