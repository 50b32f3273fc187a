"""Jobs that run: worker processes, progress, results in every form, cancel, crashes, limits, order."""

import io
import json
import os
import signal
import time

import numpy as np
import pytest

from owcsim.clients.result import Result
from owcsim.formats.result_files import write_cir_csv
from owcsim.schemas import SceneSpec
from tests.results import simulate_document as simulate

from .helpers import app_client, long_doc, quick_doc, wait_for


def _strip(res):
    res = json.loads(json.dumps(res))
    res["run"].pop("wall_time_s")
    return res


def test_a_job_runs_and_serves_the_same_result_as_the_engine(live, tmp_path):
    doc = quick_doc(paths=6000, max_reflections=2, direction="auto")
    job = live.post("/v1/jobs", json=doc).json()
    done = wait_for(live, job["id"], "succeeded")
    assert done["progress"]["fraction"] == 1.0 and done["progress"]["paths"] == 6000
    assert done["started_at"] and done["finished_at"] >= done["started_at"] and done["attempts"] == 1
    served = live.get(f"{job['url']}/result").json()
    assert _strip(served) == _strip(simulate(SceneSpec.model_validate(doc)))  # same seed, same numbers
    # CSV: byte for byte the command line's cir.csv
    csv = live.get(f"{job['url']}/result.csv")
    assert csv.headers["content-type"].startswith("text/csv")
    write_cir_csv(Result.from_document(served), tmp_path / "cir.csv")
    assert csv.content == (tmp_path / "cir.csv").read_bytes()
    # .npz: the client's arrays
    with np.load(io.BytesIO(live.get(f"{job['url']}/result.npz").content)) as z:
        served_arrays = {k: z[k] for k in z.files}
    mine = Result.from_document(served).arrays()
    assert served_arrays.keys() == mine.keys()
    for k in mine:
        np.testing.assert_array_equal(served_arrays[k], mine[k])
    assert served_arrays["cir"].shape == (1, 50) and served_arrays["t_edges_s"].shape == (51,)
    png = live.get(f"{job['url']}/plot.png")
    assert png.headers["content-type"] == "image/png" and png.content[:4] == b"\x89PNG"
    assert live.get(f"{job['url']}/plot.png?link=0").status_code == 200
    assert live.get(f"{job['url']}/plot.png?link=3").status_code == 422
    assert live.post(f"{job['url']}/cancel").status_code == 409  # finished


def test_progress_is_written_while_running_and_cancel_stops_within_seconds(tmp_path):
    with app_client(tmp_path, run_jobs=True, progress_interval_s=0.1) as c:
        job = c.post("/v1/jobs", json=long_doc()).json()
        wait_for(c, job["id"], "running")
        deadline, seen = time.monotonic() + 20, []
        while len(seen) < 3 and time.monotonic() < deadline:
            p = c.get(job["url"]).json()["progress"]
            if p["paths"] and (not seen or p["paths"] > seen[-1]["paths"]):
                seen.append(p)
            time.sleep(0.05)
        assert len(seen) == 3, "progress did not advance"
        assert 0 < seen[0]["fraction"] < seen[-1]["fraction"] < 1 and seen[-1]["dc_gain_rel_stderr"] > 0
        t0 = time.monotonic()
        r = c.post(f"{job['url']}/cancel")
        assert r.status_code == 202 and r.json()["cancel_requested"]
        done = wait_for(c, job["id"], "cancelled", timeout=10)
        assert time.monotonic() - t0 < 3
        partial = c.get(f"{job['url']}/result").json()  # a cancelled run keeps its partial result
        assert partial["run"]["stop_reason"] == "cancelled"
        assert 0 < partial["run"]["paths_total"] < 200_000_000 and done["error"] is None


def _worker_pid(client, job_id, timeout=20.0) -> int:
    store = client.app.state.store
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        row = store.get(job_id)
        if row.status == "running" and row.worker_pid and row.paths > 0:
            return row.worker_pid
        time.sleep(0.05)
    raise AssertionError("the job did not start")


def test_a_killed_worker_is_retried_once_then_the_job_fails_with_the_reason(tmp_path):
    with app_client(tmp_path, run_jobs=True, crash_retries=1) as c:
        job = c.post("/v1/jobs", json=long_doc()).json()
        first = _worker_pid(c, job["id"])
        os.kill(first, signal.SIGKILL)
        deadline = time.monotonic() + 20
        while (second := _worker_pid(c, job["id"])) == first:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        retried = c.get(job["url"]).json()
        assert retried["status"] == "running" and retried["attempts"] == 2 and "SIGKILL" in retried["error"]
        os.kill(second, signal.SIGKILL)
        failed = wait_for(c, job["id"], "failed", timeout=10)
        assert "killed by SIGKILL" in failed["error"] and failed["finished_at"]
        assert c.get(f"{job['url']}/result").status_code == 409


def test_wall_time_limit_fails_the_job(tmp_path):
    with app_client(tmp_path, run_jobs=True, max_wall_time_s=1.0) as c:
        job = c.post("/v1/jobs", json=long_doc()).json()
        failed = wait_for(c, job["id"], "failed", timeout=20)
        assert "wall-time limit of 1 s" in failed["error"]


def test_jobs_start_in_order_and_at_most_n_at_once(tmp_path):
    with app_client(tmp_path, run_jobs=True, max_concurrent_jobs=1) as c:
        ids = [c.post("/v1/jobs", json=quick_doc(seed=i)).json()["id"] for i in range(4)]
        most = 0
        deadline = time.monotonic() + 60
        while True:
            jobs = c.get("/v1/jobs").json()["items"]
            most = max(most, sum(j["status"] == "running" for j in jobs))
            if all(j["status"] == "succeeded" for j in jobs):
                break
            assert time.monotonic() < deadline
            time.sleep(0.02)
        assert most == 1
        started = [c.get(f"/v1/jobs/{i}").json()["started_at"] for i in ids]
        assert started == sorted(started)


def test_a_cancel_while_queued_never_runs(tmp_path):
    with app_client(tmp_path, run_jobs=True, max_concurrent_jobs=1) as c:
        blocker = c.post("/v1/jobs", json=long_doc()).json()
        queued = c.post("/v1/jobs", json=quick_doc()).json()
        wait_for(c, blocker["id"], "running")
        assert c.post(f"{queued['url']}/cancel").json()["status"] == "cancelled"
        c.post(f"{blocker['url']}/cancel")
        wait_for(c, blocker["id"], "cancelled")
        time.sleep(0.5)
        job = c.get(queued["url"]).json()
        assert job["status"] == "cancelled" and job["attempts"] == 0


def test_engine_warnings_are_kept_with_the_job(live):
    doc = quick_doc()
    doc["meshes"] = [
        {"vertices": [[1, 1, 1], [2, 1, 1], [1, 2, 1], [3, 3, 1]], "faces": [[0, 1, 2], [0, 0, 3]], "reflectance": 0.5}
    ]
    with pytest.warns(UserWarning, match="degenerate"):  # a small scene is pre-flighted in the request thread
        job = live.post("/v1/jobs", json=doc).json()
    done = wait_for(live, job["id"], "succeeded")
    assert any("degenerate" in w for w in done["warnings"])


def test_workers_per_job_give_the_same_result(tmp_path):
    """Each job may use an engine pool inside its worker; the seed fixes the result all the same."""
    doc = quick_doc(paths=8192, batch_size=1024, max_reflections=2)
    with app_client(tmp_path, run_jobs=True, workers_per_job=2) as c:
        job = c.post("/v1/jobs", json=doc).json()
        wait_for(c, job["id"], "succeeded", timeout=60)
        served = c.get(f"{job['url']}/result").json()
    assert served["run"]["workers"] == 2
    alone = simulate(SceneSpec.model_validate(doc))
    for res in (served, alone):
        res["run"].pop("workers")
    assert _strip(served) == _strip(alone)
