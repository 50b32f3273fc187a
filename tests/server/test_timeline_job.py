"""A timeline job over HTTP (issue 26): one job, progress per time, the timeline's files; bad documents 422."""

import copy
import csv
import io
import time

import pytest

from .helpers import app_client, quick_doc, wait_for

N_TIMES = 4


def _doc(paths=20_000):
    doc = quick_doc(paths=paths)
    doc["link_budget"] = {"bit_rate": 1e7}
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
        "outage": {"quantity": "dc_gain", "threshold": 1e-6},
    }
    return doc


@pytest.fixture
def live_fast(tmp_path):
    """Jobs run in worker processes; progress is written after every report."""
    with app_client(tmp_path, run_jobs=True, progress_interval_s=1e-3) as client:
        yield client


@pytest.mark.filterwarnings("ignore:You should not use the 'timeout' argument")  # the client on a TestClient
def test_a_timeline_job_reports_progress_per_time_and_serves_its_files(live_fast):
    job = live_fast.post("/v1/jobs", json=_doc()).json()
    seen = set()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        state = live_fast.get(f"/v1/jobs/{job['id']}").json()
        if state["progress"] and state["progress"]["fraction"] is not None:
            seen.add(round(state["progress"]["fraction"], 6))
        if state["status"] in ("succeeded", "failed"):
            break
        time.sleep(0.01)
    assert state["status"] == "succeeded", state
    done = wait_for(live_fast, job["id"], "succeeded")
    assert done["progress"]["fraction"] == 1.0 and done["progress"]["batches"] == N_TIMES  # one report per time
    assert seen <= {k / N_TIMES for k in range(N_TIMES + 1)} | {0.0}  # only per-time reports reach the store
    assert seen & {k / N_TIMES for k in range(1, N_TIMES)}, seen  # a time done while the job ran
    result = live_fast.get(f"{job['url']}/result").json()
    tl = result["timeline"]
    assert tl["times_s"] == [0.0, 10.0, 20.0, 30.0] and tl["method"] == "reweighted"  # auto, 4 times
    link = tl["links"][0]
    assert len(link["dc_gain"]) == N_TIMES and len(link["dc_gain_diff_stderr"]) == N_TIMES - 1
    files = live_fast.get(f"{job['url']}/timeline").json()["files"]
    assert set(files) == {"timeline.csv", "timeline.nc", "timeline.svg"}
    table = live_fast.get(files["timeline.csv"])
    assert table.status_code == 200
    rows = list(csv.DictReader(io.StringIO(table.text)))
    assert [float(r["dc_gain"]) for r in rows] == link["dc_gain"]
    nc = live_fast.get(files["timeline.nc"])
    assert nc.status_code == 200 and nc.content[:3] == b"CDF"
    svg = live_fast.get(files["timeline.svg"])
    assert svg.status_code == 200 and svg.headers["content-type"].startswith("image/svg+xml")
    # the Python client: the job's Result carries the timeline views, the job its files
    from owcsim.clients.client import Client

    client_job = Client("http://testserver", http=live_fast).job(job["id"])
    served = client_job.result()
    assert served.timeline == served.model_validate(result).timeline
    assert list(served.timeline_dataframe()["dc_gain"]) == link["dc_gain"]
    assert client_job.timeline_file("timeline.nc") == nc.content


def test_a_job_without_timeline_has_no_timeline_files(live):
    job = live.post("/v1/jobs", json=quick_doc()).json()
    wait_for(live, job["id"], "succeeded")
    answer = live.get(f"{job['url']}/timeline.csv")
    assert answer.status_code == 404 and "no timeline" in answer.json()["detail"]


@pytest.mark.parametrize(
    "change,message",
    [
        (lambda d: d.update(medium={"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.0}), "remove the static"),
        (lambda d: d["timeline"].update(times_s=[0.0, 40.0]), "outside the frames' times"),
        (
            lambda d: d["timeline"].update(
                trajectories=[{"device": "nobody", "times_s": [0], "positions": [[1, 1, 1]]}]
            ),
            "no receiver",
        ),
    ],
)
def test_bad_timelines_are_located_422s(api, change, message):
    doc = copy.deepcopy(_doc())
    change(doc)
    answer = api.post("/v1/jobs", json=doc)
    assert answer.status_code == 422
    body = answer.json()
    assert message in body["detail"] and "timeline" in body["detail"]  # located: the section, the entry


def test_frames_from_a_server_path_are_refused_at_their_field(api):
    doc = _doc()
    doc["timeline"]["frames"] = {
        "type": "netcdf",
        "path": "/etc/passwd",
        "variable": "K",
        "albedo": 0.0,
        "origin": [0, 0, 0],
    }
    r = api.post("/v1/jobs", json=doc)
    assert r.status_code == 422, r.text
    fields = r.json()["errors"]
    assert [f["loc"] for f in fields] == ["body.timeline.frames.path"] and fields[0]["type"] == "path_not_allowed"


def test_an_fds_case_sent_by_the_client_runs_over_http(live_fast, tmp_path):
    """The real FDS office fire, zipped by the client into the body (a few MB: checked in the pre-flight process),
    runs as a timeline job whose result says where its frames came from."""
    pytest.importorskip("fdsreader", reason="pip install 'owcsim[fire]' (scripts/test installs it)")
    from owcsim.clients.scene import scene_document
    from tests.fds_data import office_fire

    doc = quick_doc(paths=500)
    doc["room"]["size"] = [6.0, 4.0, 3.0]
    doc["timeline"] = {
        "frames": {
            "type": "fds",
            "path": str(office_fire()),
            "slice_id": "EXT_3D_CELL",
            "albedo": 0.3,
            "origin": [0, 0, 0],
            "times_s": [0.0, 90.0],
        },
    }
    body = scene_document(doc, base_dir=tmp_path)
    job = live_fast.post("/v1/jobs", json=body)
    assert job.status_code == 202, job.text
    wait_for(live_fast, job.json()["id"], "succeeded", timeout=120)
    tl = live_fast.get(f"{job.json()['url']}/result").json()["timeline"]
    assert tl["frames_report"]["kind"] == "fds" and tl["frames_report"]["grid_shape"] == [30, 20, 15]
    h0 = tl["links"][0]["los_gain"]
    assert h0[1] < h0[0]  # the smoke of 90 s attenuates the line of sight
