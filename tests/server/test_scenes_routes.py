"""The endpoints the web pages use (server/routes/scenes.py): examples, pre-flight without a job, delete."""

import json

import pytest

from owcsim.schemas import SceneSpec
from owcsim.server.routes.scenes import EXAMPLES

from .helpers import app_client, quick_doc, wait_for
from .test_api import locs, problem


def test_examples_are_valid_documents_the_service_accepts(api):
    items = api.get("/v1/examples").json()["items"]
    assert [e["id"] for e in items] == list(EXAMPLES)
    for e in items:
        SceneSpec.model_validate(e["document"])
        assert e["name"] == e["document"]["name"]
        r = api.post("/v1/preflight", json=e["document"])
        assert r.status_code == 200, r.text


def test_preflight_estimates_without_queueing_and_matches_the_submission(api):
    doc = quick_doc(paths=3000)
    est = api.post("/v1/preflight", json=doc).json()
    assert api.get("/v1/jobs").json()["items"] == []  # nothing stored
    job = api.post("/v1/jobs", json=doc).json()
    row = api.app.state.store.get(job["id"])
    assert est["memory_bytes"] == row.memory_bytes > 0  # the estimate the server's limits use
    assert est["triangles"] == 12 and est["receivers"] == 1
    assert est["paths"] == 3000  # backward: one source device, the receiver
    assert est["time_s"] is None and "unknown" in est["time_basis"]  # no job has finished here yet
    assert est["modeled"]["max_reflections"] == "K = 1 (given)"
    auto = api.post("/v1/preflight", json=quick_doc(max_reflections=None, t_max_s=None)).json()
    assert "pilot" in auto["modeled"]["max_reflections"] and "pilot" in auto["modeled"]["time_window"]


def test_preflight_refuses_what_a_submission_refuses(api):
    bad = quick_doc()
    bad["receivers"][0]["fov_deg"] = 200
    for body in (json.dumps(bad), '{"room": '):
        pre, sub = api.post("/v1/preflight", content=body), api.post("/v1/jobs", content=body)
        assert pre.status_code == sub.status_code in (400, 422)
        assert problem(pre, pre.status_code)["errors"] == problem(sub, sub.status_code)["errors"]
    assert locs(api.post("/v1/preflight", json=bad).json()) == {"body.receivers.0.fov_deg"}
    with app_client(api.app.state.settings.db.parent / "limits", max_paths_per_job=100) as small:
        r = small.post("/v1/preflight", json=quick_doc(paths=2000))
        assert locs(problem(r, 422, "limit-exceeded")) == {"body.simulation.paths"}


def test_preflight_time_is_the_callers_measured_rate(live):
    job = live.post("/v1/jobs", json=quick_doc(paths=4000)).json()
    done = wait_for(live, job["id"], "succeeded")
    rate = done["progress"]["paths"] / done["progress"]["elapsed_s"]
    est = live.post("/v1/preflight", json=quick_doc(paths=40_000)).json()
    assert est["time_s"] == pytest.approx(40_000 / rate, rel=1e-9)
    assert "paths/s" in est["time_basis"]
    budget = live.post("/v1/preflight", json=quick_doc(paths=None, target_rel_error=0.05, time_budget_s=7)).json()
    assert budget["paths"] is None and budget["time_s"] == 7


def test_delete_a_finished_job_only(api):
    job = api.post("/v1/jobs", json=quick_doc()).json()
    problem(api.delete(job["url"]), 409, "job-not-finished")  # queued: cancel it first
    assert api.get(job["url"]).status_code == 200
    api.post(f"{job['url']}/cancel")
    r = api.delete(job["url"])
    assert r.status_code == 204 and r.content == b""
    problem(api.get(job["url"]), 404, "job-not-found")
    problem(api.delete(job["url"]), 404, "job-not-found")
    assert api.app.state.store.result_json(job["id"]) is None


def test_a_key_deletes_and_preflights_only_as_itself(tmp_path):
    with app_client(tmp_path, api_keys="key-a,key-b") as c:
        a, b = ({"Authorization": f"Bearer {k}"} for k in ("key-a", "key-b"))
        problem(c.post("/v1/preflight", json=quick_doc()), 401, "unauthorized")
        assert c.get("/v1/examples").status_code == 200  # open, like /v1/version
        job = c.post("/v1/jobs", json=quick_doc(), headers=a).json()
        c.post(f"{job['url']}/cancel", headers=a)
        problem(c.delete(job["url"], headers=b), 404, "job-not-found")
        assert c.get(job["url"], headers=a).status_code == 200
        assert c.delete(job["url"], headers=a).status_code == 204


def test_a_jobs_scene_is_streamed_a_piece_at_a_time(api):
    """GET /v1/jobs/{id}/scene sends the stored document decompressed in pieces of at most 1 MiB, never whole
    (before: read whole once per request; 20 requests at once for a 90,000-receiver scene, 18 MB, took a real
    server from 136 to 655 MB); the bytes are the canonical document, and a deleted job's is 404."""
    import tracemalloc

    from owcsim.server.job_rows import pack

    doc = quick_doc(paths=1)
    rx = doc["receivers"][0]
    doc["receivers"] = [dict(rx, id=f"r{i}") for i in range(60_000)]
    job = api.post("/v1/jobs", json=doc).json()
    store = api.app.state.store
    whole = store.scene_json(job["id"]).encode()
    packed = len(pack(whole))
    assert len(whole) > 10 << 20
    r = api.get(f"/v1/jobs/{job['id']}/scene")
    assert r.status_code == 200 and r.content == whole and r.headers["content-type"] == "application/json"
    assert "content-length" not in r.headers  # streamed
    tracemalloc.start()
    pieces = 0
    for piece in store.scene_chunks(job["id"]):
        assert len(piece) <= 1 << 20
        pieces += 1
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    # the stored (compressed) bytes and a few pieces (measured: 3.5 MB for 0.19 MB stored, 12 MB whole); whole: 12+
    assert pieces >= 10 and peak < packed + (4 << 20) < len(whole) / 2, (pieces, peak, packed, len(whole))
    assert store.scene_chunks("0" * 32) is None
