"""Every endpoint and every error answer, in-process (TestClient); jobs stay queued (no dispatcher)."""

import base64
import json

import pytest

from .helpers import app_client, quick_doc

PROBLEM = "application/problem+json"


def problem(r, status, kind=None):
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith(PROBLEM)
    body = r.json()
    assert body["status"] == status and body["title"] and "Traceback" not in r.text
    if kind:
        assert body["type"] == f"urn:owcsim:problem:{kind}"
    return body


def locs(body):
    return {e["loc"] for e in body["errors"]}


def test_submit_answers_202_with_the_job_and_its_url(api):
    r = api.post("/v1/jobs", json=quick_doc() | {"name": "room"})
    assert r.status_code == 202
    job = r.json()
    assert r.headers["location"] == job["url"] == f"/v1/jobs/{job['id']}"
    assert job["status"] == "queued" and job["name"] == "room" and job["progress"]["fraction"] == 0
    assert job["created_at"].endswith("Z") and job["started_at"] is None
    assert job["urls"]["result"] == f"{job['url']}/result"
    got = api.get(job["url"])
    assert got.status_code == 200 and got.json() == job


def test_health_version_and_openapi(api):
    h = api.get("/v1/health")
    assert h.status_code == 503  # no dispatcher in this app: it cannot run jobs
    assert h.json()["status"] == "unavailable" and h.json()["store"] is True
    assert api.get("/v1/version").json()["api_version"] == "v1"
    doc = api.get("/v1/openapi.json").json()
    assert doc["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]["application/json"]["schema"] == {
        "$ref": "#/components/schemas/SceneSpec"
    }
    assert "receivers" in doc["components"]["schemas"]["SceneSpec"]["properties"]
    ops = {(m.upper(), p) for p, item in doc["paths"].items() for m in item}
    assert ops == {
        ("POST", "/v1/jobs"),
        ("GET", "/v1/jobs"),
        ("GET", "/v1/jobs/{job_id}"),
        ("POST", "/v1/jobs/{job_id}/cancel"),
        ("GET", "/v1/jobs/{job_id}/result"),
        ("GET", "/v1/jobs/{job_id}/result.csv"),
        ("GET", "/v1/jobs/{job_id}/result.npz"),
        ("GET", "/v1/jobs/{job_id}/plot.png"),
        ("GET", "/v1/jobs/{job_id}/timeline"),
        ("GET", "/v1/jobs/{job_id}/timeline.csv"),
        ("GET", "/v1/jobs/{job_id}/timeline.nc"),
        ("GET", "/v1/jobs/{job_id}/timeline.svg"),
        ("GET", "/v1/jobs/{job_id}/scene"),
        ("GET", "/v1/health"),
        ("GET", "/v1/version"),
        ("GET", "/v1/examples"),  # the web pages' (routes/scenes.py)
        ("POST", "/v1/preflight"),
        ("DELETE", "/v1/jobs/{job_id}"),
    }
    post = doc["paths"]["/v1/jobs"]["post"]["responses"]
    assert post["422"]["content"] == {PROBLEM: {"schema": {"$ref": "#/components/schemas/Problem"}}}


def test_health_is_ok_with_the_dispatcher(live):
    body = live.get("/v1/health").json()
    assert body["status"] == "ok" and body["dispatcher"] and body["max_concurrent_jobs"] == 2


@pytest.mark.parametrize(
    "body,status,kind",
    [
        (b"{not json", 400, "malformed-json"),
        (b"\xff\xfe", 400, "malformed-json"),
        (b"[1, 2]", 422, "invalid-scene"),
        (b"", 400, "malformed-json"),
    ],
)
def test_malformed_bodies(api, body, status, kind):
    p = problem(api.post("/v1/jobs", content=body, headers={"content-type": "application/json"}), status, kind)
    assert locs(p) == {"body"}


def test_wrong_media_type_is_415(api):
    problem(
        api.post("/v1/jobs", content=b"a=1", headers={"content-type": "application/x-www-form-urlencoded"}),
        415,
        "unsupported-media-type",
    )


def test_invalid_fields_are_located(api):
    doc = quick_doc()
    doc["receivers"][0]["fov_deg"] = 120
    doc["room"]["reflectance"]["floor"] = 1.5
    doc["colour"] = "blue"
    p = problem(api.post("/v1/jobs", json=doc), 422, "invalid-scene")
    assert locs(p) == {"body.receivers.0.fov_deg", "body.room.reflectance.floor", "body.colour"}
    assert "body.receivers.0.fov_deg: Input should be less than or equal to 90" in p["detail"]


def test_document_level_rule_is_located_at_body(api):
    doc = quick_doc()
    doc["receivers"] = []
    p = problem(api.post("/v1/jobs", json=doc), 422, "invalid-scene")
    assert locs(p) == {"body"} and "no receiver" in p["detail"]


def test_mesh_paths_are_refused(api):
    doc = quick_doc()
    doc["meshes"] = [{"file": "/etc/passwd.obj", "reflectance": 0.5}]
    p = problem(api.post("/v1/jobs", json=doc), 422, "invalid-scene")
    assert locs(p) == {"body.meshes.0.file"} and "data_base64" in p["detail"]


def test_unreadable_base64_mesh_gets_the_engine_message(api):
    doc = quick_doc()
    doc["meshes"] = [{"data_base64": "*** not base64 ***", "format": "stl", "reflectance": 0.5}]
    p = problem(api.post("/v1/jobs", json=doc), 422, "scene-not-runnable")
    assert "meshes[0]: cannot read mesh" in p["detail"]
    doc["meshes"][0]["data_base64"] = base64.b64encode(b"solid nothing\nendsolid").decode()
    assert "meshes[0]" in problem(api.post("/v1/jobs", json=doc), 422, "scene-not-runnable")["detail"]


def test_inline_and_base64_meshes_are_accepted(api):
    obj = "v 1 1 1\nv 2 1 1\nv 1 2 1\nf 1 2 3\n"
    doc = quick_doc()
    doc["meshes"] = [
        {"vertices": [[1, 1, 1], [2, 1, 1], [1, 2, 1]], "faces": [[0, 1, 2]], "reflectance": 0.5},
        {"data_base64": base64.b64encode(obj.encode()).decode(), "format": "obj", "reflectance": 0.4},
    ]
    assert api.post("/v1/jobs", json=doc).status_code == 202


def test_engine_refusal_is_a_422_with_its_message(api, monkeypatch):
    import owcsim.engine.run.simulate
    from owcsim.engine.core.errors import SceneError

    def refuse(*a, **k):
        raise SceneError("algorithm 4 is not available in this version; use algorithm 1")

    monkeypatch.setattr(owcsim.engine.run.simulate, "simulate", refuse)
    # the pre-flight runs in its own process: here, in this one, so that the patch applies
    from owcsim.server import preflight as pf

    api.app.state.preflighter = lambda spec, text: pf.Preflight(pf.preflight(spec), 0)
    p = problem(api.post("/v1/jobs", json=quick_doc(algorithm=4)), 422, "scene-not-runnable")
    assert "algorithm 4 is not available" in p["detail"] and locs(p) == {"body"}
    assert api.get("/v1/jobs").json()["items"] == []


def test_body_size_limit_declared_and_streamed(tmp_path):
    with app_client(tmp_path, max_body_bytes=4096) as c:
        big = json.dumps(quick_doc() | {"description": "x" * 5000}).encode()
        p = problem(
            c.post("/v1/jobs", content=big, headers={"content-type": "application/json"}), 413, "body-too-large"
        )
        assert p["max_body_bytes"] == 4096

        def chunks():  # no Content-Length: counted while it streams
            for i in range(0, len(big), 1000):
                yield big[i : i + 1000]

        problem(c.post("/v1/jobs", content=chunks(), headers={"content-type": "application/json"}), 413)
        assert c.post("/v1/jobs", json=quick_doc()).status_code == 202


def test_server_limits(tmp_path):
    with app_client(tmp_path, max_triangles=20, max_paths_per_job=10_000, max_wall_time_s=60, max_receivers=50) as c:
        doc = quick_doc()
        doc["furniture"] = [{"min": [1, 1, 0], "max": [2, 2, 1], "reflectance": 0.5}]
        p = problem(c.post("/v1/jobs", json=doc), 422, "limit-exceeded")
        assert locs(p) == {"body.meshes"} and "24 triangles" in p["detail"]
        p = problem(c.post("/v1/jobs", json=quick_doc(paths=20_000)), 422, "limit-exceeded")
        assert locs(p) == {"body.simulation.paths"}
        p = problem(
            c.post("/v1/jobs", json=quick_doc(paths=None, target_rel_error=0.01, time_budget_s=120)),
            422,
            "limit-exceeded",
        )
        assert locs(p) == {"body.simulation.time_budget_s"}
        doc = quick_doc()
        doc["receiver_grids"] = [{"origin": [0.5, 0.5, 0.5], "size": [4, 4], "spacing": 0.5, "area": 1e-4}]
        p = problem(c.post("/v1/jobs", json=doc), 422, "limit-exceeded")
        assert locs(p) == {"body.receiver_grids"} and "82 receivers" in p["detail"]
        doc["receiver_grids"] = [  # 9 points, each also held 8 ways: 81 hidden receivers
            {"origin": [1, 1, 0.5], "size": [2, 2], "spacing": 1, "area": 1e-4, "orientation": {"samples": 8}}
        ]
        p = problem(c.post("/v1/jobs", json=doc), 422, "limit-exceeded")
        assert locs(p) == {"body.receiver_grids"} and "82 receivers, counting each orientation" in p["detail"]
        assert c.post("/v1/jobs", json=quick_doc(paths=10_000)).status_code == 202


def test_full_queue_answers_429_with_retry_after(tmp_path):
    with app_client(tmp_path, max_queued_jobs=2, retry_after_s=7) as c:
        for _ in range(2):
            assert c.post("/v1/jobs", json=quick_doc()).status_code == 202
        r = c.post("/v1/jobs", json=quick_doc())
        problem(r, 429, "queue-full")
        assert r.headers["retry-after"] == "7"
        cancelled = c.get("/v1/jobs").json()["items"][0]["id"]
        c.post(f"/v1/jobs/{cancelled}/cancel")  # a cancelled job leaves the queue
        assert c.post("/v1/jobs", json=quick_doc()).status_code == 202


def test_idempotency_key_returns_the_first_job(api, monkeypatch):
    import owcsim.server.routes.jobs as routes

    preflights = []
    real = routes.check_runnable
    monkeypatch.setattr(routes, "check_runnable", lambda *a: (preflights.append(1), real(*a))[1])
    first = api.post("/v1/jobs", json=quick_doc(), headers={"Idempotency-Key": "abc-1"})
    again = api.post("/v1/jobs", json=quick_doc(), headers={"Idempotency-Key": "abc-1"})
    assert first.status_code == again.status_code == 202
    assert len(preflights) == 1  # a retry (after a client timeout) finds the job before any pre-flight
    assert again.json()["id"] == first.json()["id"] and again.headers["idempotent-replayed"] == "true"
    # the same document in another spelling is the same request
    respaced = json.dumps(quick_doc(), indent=3).encode()
    same = api.post(
        "/v1/jobs", content=respaced, headers={"Idempotency-Key": "abc-1", "content-type": "application/json"}
    )
    assert same.json()["id"] == first.json()["id"]
    other = problem(
        api.post("/v1/jobs", json=quick_doc(seed=2), headers={"Idempotency-Key": "abc-1"}),
        422,
        "idempotency-key-reused",
    )
    assert other["job_id"] == first.json()["id"]
    assert api.post("/v1/jobs", json=quick_doc()).json()["id"] != first.json()["id"]
    assert len(api.get("/v1/jobs").json()["items"]) == 2
    problem(api.post("/v1/jobs", json=quick_doc(), headers={"Idempotency-Key": "x" * 300}), 422, "invalid-parameter")


def test_list_pages_newest_first_and_filters(api):
    ids = [api.post("/v1/jobs", json=quick_doc(seed=i)).json()["id"] for i in range(5)]
    api.post(f"/v1/jobs/{ids[1]}/cancel")
    seen, url = [], "/v1/jobs?limit=2"
    while url:
        page = api.get(url).json()
        assert len(page["items"]) <= 2
        seen += [j["id"] for j in page["items"]]
        url = page["next"]
    assert seen == ids[::-1]
    assert [j["id"] for j in api.get("/v1/jobs?status=cancelled").json()["items"]] == [ids[1]]
    both = api.get("/v1/jobs", params={"status": ["cancelled", "queued"], "limit": 3}).json()
    assert len(both["items"]) == 3 and both["next_cursor"] and "status=cancelled" in both["next"]
    assert api.get("/v1/jobs?status=running").json() == {"items": [], "next_cursor": None, "next": None}
    for bad in ("status=done", "limit=0", "limit=501", "cursor=abc", "limit=x"):
        p = problem(api.get(f"/v1/jobs?{bad}"), 422, "invalid-parameter")
        assert {loc.split(".")[1] for loc in locs(p)} == {bad.split("=")[0]}, p


def test_unknown_job_route_and_method(api):
    problem(api.get("/v1/jobs/nope"), 404, "job-not-found")
    problem(api.get("/v1/jobs/nope/result"), 404, "job-not-found")
    problem(api.post("/v1/jobs/nope/cancel"), 404, "job-not-found")
    problem(api.get("/v1/nothing"), 404, "not-found")
    r = api.delete("/v1/jobs")
    problem(r, 405, "method-not-allowed")
    assert r.headers["allow"] == "GET, HEAD, POST"  # the methods of the path, from the included router
    r = api.put("/v1/jobs/abc")
    problem(r, 405, "method-not-allowed")
    assert r.headers["allow"] == "DELETE, GET, HEAD"


def test_unusable_json_numbers_are_400(api):
    body = b'{"simulation": {"seed": ' + b"9" * 5000 + b"}}"  # past Python's 4300-digit integer limit
    p = problem(api.post("/v1/jobs", content=body, headers={"content-type": "application/json"}), 400, "malformed-json")
    assert "4300" in p["detail"]


@pytest.mark.parametrize("suffix", ["result", "result.csv", "result.npz", "plot.png"])
def test_results_of_a_queued_job_are_409(api, suffix):
    job = api.post("/v1/jobs", json=quick_doc()).json()
    p = problem(api.get(f"{job['url']}/{suffix}"), 409, "result-not-ready")
    assert p["job_status"] == "queued" and "is queued" in p["detail"]


def test_cancel_a_queued_job(api):
    job = api.post("/v1/jobs", json=quick_doc()).json()
    r = api.post(f"{job['url']}/cancel")
    assert r.status_code == 200 and r.json()["status"] == "cancelled" and r.json()["finished_at"]
    assert api.post(f"{job['url']}/cancel").status_code == 200  # again: no-op
    p = problem(api.get(f"{job['url']}/result"), 409, "result-not-ready")
    assert "cancelled" in p["detail"]


def test_unexpected_error_is_a_500_problem_without_trace(api, monkeypatch):
    import owcsim.server.routes.jobs

    def boom(*a, **k):
        raise RuntimeError("secret internals")

    api.post("/v1/jobs", json=quick_doc())
    monkeypatch.setattr(owcsim.server.routes.jobs, "job_public", boom)
    p = problem(api.get("/v1/jobs"), 500, "internal-error")
    assert "secret" not in json.dumps(p) and p["reference"] in p["detail"]


class TestApiKeys:
    KEYS = {"alice": "alice-token-123", "bob": "bob-token-456"}

    @pytest.fixture
    def c(self, tmp_path):
        keyfile = tmp_path / "keys"
        keyfile.write_text(f"# team keys\n{self.KEYS['bob']}\n")
        with app_client(tmp_path, api_keys=self.KEYS["alice"], api_keys_file=keyfile) as client:
            yield client

    def h(self, who):
        return {"Authorization": f"Bearer {self.KEYS[who]}"}

    def test_a_key_is_required(self, c):
        r = c.get("/v1/jobs")
        problem(r, 401, "unauthorized")
        assert r.headers["www-authenticate"].startswith("Bearer")
        problem(c.post("/v1/jobs", json=quick_doc(), headers={"Authorization": "Bearer wrong"}), 401)
        problem(c.get("/v1/jobs", headers={"Authorization": "Basic YTpi"}), 401)
        assert c.get("/v1/version").status_code == 200  # open
        assert c.get("/v1/health").status_code in (200, 503)

    def test_a_key_sees_and_cancels_only_its_own_jobs(self, c):
        a = c.post("/v1/jobs", json=quick_doc(), headers=self.h("alice")).json()
        b = c.post("/v1/jobs", json=quick_doc(), headers=self.h("bob")).json()
        assert [j["id"] for j in c.get("/v1/jobs", headers=self.h("alice")).json()["items"]] == [a["id"]]
        assert [j["id"] for j in c.get("/v1/jobs", headers=self.h("bob")).json()["items"]] == [b["id"]]
        for path in ("", "/result", "/result.csv", "/plot.png"):
            problem(c.get(f"{a['url']}{path}", headers=self.h("bob")), 404, "job-not-found")
        problem(c.post(f"{a['url']}/cancel", headers=self.h("bob")), 404)
        assert c.get(a["url"], headers=self.h("alice")).json()["status"] == "queued"
        assert c.post(f"{a['url']}/cancel", headers=self.h("alice")).json()["status"] == "cancelled"

    def test_idempotency_keys_are_per_api_key(self, c):
        key = {"Idempotency-Key": "same"}
        a = c.post("/v1/jobs", json=quick_doc(), headers=self.h("alice") | key).json()
        b = c.post("/v1/jobs", json=quick_doc(), headers=self.h("bob") | key).json()
        assert a["id"] != b["id"]


def test_numbers_the_schema_cannot_compute_with_are_422(api):
    """Found by the fuzz: a grid whose size / spacing overflows raised OverflowError (a 500)."""
    doc = quick_doc()
    doc["receiver_grids"] = [{"origin": [1, 1, 0], "size": [1.0, 1.0], "spacing": 5e-324, "area": 1e-4}]
    p = problem(api.post("/v1/jobs", json=doc), 422, "invalid-scene")
    assert locs(p) == {"body.receiver_grids.0"} and "100000 receivers" in p["detail"]
    doc = quick_doc()  # found by the fuzz too: m = -ln 2 / ln cos(1e-300 deg) divided by zero
    del doc["transmitters"][0]["lambertian_order"]
    doc["transmitters"][0]["half_power_semi_angle_deg"] = 1e-300
    p = problem(api.post("/v1/jobs", json=doc), 422, "invalid-scene")
    assert locs(p) == {"body.transmitters.0"} and "above 10000" in p["detail"]
