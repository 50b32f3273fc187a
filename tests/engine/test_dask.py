"""Dask distributed executor on a LocalCluster of 2 worker processes (127.0.0.1).

Same bits as the local pool and the serial run; the scene is built once per worker
per job; a worker killed mid-job and a task that fails are retried and the result is
still exact; stopping a run cancels its tasks on the cluster; clear errors without
Dask or without a scheduler.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time

import pytest
import trimesh

distributed = pytest.importorskip("distributed")
from dask import config as dask_config  # noqa: E402

from owcsim.engine.core.errors import EngineError, SceneError  # noqa: E402
from owcsim.engine.integrator.path import WorkItem  # noqa: E402
from owcsim.engine.run.execution import JobRef  # noqa: E402
from owcsim.engine.run.execution_dask import (  # noqa: E402
    ClusterError,
    DaskExecutor,
    DaskUnavailableError,
    executor_from_scheduler,
    portable_spec,
    worker_cache_info,
)
from owcsim.engine.run.simulate import kernel_settings  # noqa: E402
from owcsim.engine.scene.scene import build_scene  # noqa: E402
from tests.results import simulate_document as simulate  # noqa: E402
from tests.scenes import room_doc, spec  # noqa: E402

BATCH_PREFIX = "owcsim-batch-"


def _strip(res):
    res = json.loads(json.dumps(res))
    for key in ("wall_time_s", "workers"):
        res["run"].pop(key)
    return res


def _doc(**simulation):
    """Two receivers, one behind a desk (shadow rays), auto direction with a pilot."""
    sim = dict(max_reflections=4, paths=12_000, batch_size=1024, direction="auto", pilot_paths=512)
    sim.update(simulation)
    doc = room_doc(**sim)
    doc["furniture"] = [{"min": [3.0, 3.0, 0.0], "max": [4.0, 4.5, 1.0], "reflectance": 0.6}]
    doc["receivers"].append(
        {"id": "rx2", "position": [4.5, 0.5, 0.8], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 70}
    )
    return doc


@pytest.fixture(scope="module")
def client():
    # The tests read the scheduler's transition log, a deque of 1000 entries by default: keep more,
    # so that one test's reading never depends on how many transitions earlier tests made.
    with dask_config.set({"distributed.admin.low-level-log-length": 100_000}):
        cluster = distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.CRITICAL,
        )
    client = distributed.Client(cluster, set_as_default=False)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


@pytest.fixture
def dask(client):
    client.wait_for_workers(2, timeout=60)  # a test may have killed one; its nanny restarts it
    ex = DaskExecutor(client)
    try:
        yield ex
    finally:
        ex.close()


def _batch_tasks(dask_scheduler):
    return sorted(str(k) for k in dask_scheduler.tasks if str(k).startswith(BATCH_PREFIX))


def _no_batch_tasks_left(client, timeout=10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not client.run_on_scheduler(_batch_tasks):
            return True
        time.sleep(0.1)
    return False


def test_same_bits_as_local_pool_and_serial(dask):
    doc = _doc()
    local_pool = simulate(spec(doc), workers=2)
    on_dask = simulate(spec(doc), executor=dask)
    assert _strip(on_dask) == _strip(local_pool) == _strip(simulate(spec(doc)))
    assert on_dask["run"]["workers"] == dask.workers == 2
    assert on_dask["run"]["batches"] in (12, 24)
    assert on_dask["links"][0]["dc_gain"] > on_dask["links"][0]["los_gain"] > 0


def test_accuracy_mode_and_tilted_devices_same_bits_as_serial(dask):
    # Tilted normals: the worker must get the validated document itself, not re-normalised JSON.
    doc = room_doc(
        max_reflections=3,
        paths=None,
        target_rel_error=0.03,
        batch_size=512,
        direction="backward",
        rx_normal=(0.31, -0.17, 0.93),
        tx_normal=(0.12, 0.27, -0.95),
    )
    serial = simulate(spec(doc))
    on_dask = simulate(spec(doc), executor=dask)
    assert serial["run"]["stop_reason"] == on_dask["run"]["stop_reason"] == "target_reached"
    assert _strip(on_dask) == _strip(serial)


def test_scene_built_once_per_worker_per_job(client, dask):
    before = client.run(worker_cache_info)
    res = simulate(spec(_doc(paths=16_384, batch_size=512, direction="forward", seed=11)), executor=dask)
    after = client.run(worker_cache_info)
    builds = {w: after[w]["builds"] - before[w]["builds"] for w in after}
    assert res["run"]["batches"] == 32
    assert all(n <= 1 for n in builds.values()) and sum(builds.values()) >= 1  # not once per task


def test_mesh_files_travel_as_content(tmp_path, dask):
    desk = trimesh.creation.box(extents=[1.0, 1.0, 0.8])
    desk.apply_translation([3.5, 3.5, 0.4])
    (tmp_path / "desk.obj").write_text(desk.export(file_type="obj"))
    doc = room_doc(paths=4096, batch_size=1024, direction="forward")
    doc["meshes"] = [{"file": "desk.obj", "reflectance": 0.6}]
    portable = portable_spec(spec(doc), tmp_path)
    assert portable.meshes[0].file is None and portable.meshes[0].format == "obj" and portable.meshes[0].data_base64
    # A job of 1 source on 2 workers, from the scene file's folder.
    serial = simulate(spec(doc), base_dir=tmp_path)
    assert _strip(simulate(spec(doc), base_dir=tmp_path, executor=dask)) == _strip(serial)


def test_worker_builds_a_different_scene_is_an_error(dask):
    """The worker checks what it built against the client's scene (other mesh file, trimesh, engine...)."""
    a, b = spec(room_doc(paths=2048, batch_size=1024)), spec(room_doc(rx=(4.0, 1.0, 0.0), paths=2048, batch_size=1024))
    scene = dataclasses.replace(build_scene(a), spec=b)  # geometry/devices of a, document of b
    job = JobRef(scene, "", "", None)
    items = [WorkItem("forward", 0, (0,), i, 1024, 7) for i in range(2)]
    with pytest.raises(SceneError, match="different scene"):
        list(dask.map(job, items, kernel_settings(a, scene)))


def test_cancel_reaches_the_cluster(client, dask):
    # An accuracy run that would go on for minutes, stopped after 6 batches.
    doc = room_doc(
        max_reflections=6, paths=None, target_rel_error=1e-5, time_budget_s=600, batch_size=4096, direction="forward"
    )
    seen, serial_seen = [], []
    res = simulate(
        spec(doc), executor=dask, progress=lambda p: seen.append(p.paths), should_stop=lambda: len(seen) >= 6
    )
    assert res["run"]["stop_reason"] == "cancelled"
    # accuracy runs start with batches of a quarter of batch_size, at least 2048 paths, and double them every
    # GROWTH_ROUNDS (4) rounds up to batch_size (simulate._items)
    assert seen == [2048, 4096, 6144, 8192, 12288, 16384]  # progress flows back, batch by batch
    serial = simulate(
        spec(doc), progress=lambda p: serial_seen.append(p.paths), should_stop=lambda: len(serial_seen) >= 6
    )
    assert _strip(res) == _strip(serial)
    assert _no_batch_tasks_left(client)

    # The executor directly: an endless stream of batches, closed after the first tally.
    s = spec(room_doc(max_reflections=6, batch_size=8192, direction="forward"))
    pulled = []

    def endless():
        for b in range(10**9):
            pulled.append(b)
            yield WorkItem("forward", 0, (0,), b, 8192, 7)

    built = build_scene(s)
    results = dask.map(JobRef(built, "", "", None), endless(), kernel_settings(s, built))
    next(results)
    assert len(pulled) <= dask.window + 1  # a bounded window is in flight
    assert client.run_on_scheduler(_batch_tasks)
    results.close()
    assert _no_batch_tasks_left(client)


def _fail_first_call():
    """Run on a worker: the next batch this worker traces raises, once."""
    import owcsim.engine.run.execution_dask as ed

    original = ed.trace_batch

    def flaky(*args, **kwargs):
        ed.trace_batch = original
        raise RuntimeError("injected failure")

    ed.trace_batch = flaky


def _restore_and_report():
    import owcsim.engine.run.execution_dask as ed
    from owcsim.engine.integrator.kernel import trace_batch

    still_armed = ed.trace_batch is not trace_batch
    ed.trace_batch = trace_batch
    return still_armed


def test_failed_task_is_retried_with_the_same_result(client, dask):
    doc = _doc(paths=8192, batch_size=1024, direction="backward", seed=5)
    client.run(_fail_first_call)
    try:
        on_dask = simulate(spec(doc), executor=dask)
    finally:
        armed = client.run(_restore_and_report)
    assert not all(armed.values())  # at least one worker's failure fired and was retried
    assert _strip(on_dask) == _strip(simulate(spec(doc)))


def _reruns(dask_scheduler):
    """Batch tasks the scheduler sent to a worker more than once (recent transitions)."""
    counts = {}
    for t in dask_scheduler.transition_log:
        if str(t[0]).startswith(BATCH_PREFIX) and t[2] == "processing":
            counts[t[0]] = counts.get(t[0], 0) + 1
    return sorted(str(k) for k, n in counts.items() if n > 1)


def test_worker_killed_mid_job_still_exact(client, dask):
    doc = _doc(paths=60 * 2048, batch_size=2048, direction="forward", seed=3)
    pids = client.run(os.getpid)
    killed = []

    def kill_one_busy_worker(p):
        if p.batches == 4 and not killed:
            busy = [w for w, keys in client.processing().items() if any(str(k).startswith(BATCH_PREFIX) for k in keys)]
            victim = busy[0] if busy else next(iter(pids))
            os.kill(pids[victim], signal.SIGKILL)
            killed.append(victim)

    on_dask = simulate(spec(doc), executor=dask, progress=kill_one_busy_worker)
    assert killed
    assert client.run_on_scheduler(_reruns)  # the lost worker's batches ran again elsewhere
    assert on_dask["run"]["batches"] == 60 and on_dask["run"]["stop_reason"] == "paths"
    assert _strip(on_dask) == _strip(simulate(spec(doc)))
    client.wait_for_workers(2, timeout=60)
    assert pids[killed[0]] not in client.run(os.getpid).values()  # the nanny started a new process


def test_errors_without_dask_or_without_a_scheduler(monkeypatch):
    # The engine imports without Dask, and says how to install it.
    code = (
        "import sys; sys.modules['distributed'] = sys.modules['dask'] = None\n"
        "import owcsim.engine.run.simulate, owcsim.engine.run.execution_dask as ed\n"
        "try:\n    ed.executor_from_scheduler('tcp://127.0.0.1:8786')\n"
        "except ed.DaskUnavailableError as e:\n    print(e)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))),
    ).stdout
    assert "pip install 'owcsim[cluster]'" in out
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ImportError, match=r"owcsim\[cluster\]") as err:
        DaskExecutor("tcp://127.0.0.1:8786")
    assert isinstance(err.value, EngineError) and isinstance(err.value, DaskUnavailableError)
    monkeypatch.undo()
    # No scheduler listening: a located error, quickly.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t = time.monotonic()
    with pytest.raises(ClusterError, match=f"127.0.0.1:{port}"):
        executor_from_scheduler(f"tcp://127.0.0.1:{port}", timeout_s=1)
    assert time.monotonic() - t < 15


def test_executor_from_a_scheduler_address(client):
    """The address form opens (and closes) its own client."""
    doc = room_doc(paths=4096, batch_size=1024, direction="backward", seed=2)
    with executor_from_scheduler(client.scheduler.address) as ex:
        assert ex.workers == 2 and ex.window >= 4
        on_dask = simulate(spec(doc), executor=ex)
    assert ex._client.status == "closed"
    assert _strip(on_dask) == _strip(simulate(spec(doc)))


def test_command_line_scheduler_flag(client, tmp_path, capsys, monkeypatch):
    """`owcsim run --scheduler ADDRESS`: the same result.json numbers as one local process."""
    from owcsim.cli import main
    from tests.scenes import EXAMPLES

    barry = str(EXAMPLES / "barry_config_a.json")
    common = ["--paths", "4096", "--seed", "5", "--max-reflections", "2", "--set", "simulation.batch_size=1024"]
    assert main(["run", barry, "--out", str(tmp_path / "dask"), "--scheduler", client.scheduler.address, *common]) == 0
    assert main(["run", barry, "--out", str(tmp_path / "local"), *common]) == 0
    on_dask, local = (json.loads((tmp_path / d / "result.json").read_text()) for d in ("dask", "local"))
    assert on_dask["run"]["workers"] == 2
    assert _strip(on_dask) == _strip(local)
    # --scheduler and --workers exclude each other; an unreachable scheduler is a located error, exit 2
    with pytest.raises(SystemExit) as exit_:
        main(["run", barry, "--out", str(tmp_path / "x"), "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"])
    assert exit_.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    from owcsim.engine.run import execution_dask

    quick = functools.partial(execution_dask.executor_from_scheduler, timeout_s=1.0)  # not the default 30 s
    monkeypatch.setattr(execution_dask, "executor_from_scheduler", quick)
    assert main(["run", barry, "--out", str(tmp_path / "y"), "--scheduler", f"tcp://127.0.0.1:{port}"]) == 2
    assert f"127.0.0.1:{port}" in capsys.readouterr().err


def _batch_keys_done(dask_scheduler):
    """Keys of the batch tasks whose results reached memory, among the scheduler's recent transitions."""
    return sorted(
        {
            str(t[0])
            for t in list(dask_scheduler.transition_log)
            if str(t[0]).startswith(BATCH_PREFIX) and t[2] == "memory"
        }
    )


def test_service_sends_its_jobs_to_the_scheduler(client, tmp_path):
    """OWCSIM_SCHEDULER: a job runs its batches on the cluster and serves the engine's numbers."""
    from pydantic import ValidationError

    from owcsim.server.settings import Settings
    from tests.server.helpers import app_client, quick_doc, wait_for

    doc = quick_doc(paths=6000, max_reflections=2)
    with app_client(tmp_path, run_jobs=True, scheduler=client.scheduler.address) as c:
        # transition_log is a bounded deque (1000 entries): compare the sets of batch keys, not its length
        before = client.run_on_scheduler(_batch_keys_done)
        job = c.post("/v1/jobs", json=doc).json()
        done = wait_for(c, job["id"], ("succeeded", "failed"), timeout=120)
        assert done["status"] == "succeeded", done
        served = c.get(f"{job['url']}/result").json()

        ran_here = set(client.run_on_scheduler(_batch_keys_done)) - set(before)
        assert len(ran_here) >= 6, ran_here  # 6 batches of 1024 paths ran on the cluster
    assert served["run"]["workers"] == 2
    assert _strip(served) == _strip(simulate(spec(doc)))
    with pytest.raises(ValidationError, match="tcp://host:8786"):
        Settings(db=tmp_path / "j.sqlite", scheduler="127.0.0.1:8786")
