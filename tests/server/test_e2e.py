"""End to end: a real `owcsim serve` (uvicorn) on 127.0.0.1, driven by the Python client."""

import io
import json
import signal
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from owcsim.clients import Client, InvalidRequest, NotFound, Unauthorized
from owcsim.schemas import SceneSpec
from owcsim.schemas.results import SimulationResultPublic
from tests.results import simulate_document as simulate

from .helpers import ServerProcess, long_doc, quick_doc


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with ServerProcess(
        tmp_path_factory.mktemp("e2e") / "jobs.sqlite", progress_interval_s=0.1, max_body_bytes=200_000
    ) as s:
        yield s


def test_submit_watch_progress_fetch_and_cancel(server):
    with Client(server.url) as owc:
        job = owc.submit(quick_doc(paths=1_000_000, batch_size=4096, max_reflections=2))
        bar = io.StringIO()
        job.wait(progress=True, stream=bar)
        shown = {line.split("%")[0].split("]")[-1].strip() for line in bar.getvalue().split("\r") if "%" in line}
        assert "100.0" in shown and len(shown) >= 3, shown  # it moved while we watched
        result = job.result()
        assert isinstance(result, SimulationResultPublic) and result.run.paths_total == 1_000_000
        arrays = result.arrays()
        served = job.npz()
        for k in arrays:
            np.testing.assert_array_equal(arrays[k], served[k])
        assert job.csv().startswith("transmitter,receiver,t_start_s") and job.plot_png()[:4] == b"\x89PNG"

        long = owc.submit(long_doc())
        while long.refresh().progress.paths == 0:
            time.sleep(0.05)
        t0 = time.monotonic()
        long.cancel()
        long.wait(timeout=10)
        assert long.status == "cancelled" and time.monotonic() - t0 < 3
        assert long.result().run.stop_reason == "cancelled"
        assert {j.id for j in owc.jobs()} >= {job.id, long.id}
        assert owc.health().status == "ok" and owc.version().api_version == "v1"


def test_idempotent_retry_and_bad_requests_through_uvicorn(server):
    with Client(server.url) as owc:
        a = owc.submit(quick_doc(), idempotency_key="retry-me")
        b = owc.submit(quick_doc(), idempotency_key="retry-me")
        assert a.id == b.id
        doc = quick_doc()
        doc["description"] = "x" * 300_000
        with pytest.raises(InvalidRequest) as err:
            owc.submit(doc)
        assert err.value.status == 413
        doc = quick_doc()
        doc["receivers"][0]["fov_deg"] = 95
        with pytest.raises(InvalidRequest) as err:
            owc.submit(doc)
        assert err.value.status == 422 and err.value.errors[0].loc == "body.receivers.0.fov_deg"
        with pytest.raises(NotFound):
            owc.job("0" * 32)
    r = httpx.post(f"{server.url}/v1/jobs", content=b'{"room": ', headers={"content-type": "application/json"})
    assert r.status_code == 400 and r.headers["content-type"] == "application/problem+json"
    r = httpx.post(f"{server.url}/v1/jobs", content=b"x" * 300_000, headers={"content-type": "application/json"})
    assert r.status_code == 413


def test_api_keys_isolate_callers(tmp_path):
    with ServerProcess(tmp_path / "jobs.sqlite", api_keys="key-a,key-b") as srv:
        with Client(srv.url, "key-a") as a, Client(srv.url, "key-b") as b, Client(srv.url) as anonymous:
            job = a.submit(quick_doc())
            assert job.wait(timeout=30).status == "succeeded"
            with pytest.raises(NotFound):
                b.job(job.id)
            with pytest.raises(NotFound):
                b._request("POST", f"/v1/jobs/{job.id}/cancel")
            assert list(b.jobs()) == [] and [j.id for j in a.jobs()] == [job.id]
            with pytest.raises(Unauthorized) as err:
                anonymous.submit(quick_doc())
            assert err.value.status == 401 and "API key" in str(err.value)
            with pytest.raises(Unauthorized):
                Client(srv.url, "key-c").job(job.id)


def _state(pid: int) -> str:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("State:"):
                return line.split()[1]
    except FileNotFoundError:
        pass
    return "gone"


def _strip(res: dict) -> dict:
    res = json.loads(json.dumps(res))
    res["run"].pop("wall_time_s")
    return res


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_restart_while_a_job_runs_loses_nothing(tmp_path, sig):
    """Stop the server process mid-job (crash or orderly stop), start it again: every job completes."""
    srv = ServerProcess(tmp_path / "jobs.sqlite", max_concurrent_jobs=1, progress_interval_s=0.1)
    doc = quick_doc(paths=4_000_000, batch_size=16384, seed=5)
    try:
        srv.start()
        with Client(srv.url) as owc:
            running = owc.submit(doc)
            queued = [owc.submit(quick_doc(seed=i)) for i in range(2)]
            while running.refresh().progress.paths == 0:
                time.sleep(0.02)
            assert running.status == "running" and running.progress.fraction < 0.9
        from owcsim.server.store import JobStore

        worker = JobStore(srv.db).get(running.id).worker_pid
        srv.stop(sig)  # the server process only: its forkserver and worker must notice by themselves
        expected = "running" if sig == signal.SIGKILL else "queued"
        assert JobStore(srv.db).get(running.id).status == expected
        deadline = time.monotonic() + 10
        while _state(worker) not in ("gone", "Z"):  # the orphaned worker stops on its own
            assert time.monotonic() < deadline, "the worker outlived its server"
            time.sleep(0.05)
        srv.start()
        with Client(srv.url) as owc:
            for job in [running, *queued]:
                assert owc.job(job.id).wait(timeout=90).status == "succeeded"
            again = owc.job(running.id)
            assert again.attempts == 2
            assert again.error.startswith(
                "requeued: the server " + ("restarted" if sig == signal.SIGKILL else "stopped")
            )
            result = again.result()
            assert result.run.paths_total == 4_000_000 and result.run.stop_reason == "paths"
            if sig == signal.SIGKILL:  # same seed: the rerun gives exactly the uninterrupted result
                assert _strip(result.raw) == _strip(simulate(SceneSpec.model_validate(doc)))
            assert len(list(owc.jobs())) == 3
    finally:
        srv.kill()


def test_cli_serve_and_submit(server, tmp_path, capsys, monkeypatch):
    from owcsim.cli import main
    from owcsim.clients.http import RetryPolicy
    from tests.scenes import EXAMPLES

    out = tmp_path / "out"
    assert (
        main(
            [
                "submit",
                str(EXAMPLES / "barry_config_a.json"),
                "--server",
                server.url,
                "--out",
                str(out),
                "--paths",
                "20000",
                "--set",
                "receivers.0.fov_deg=60",
            ]
        )
        == 0
    )
    printed = capsys.readouterr()
    assert "tx -> rx" in printed.out and "20,000 paths" in printed.out and "submitted job" in printed.err
    res = json.loads((out / "result.json").read_text())
    assert res["scene"]["receivers"][0]["fov_deg"] == 60
    assert (out / "cir.csv").exists() and (out / "cir.png").read_bytes()[:4] == b"\x89PNG"

    scene = tmp_path / "with_mesh.json"  # a mesh file next to the scene travels inline
    (tmp_path / "plate.obj").write_text("v 1 1 1\nv 2 1 1\nv 1 2 1\nf 1 2 3\n")
    doc = quick_doc()
    doc["meshes"] = [{"file": "plate.obj", "reflectance": 0.5}]
    scene.write_text(json.dumps(doc))
    assert main(["submit", str(scene), "--server", server.url]) == 0
    capsys.readouterr()

    assert main(["submit", str(scene), "--server", server.url, "--no-wait"]) == 0
    assert len(capsys.readouterr().out.strip()) == 32

    assert main(["submit", str(scene), "--server", server.url, "--set", "description=" + "x" * 300_000]) == 2
    assert "413" in capsys.readouterr().err

    monkeypatch.setattr(RetryPolicy, "delay", lambda self, attempt, response=None: 0.0)
    port = server.port + 1 if server.port < 65535 else server.port - 1
    assert main(["submit", str(scene), "--server", f"http://127.0.0.1:{port}"]) == 1
    assert "cannot reach the owcsim server" in capsys.readouterr().err


def test_serve_refuses_bad_settings(tmp_path, capsys):
    from owcsim.cli import main

    assert main(["serve", "--db", str(tmp_path / "j.sqlite"), "--max-concurrent-jobs", "0"]) == 2
    assert "max_concurrent_jobs" in capsys.readouterr().err
    assert main(["serve", "--db", str(tmp_path / "j.sqlite"), "--api-keys-file", str(tmp_path / "none")]) == 2
    assert "api_keys_file" in capsys.readouterr().err
    comments = tmp_path / "keys.txt"
    comments.write_text("# tokens go here\n\n")
    assert main(["serve", "--db", str(tmp_path / "j.sqlite"), "--api-keys-file", str(comments)]) == 2
    assert "holds no key" in capsys.readouterr().err
