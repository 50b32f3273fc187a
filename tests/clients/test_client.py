"""The Python client on its own: retries and backoff, problem exceptions, scenes, results, async twin."""

import asyncio
import base64
import io
import json

import httpx
import numpy as np
import pytest

from owcsim.clients import (
    AsyncClient,
    Client,
    Conflict,
    ConnectionFailed,
    InvalidRequest,
    JobFailed,
    NotFound,
    QueueFull,
    Result,
    RetryPolicy,
    ServerError,
)
from owcsim.clients.http import retry_after
from owcsim.clients.progress import ProgressBar
from owcsim.clients.scene import scene_document
from owcsim.schemas import SceneSpec
from owcsim.schemas.jobs import JobPublic
from owcsim.schemas.results import SimulationResultPublic
from tests.results import simulate_document as simulate
from tests.scenes import room_doc

FAST = RetryPolicy(retries=3, backoff_s=0.0, max_backoff_s=0.0)
JOB = {
    "id": "j1",
    "url": "/v1/jobs/j1",
    "status": "queued",
    "created_at": "2026-01-01T00:00:00Z",
    "urls": {
        "self": "/v1/jobs/j1",
        "result": "/v1/jobs/j1/result",
        "result_csv": "/v1/jobs/j1/result.csv",
        "result_npz": "/v1/jobs/j1/result.npz",
        "plot": "/v1/jobs/j1/plot.png",
        "cancel": "/v1/jobs/j1/cancel",
    },
}


def problem(status, kind, detail, errors=()):
    return httpx.Response(
        status,
        headers={"content-type": "application/problem+json"},
        json={
            "type": f"urn:owcsim:problem:{kind}",
            "title": kind,
            "status": status,
            "detail": detail,
            "errors": list(errors),
        },
    )


def scripted(*answers, seen=None):
    """A transport answering in turn: an httpx.Response, or an exception to raise."""
    queue = list(answers)

    def handler(request: httpx.Request):
        if seen is not None:
            seen.append(request)
        answer = queue.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer

    return httpx.MockTransport(handler)


def client(*answers, seen=None, retry=FAST):
    http = httpx.Client(base_url="http://owcsim.test", transport=scripted(*answers, seen=seen))
    return Client("http://owcsim.test", api_key="k", retry=retry, http=http)


@pytest.fixture(scope="module")
def result_doc():
    return json.loads(json.dumps(simulate(SceneSpec.model_validate(room_doc(paths=3000, max_reflections=2)))))


def test_connection_errors_and_503_are_retried_with_one_idempotency_key():
    seen = []
    owc = client(
        httpx.ConnectError("refused"),
        httpx.ReadTimeout("slow"),
        httpx.Response(503),
        httpx.Response(202, json=JOB),
        seen=seen,
    )
    job = owc.submit(room_doc())
    assert job.id == "j1" and job.status == "queued" and len(seen) == 4
    keys = {r.headers["idempotency-key"] for r in seen}
    assert len(keys) == 1 and len(keys.pop()) == 32
    assert seen[0].headers["authorization"] == "Bearer k"
    assert json.loads(seen[0].content)["transmitters"][0]["id"] == "tx"


def test_retries_give_up_with_clear_errors():
    with pytest.raises(ConnectionFailed, match="cannot reach the owcsim server at http://owcsim.test"):
        client(*[httpx.ConnectError("refused")] * 4).health()
    full = problem(429, "queue-full", "the queue is full (2 jobs): try again later")
    with pytest.raises(QueueFull) as err:
        client(full, full, full, full).submit(room_doc())
    assert err.value.status == 429 and "queue is full" in str(err.value)


def test_retry_after_is_honoured():
    r = httpx.Response(429, headers={"retry-after": "3"})
    assert retry_after(r) == 3.0 and RetryPolicy(max_backoff_s=2).delay(0, r) == 2.0
    assert retry_after(httpx.Response(429, headers={"retry-after": "Wed, 21 Oct 2015 07:28:00 GMT"})) == 0.0
    assert retry_after(httpx.Response(429)) is None
    assert 0.25 <= RetryPolicy(backoff_s=0.5).delay(0) <= 0.5


def test_problem_answers_become_exceptions_with_the_fields():
    bad = problem(
        422,
        "invalid-scene",
        "body.receivers.0.fov_deg: too wide",
        [
            {
                "loc": "body.receivers.0.fov_deg",
                "msg": "Input should be less than or equal to 90",
                "type": "less_than_equal",
            },
            {"loc": "body.room", "msg": "missing", "type": "missing"},
        ],
    )
    with pytest.raises(InvalidRequest) as err:
        client(bad).submit(room_doc())
    e = err.value
    assert e.status == 422 and e.problem.type == "urn:owcsim:problem:invalid-scene"
    assert [f.loc for f in e.errors] == ["body.receivers.0.fov_deg", "body.room"]
    assert "body.receivers.0.fov_deg: Input should be less than or equal to 90" in str(e)
    with pytest.raises(NotFound):
        client(problem(404, "job-not-found", "no job 'x'")).job("x")
    with pytest.raises(Conflict):
        client(httpx.Response(200, json=JOB | {"status": "running"}), problem(409, "result-not-ready", "running")).job(
            "j1"
        ).result(wait=False)
    with pytest.raises(ServerError) as err:  # not a problem document (a proxy's page)
        client(httpx.Response(500, text="<html>oops</html>")).health()
    assert err.value.problem.detail == "<html>oops</html>"


def test_wait_polls_until_done_and_draws_progress(result_doc):
    running = JOB | {
        "status": "running",
        "progress": {"fraction": 0.5, "paths": 1500, "batches": 1, "dc_gain_rel_stderr": 0.01, "elapsed_s": 0.1},
    }
    done = JOB | {"status": "succeeded", "progress": {"fraction": 1.0, "paths": 3000, "batches": 2}}
    owc = client(
        httpx.Response(200, json=running), httpx.Response(200, json=done), httpx.Response(200, json=result_doc)
    )
    job = owc.job("j1")
    bar = io.StringIO()
    assert job.wait(progress=True, stream=bar) is job and job.status == "succeeded"
    assert "100.0%" in bar.getvalue() and bar.getvalue().endswith("\n")
    result = job.result()
    assert isinstance(result, SimulationResultPublic) and isinstance(result, Result)
    failed = JOB | {"status": "failed", "error": "the worker process was killed by SIGKILL"}
    with pytest.raises(JobFailed, match="SIGKILL"):
        client(httpx.Response(200, json=failed), httpx.Response(200, json=failed)).job("j1").wait()
    slow = [httpx.Response(200, json=running)] * 20
    with pytest.raises(TimeoutError):
        client(*slow).job("j1").wait(timeout=0.3)


def test_result_arrays_plot_and_files(result_doc, tmp_path):
    result = Result.from_document(result_doc)
    a = result.arrays()
    lk = result_doc["links"][0]
    np.testing.assert_array_equal(a["cir"][0], lk["cir"]["total"])
    assert a["by_reflection_order"].shape == (1, 3, result_doc["time_bins"]["n_bins"])
    assert a["t_edges_s"][1] == result_doc["time_bins"]["time_bin_s"] and a["dc_gain"][0] == lk["dc_gain"]
    assert result.link("tx", "rx").dc_gain == lk["dc_gain"]
    with pytest.raises(KeyError):
        result.link("tx", "nobody")
    paths = result.save(tmp_path / "out")
    assert json.loads(paths[0].read_text()) == result_doc  # as served, nothing dropped
    result.plot(tmp_path / "h.png")
    assert (tmp_path / "h.png").read_bytes()[:4] == b"\x89PNG"


def test_scene_documents_from_spec_dict_and_file_with_inline_meshes(tmp_path):
    (tmp_path / "plate.obj").write_text("v 1 1 1\nv 2 1 1\nv 1 2 1\nf 1 2 3\n")
    doc = room_doc()
    doc["meshes"] = [{"file": "plate.obj", "reflectance": 0.5}]
    (tmp_path / "scene.json").write_text(json.dumps(doc))
    sent = scene_document(tmp_path / "scene.json")
    mesh = sent["meshes"][0]
    assert "file" not in mesh and mesh["format"] == "obj"
    assert base64.b64decode(mesh["data_base64"]).startswith(b"v 1 1 1")
    SceneSpec.model_validate(sent)
    assert "file" in doc["meshes"][0]  # the caller's dict is left alone
    assert scene_document(doc, base_dir=tmp_path)["meshes"][0]["format"] == "obj"
    spec_doc = scene_document(SceneSpec.model_validate(room_doc()))
    assert SceneSpec.model_validate(spec_doc) == SceneSpec.model_validate(room_doc())
    with pytest.raises(FileNotFoundError, match="nothing.obj"):
        scene_document({**doc, "meshes": [{"file": "nothing.obj", "reflectance": 0.5}]}, base_dir=tmp_path)
    with pytest.raises(TypeError):
        scene_document(42)


def test_listing_follows_pages():
    page1 = {"items": [JOB], "next_cursor": "7", "next": "/v1/jobs?cursor=7"}
    page2 = {"items": [JOB | {"id": "j0"}], "next_cursor": None, "next": None}
    seen = []
    jobs = list(
        client(httpx.Response(200, json=page1), httpx.Response(200, json=page2), seen=seen).jobs(
            status="queued", page_size=1
        )
    )
    assert [j.id for j in jobs] == ["j1", "j0"] and "cursor=7" in str(seen[1].url)
    assert "status=queued" in str(seen[0].url)


def test_progress_bar_line():
    out = io.StringIO()
    bar = ProgressBar(out)
    bar.update(JobPublic.model_validate(JOB | {"status": "running", "progress": {"fraction": 0.25, "paths": 1234}}))
    bar.close()
    assert "25.0%" in out.getvalue() and "1,234 paths" in out.getvalue() and out.getvalue().startswith("\r[")


def test_async_twin(result_doc):
    done = JOB | {"status": "succeeded"}
    answers = [
        httpx.ConnectError("refused"),
        httpx.Response(202, json=JOB),
        httpx.Response(200, json=done),
        httpx.Response(200, json=result_doc),
        httpx.Response(200, json=JOB | {"status": "cancelled"}),
        httpx.Response(200, json={"items": [done], "next_cursor": None, "next": None}),
    ]
    seen = []

    async def main():
        http = httpx.AsyncClient(base_url="http://owcsim.test", transport=scripted(*answers, seen=seen))
        async with AsyncClient("http://owcsim.test", retry=FAST, http=http) as owc:
            job = await owc.submit(room_doc())
            await job.wait()
            result = await job.result()
            cancelled = await job.cancel()
            listed = [j.id async for j in owc.jobs()]
        await http.aclose()
        return job, result, cancelled, listed

    job, result, cancelled, listed = asyncio.run(main())
    assert job.id == "j1" and isinstance(result, Result) and cancelled.status == "cancelled" and listed == ["j1"]
    assert seen[0].headers["idempotency-key"] == seen[1].headers["idempotency-key"]


def test_async_client_against_the_app(tmp_path):
    """The async client through httpx's ASGI transport, on the real app (jobs stay queued)."""
    from owcsim.server.app import create_app
    from owcsim.server.settings import Settings

    app = create_app(Settings(db=tmp_path / "j.sqlite"), run_jobs=False)

    async def main():
        http = httpx.AsyncClient(base_url="http://app", transport=httpx.ASGITransport(app=app))
        async with AsyncClient("http://app", retry=FAST, http=http) as owc:
            job = await owc.submit(room_doc())
            again = await owc.job(job.id)
            with pytest.raises(InvalidRequest) as err:
                await owc.submit({"transmitters": []})
            await job.cancel()
            version = await owc.version()
        await http.aclose()
        return job, again, err.value, version

    job, again, err, version = asyncio.run(main())
    assert again.id == job.id and again.status == "queued" and version.api_version == "v1"
    assert job.status == "cancelled" and err.status == 422
    assert {f.loc for f in err.errors} >= {"body.transmitters"}


def test_health_reports_unavailable_without_retrying():
    body = {
        "status": "unavailable",
        "store": True,
        "dispatcher": False,
        "queued": 0,
        "running": 0,
        "max_concurrent_jobs": 2,
        "max_queued_jobs": 10,
    }
    seen = []
    assert client(httpx.Response(503, json=body), seen=seen).health().status == "unavailable" and len(seen) == 1


def _timed_transport(done_at):
    """A job that reports `running` until time.monotonic() reaches `done_at`, then `succeeded`."""
    import time

    def handler(request: httpx.Request):
        return httpx.Response(200, json={**JOB, "status": "succeeded" if time.monotonic() >= done_at else "running"})

    return httpx.MockTransport(handler)


def test_wait_polls_at_its_deadline_and_honours_its_timeout():
    import socket
    import time

    from owcsim.clients.client import Job
    from owcsim.clients.http import LAST_POLL_S

    # done 0.9 s into a 1 s wait: the last poll lands on the deadline and sees it (it used to give up early)
    t0 = time.monotonic()
    http = httpx.Client(base_url="http://owcsim.test", transport=_timed_transport(t0 + 0.9))
    job = Job(
        Client("http://owcsim.test", retry=FAST, http=http), JobPublic.model_validate({**JOB, "status": "running"})
    )
    assert job.wait(timeout=1.0).info.status == "succeeded"
    http = httpx.Client(base_url="http://owcsim.test", transport=_timed_transport(t0 + 60))
    job = Job(
        Client("http://owcsim.test", retry=FAST, http=http), JobPublic.model_validate({**JOB, "status": "running"})
    )
    t = time.monotonic()
    with pytest.raises(TimeoutError, match="still running after 0.5 s"):
        job.wait(timeout=0.5)
    assert 0.45 < time.monotonic() - t < 0.5 + 0.5
    # a server that accepts the connection and never answers: TimeoutError by the deadline, not after
    # the client's 30 s request timeout and its retries
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        owc = Client(f"http://127.0.0.1:{silent.getsockname()[1]}", timeout=30.0)
        job = Job(owc, JobPublic.model_validate({**JOB, "status": "running"}))
        t = time.monotonic()
        with pytest.raises(TimeoutError):
            job.wait(timeout=1.0)
        assert time.monotonic() - t < 1.0 + LAST_POLL_S + 0.5
        owc.close()


def test_a_submission_without_answer_names_its_idempotency_key():
    owc = client(
        httpx.ReadTimeout("no answer"), httpx.ReadTimeout("no answer"), retry=RetryPolicy(retries=1, backoff_s=0.0)
    )
    with pytest.raises(ConnectionFailed, match="idempotency_key=") as err:
        owc.submit(room_doc(paths=100), idempotency_key="k-123")
    assert err.value.idempotency_key == "k-123" and "k-123" in str(err.value)


def test_async_wait_polls_at_its_deadline():
    import time

    from owcsim.clients.aio import AsyncJob

    async def go():
        t0 = time.monotonic()
        http = httpx.AsyncClient(base_url="http://owcsim.test", transport=_timed_transport(t0 + 0.9))
        owc = AsyncClient("http://owcsim.test", retry=FAST, http=http)
        job = AsyncJob(owc, JobPublic.model_validate({**JOB, "status": "running"}))
        assert (await job.wait(timeout=1.0)).info.status == "succeeded"
        http = httpx.AsyncClient(base_url="http://owcsim.test", transport=_timed_transport(t0 + 60))
        job = AsyncJob(
            AsyncClient("http://owcsim.test", retry=FAST, http=http),
            JobPublic.model_validate({**JOB, "status": "running"}),
        )
        with pytest.raises(TimeoutError, match="still running"):
            await job.wait(timeout=0.3)

    asyncio.run(go())
