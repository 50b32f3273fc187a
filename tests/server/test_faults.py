"""Issue 25, items 3, 4, 5, 10, 11, 13: faults of the disk and the store, slow and greedy clients.

Each test fails on the service before the change (the report of the change says how it was checked).
Fast ones inject the fault (SQLite's "database or disk is full") in-process; the ones marked slow use
a real `owcsim serve`, a small tmpfs (root only, skipped otherwise) and raw sockets on loopback.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import threading
import time

import httpx
import pytest

from owcsim.schemas import SceneSpec
from owcsim.server.store import JobStore, StoreError
from owcsim.server.worker import WorkerLimits, run_job

from .helpers import ROOT, ServerProcess, app_client, free_port, long_doc, quick_doc, wait_for

DISK_FULL = "database or disk is full"


def thread_cpu_s(tid: int) -> float:
    """CPU time (user + system) of one thread of this process [s] (/proc, clock-tick resolution)."""
    with open(f"/proc/self/task/{tid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def process_cpu_s(pid: int) -> float:
    """CPU time (user + system, all threads) of a process [s]."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _fail_while(monkeypatch, event: threading.Event, *names: str) -> None:
    """JobStore methods `names` raise SQLite's disk-full error while `event` is set."""
    for name in names:
        real = getattr(JobStore, name)

        def patched(self, *args, _real=real, **kwargs):
            if event.is_set():
                raise sqlite3.OperationalError(DISK_FULL)
            return _real(self, *args, **kwargs)

        monkeypatch.setattr(JobStore, name, patched)


# -- 3. disk full while jobs run ------------------------------------------------------------------------


def test_3_disk_full_a_dead_worker_does_not_spin_the_dispatcher(tmp_path, monkeypatch):
    """A worker dies while the store cannot be written: settling its run fails. The dispatcher must back
    off (the old one waited on the dead worker's sentinel again at once: 50-60 % of a core), health must
    say 503 with the reason, and the run is settled once there is space."""
    full = threading.Event()
    _fail_while(monkeypatch, full, "settle", "next_queued", "claim_next")
    with app_client(tmp_path, run_jobs=True) as c:
        job = c.post("/v1/jobs", json=long_doc()).json()
        wait_for(c, job["id"], "running")
        dispatcher = c.app.state.dispatcher
        deadline = time.monotonic() + 10
        while job["id"] not in dispatcher.running():
            assert time.monotonic() < deadline
            time.sleep(0.05)
        full.set()
        os.kill(dispatcher.running()[job["id"]], signal.SIGKILL)
        deadline = time.monotonic() + 5
        while (h := c.get("/v1/health")).status_code == 200:
            assert time.monotonic() < deadline, "health still 200 with the disk full"
            time.sleep(0.05)
        assert h.status_code == 503 and "disk full" in h.json()["reason"] and h.headers["retry-after"]
        tid = dispatcher._thread.native_id
        cpu0, t0 = thread_cpu_s(tid), time.monotonic()
        time.sleep(2.0)
        share = (thread_cpu_s(tid) - cpu0) / (time.monotonic() - t0)
        assert share < 0.10, f"the dispatcher used {100 * share:.0f} % of a core while the disk was full"
        store = c.app.state.store
        assert store.get(job["id"]).crashes == 0  # not settled yet
        full.clear()
        deadline = time.monotonic() + 15
        while store.get(job["id"]).crashes != 1:  # settled: retried after the worker's death
            assert time.monotonic() < deadline, "the dead run was not settled once there was space"
            time.sleep(0.1)
        while (h := c.get("/v1/health")).status_code != 200:  # the next pass of the dispatcher
            assert time.monotonic() < deadline, h.text
            time.sleep(0.1)
        c.post(f"/v1/jobs/{job['id']}/cancel")


def test_3_disk_full_a_worker_waits_to_store_its_outcome(tmp_path, monkeypatch, caplog):
    """The worker's progress and outcome writes fail with a full disk: the run goes on, its outcome is
    stored when there is space, one warning each and no traceback (the old worker raised out of run_job)."""
    store = JobStore(tmp_path / "jobs.sqlite")
    scene = SceneSpec.model_validate(quick_doc(paths=4096)).model_dump_json()
    store.submit(owner="o", scene_json=scene, name=None, request_hash="h", idempotency_key=None, max_queued=10)
    job_id, token = store.claim_next()
    left = {"progress": 2, "finish": 3}
    for name in left:
        real = getattr(JobStore, name)

        def failing(self, *args, _real=real, _name=name, **kwargs):
            if left[_name]:
                left[_name] -= 1
                raise sqlite3.OperationalError(DISK_FULL)
            return _real(self, *args, **kwargs)

        monkeypatch.setattr(JobStore, name, failing)
    lifeline_r, lifeline_w = mp.Pipe(duplex=False)
    sigint = signal.getsignal(signal.SIGINT)
    caplog.set_level(logging.WARNING)
    try:
        run_job(str(store.path), job_id, token, WorkerLimits(1, 60.0, 1e-6), lifeline_r)
    finally:
        signal.signal(signal.SIGINT, sigint)
        lifeline_w.close()
    assert left == {"progress": 0, "finish": 0}
    row = store.get(job_id)
    assert row.status == "succeeded" and row.has_result, row
    mine = [r for r in caplog.records if r.name.startswith("owcsim")]
    assert not any(r.exc_info for r in mine), [r.getMessage() for r in mine if r.exc_info]
    assert sum("disk is full" in r.getMessage() for r in mine) == 2, [r.getMessage() for r in mine]
    store.close()


@pytest.fixture
def small_disk(tmp_path):
    """A tmpfs of 8 MiB (root and mount(8) needed: skipped otherwise), unmounted afterwards."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("a tmpfs needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mnt)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"mount refused: {done.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def fill(directory) -> int:
    """Write a file in `directory` until the disk is full; returns its size [bytes]."""
    size = 0
    with open(directory / "filler", "wb", buffering=0) as f:
        try:
            while True:
                size += f.write(b"\0" * 65536)
        except OSError:
            pass
    return size


@pytest.mark.slow
def test_3_a_really_full_disk_idle_503_and_jobs_finish_when_space_returns(tmp_path, small_disk):
    """A real full disk (tmpfs): the server stays idle (< 10 % of a core), health is 503 with the reason,
    submissions 507, no traceback in the log; every job succeeds once the space is back."""
    log = tmp_path / "server.log"
    with ServerProcess(small_disk / "jobs.sqlite", log=log, max_concurrent_jobs=1) as srv:
        ids = [
            httpx.post(f"{srv.url}/v1/jobs", json=quick_doc(paths=3_000_000, batch_size=4096, seed=i)).json()["id"]
            for i in range(3)
        ]
        fill(small_disk)
        deadline = time.monotonic() + 10
        while (h := httpx.get(f"{srv.url}/v1/health")).status_code == 200:
            assert time.monotonic() < deadline, "health still 200 with the disk full"
            time.sleep(0.1)
        assert h.status_code == 503 and "disk full" in h.json()["reason"], h.text
        r = httpx.post(f"{srv.url}/v1/jobs", json=quick_doc(seed=99))
        assert r.status_code in (503, 507) and r.headers["retry-after"], r.text
        time.sleep(3)  # the running job has ended meanwhile and waits to store its outcome
        cpu0, t0 = process_cpu_s(srv.proc.pid), time.monotonic()
        time.sleep(3)
        share = (process_cpu_s(srv.proc.pid) - cpu0) / (time.monotonic() - t0)
        assert share < 0.10, f"the server used {100 * share:.0f} % of a core while the disk was full"
        (small_disk / "filler").unlink()
        deadline = time.monotonic() + 90
        for job_id in ids:
            while (job := httpx.get(f"{srv.url}/v1/jobs/{job_id}").json())["status"] != "succeeded":
                assert job["status"] in ("queued", "running") and time.monotonic() < deadline, job
                time.sleep(0.2)
        assert httpx.get(f"{srv.url}/v1/health").status_code == 200
    text = log.read_text()
    assert "Traceback" not in text, text[text.index("Traceback") - 500 :][:3000]


# -- 10. one server per store file, whatever its name ---------------------------------------------------


def test_10_a_second_server_through_a_hard_link_refuses_to_start(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with app_client(tmp_path / "a"):
        os.link(tmp_path / "a" / "jobs.sqlite", tmp_path / "b" / "other.sqlite")
        with pytest.raises(StoreError, match="in use by another owcsim server"):
            JobStore(tmp_path / "b" / "other.sqlite", server=True)
    JobStore(tmp_path / "b" / "other.sqlite", server=True).close()  # free once the first has stopped


# -- 11. a damaged store: clear errors, at start and while running ------------------------------------


def test_11_a_folder_in_the_stores_place_is_a_clear_error(tmp_path, capsys):
    from owcsim.cli import main

    (tmp_path / "jobs.sqlite").mkdir()
    with pytest.raises(StoreError, match="is a folder"):
        JobStore(tmp_path / "jobs.sqlite", server=True)
    assert main(["serve", "--db", str(tmp_path / "jobs.sqlite"), "--port", "9"]) == 2
    err = capsys.readouterr().err
    assert "is a folder" in err and "Traceback" not in err


def test_11_a_symbolic_link_loop_in_the_stores_place_is_a_clear_error(tmp_path, capsys):
    """A store path that is a loop of symbolic links: one line and exit status 2 (it was a RuntimeError's
    traceback from resolving the path)."""
    from owcsim.cli import main

    os.symlink(tmp_path / "jobs.sqlite", tmp_path / "jobs.sqlite")
    assert main(["serve", "--db", str(tmp_path / "jobs.sqlite"), "--port", "9"]) == 2
    err = capsys.readouterr().err
    assert "jobs.sqlite" in err and "symbolic link" in err and "Traceback" not in err


def test_11_an_empty_file_is_not_silently_an_empty_store(tmp_path, caplog):
    (tmp_path / "jobs.sqlite").write_bytes(b"")
    with pytest.raises(StoreError, match=r"empty file \(0 bytes\)"):
        JobStore(tmp_path / "jobs.sqlite", server=True)
    assert (tmp_path / "jobs.sqlite").stat().st_size == 0  # left as it was
    caplog.set_level(logging.WARNING)
    JobStore(tmp_path / "new.sqlite", server=True).close()  # a new store is started, and said so
    assert any("did not exist: started an empty one" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("how", ["overwritten", "replaced", "symlinked"])
def test_11_a_store_overwritten_while_running_is_503_and_health_says_so(tmp_path, how):
    with app_client(tmp_path, run_jobs=True) as c:
        job = c.post("/v1/jobs", json=quick_doc()).json()
        wait_for(c, job["id"], "succeeded")
        assert c.get("/v1/health").status_code == 200
        path = tmp_path / "jobs.sqlite"
        if how == "overwritten":  # e.g. a restore copied over the live file: the same inode, other bytes
            with open(path, "r+b") as f:
                f.write(b"\0" * path.stat().st_size)
        elif how == "replaced":  # another file moved into its place
            (tmp_path / "other").write_bytes(b"not a store " * 1000)
            os.replace(tmp_path / "other", path)
        else:  # a symbolic link to a copy of the store: a valid SQLite file with the same jobs, but not the one locked
            shutil.copyfile(path, tmp_path / "copy.sqlite")
            os.symlink(tmp_path / "copy.sqlite", tmp_path / "link")
            os.replace(tmp_path / "link", path)
            how = "replaced"
        deadline = time.monotonic() + 5
        while (h := c.get("/v1/health")).status_code == 200:
            assert time.monotonic() < deadline, "health still 200"
            time.sleep(0.05)
        assert h.status_code == 503 and how in h.json()["reason"], h.text
        for url in ("/v1/jobs", f"/v1/jobs/{job['id']}", f"/v1/jobs/{job['id']}/result"):
            r = c.get(url)
            assert r.status_code == 503 and r.json()["type"].endswith("store-damaged"), (url, r.text)
            assert how in r.json()["detail"] and r.headers["retry-after"]


# -- 4, 5, 13. slow and greedy clients (a real server, raw sockets from other loopback addresses) ------


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    """Default connection limits (200 connections, 50 per client address, 30 s for a body, 10 s for headers);
    bodies of at most 1 MiB, 1.5 MiB of them in memory at once."""
    tmp = tmp_path_factory.mktemp("faults")
    with ServerProcess(tmp / "jobs.sqlite", max_body_bytes=1 << 20, body_memory_bytes=3 << 19) as s:
        yield s


def _connect_from(srv, address: str) -> socket.socket:
    """A connection to the server from another loopback address (another client, as the server sees it)."""
    return socket.create_connection(("127.0.0.1", srv.port), timeout=10, source_address=(address, 0))


def _answer(sock: socket.socket, limit_s: float = 5.0) -> bytes:
    """One answer: its head, and its body when it says its length (else up to the end of the connection)."""
    sock.settimeout(limit_s)
    out = b""
    try:
        while chunk := sock.recv(65536):
            out += chunk
            head, blank, body = out.partition(b"\r\n\r\n")
            lengths = [ln for ln in head.lower().split(b"\r\n") if ln.startswith(b"content-length:")]
            if blank and lengths and len(body) >= int(lengths[0].split(b":")[1]):
                break
    except (TimeoutError, ConnectionResetError):
        pass
    return out


def _post_head(length: int, path: str = "/v1/jobs") -> bytes:
    return (
        b"POST " + path.encode() + b" HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
        b"Content-Length: " + str(length).encode() + b"\r\n\r\n"
    )


#: the routes that take a scene document: submissions and the pre-flight without a job share slots and budget
SCENE_ROUTES = ("/v1/jobs", "/v1/preflight")


@pytest.mark.parametrize("path", SCENE_ROUTES)
def test_4_slow_bodies_do_not_hold_up_a_normal_submission(srv, path):
    """8 clients send their bodies 1 byte at a time: a normal submission is answered at once (the old
    service gave each slow body one of its 6 submission slots: it waited until their 30 s deadline; POST
    /v1/preflight still took its slot before the body: 29.4 s)."""
    slow = [_connect_from(srv, "127.0.0.2") for _ in range(8)]
    stop = threading.Event()

    def trickle():
        while not stop.is_set():
            for s in slow:
                try:
                    s.sendall(b" ")
                except OSError:
                    pass
            stop.wait(0.5)

    try:
        for s in slow:
            s.sendall(_post_head(10_000, path))
        feeder = threading.Thread(target=trickle, daemon=True)
        feeder.start()
        time.sleep(1.0)  # every slow body has started
        t0 = time.monotonic()
        r = httpx.post(f"{srv.url}/v1/jobs", json=quick_doc(seed=4), timeout=60)
        took = time.monotonic() - t0
        assert r.status_code == 202, r.text
        assert took < 5.0, f"a normal submission took {took:.1f} s behind 8 slow bodies"
    finally:
        stop.set()
        for s in slow:
            s.close()


@pytest.mark.parametrize("path", SCENE_ROUTES)
def test_4_bodies_in_memory_are_bounded_and_the_one_past_it_gets_503(srv, path):
    """Two bodies of 0.9 MiB arrive (1.5 MiB may be held): the second is refused 503 with Retry-After, and
    a small submission still gets through beside the first (POST /v1/preflight's bodies were not counted)."""
    first, second = _connect_from(srv, "127.0.0.5"), _connect_from(srv, "127.0.0.6")
    part = b" " * 900_000
    try:
        first.sendall(_post_head(1_000_000, path) + part)
        time.sleep(0.5)
        second.sendall(_post_head(1_000_000, path))
        try:
            second.sendall(part)
        except OSError:
            pass
        answer = _answer(second)
        assert answer.startswith(b"HTTP/1.1 503"), answer[:300]
        assert b"retry-after" in answer.lower() and b"body_memory_bytes" in answer, answer[:600]
        r = httpx.post(f"{srv.url}/v1/jobs", json=quick_doc(seed=5), timeout=30)
        assert r.status_code == 202, r.text
    finally:
        first.close()
        second.close()


def test_5_one_client_address_cannot_fill_the_connection_cap(srv):
    """400 slow-header connections from one address: beyond 50 they get 503 + Retry-After at once, and
    health checks from another address are all answered 200 (the old service: 118 of 143 got 503)."""
    socks = [_connect_from(srv, "127.0.0.3") for _ in range(400)]
    try:
        for s in socks:
            try:
                s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\n")  # a head that never ends
            except OSError:
                pass
        time.sleep(0.5)
        codes = []
        for _ in range(50):
            with httpx.Client(timeout=10) as h:  # a new connection each time, as a load balancer's probe
                codes.append(h.get(f"{srv.url}/v1/health").status_code)
        assert codes == [200] * 50, {c: codes.count(c) for c in set(codes)}
        refused = _answer(socks[-1], 3)
        assert refused.startswith(b"HTTP/1.1 503") and b"retry-after: 1" in refused.lower(), refused[:300]
        assert b"max_connections_per_client" in refused
    finally:
        for s in socks:
            s.close()


def test_13_a_request_head_over_64_kib_is_refused_even_when_it_arrives_at_once(srv):
    for size, expected in ((70_000, b"HTTP/1.1 431"), (100_000, b"HTTP/1.1 431"), (60_000, b"HTTP/1.1 200")):
        with _connect_from(srv, "127.0.0.4") as s:
            s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * size + b"\r\n\r\n")
            answer = _answer(s)
        assert answer.startswith(expected), (size, answer[:200])


# -- 5. the reverse proxy in front of the service (docker/nginx/owcsim.conf) -------------------------------

NGINX_CONF = ROOT / "docker" / "nginx" / "owcsim.conf"


@pytest.fixture(scope="module")
def proxied(tmp_path_factory):
    """`owcsim serve` (its per-address cap off, as the configuration says) behind nginx running the
    repository's configuration; skipped only where nginx is not installed."""
    nginx = shutil.which("nginx") or next((p for p in ("/usr/sbin/nginx",) if os.path.exists(p)), None)
    if nginx is None:
        pytest.skip("nginx is not installed (apt-get install -y nginx)")
    tmp = tmp_path_factory.mktemp("proxy")
    with ServerProcess(tmp / "jobs.sqlite", max_connections_per_client=0) as srv:
        port = free_port()
        conf = NGINX_CONF.read_text()
        assert "server 127.0.0.1:8000;" in conf and "listen 8080;" in conf
        conf = conf.replace("server 127.0.0.1:8000;", f"server 127.0.0.1:{srv.port};")
        (tmp / "owcsim.conf").write_text(conf.replace("listen 8080;", f"listen 127.0.0.1:{port};"))
        temp = " ".join(f"{k}_temp_path {tmp / k};" for k in ("client_body", "proxy", "fastcgi", "uwsgi", "scgi"))
        (tmp / "nginx.conf").write_text(
            f"worker_processes 1; pid {tmp / 'nginx.pid'}; events {{ worker_connections 1024; }}\n"
            f"http {{ access_log off; {temp} include {tmp / 'owcsim.conf'}; }}\n"
        )
        cmd = [nginx, "-p", str(tmp), "-e", str(tmp / "error.log"), "-c", str(tmp / "nginx.conf")]
        proc = subprocess.Popen([*cmd, "-g", "daemon off; master_process off;"], stderr=subprocess.PIPE)
        url = f"http://127.0.0.1:{port}"
        try:
            deadline = time.monotonic() + 10
            while True:
                assert proc.poll() is None, proc.stderr.read().decode()
                try:
                    httpx.get(f"{url}/v1/version", timeout=1)
                    break
                except httpx.TransportError:
                    assert time.monotonic() < deadline, "nginx did not start"
                    time.sleep(0.1)
            yield url, port
        finally:
            proc.terminate()
            proc.wait(10)


def test_5_the_proxy_configuration_passes_requests_and_holds_its_limits(proxied):
    url, port = proxied
    assert httpx.get(f"{url}/v1/health").status_code == 200
    r = httpx.post(f"{url}/v1/jobs", json=quick_doc(seed=7))
    assert r.status_code == 202 and r.headers["location"].startswith("/v1/jobs/"), r.text
    assert httpx.get(url + r.headers["location"]).json()["id"] == r.json()["id"]
    # a body over client_max_body_size (owcsim's max_body_bytes): 413 from its Content-Length
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(_post_head(40 * 2**20))
        assert _answer(s).startswith(b"HTTP/1.1 413")
    # a header line over large_client_header_buffers (16 KiB): refused by nginx
    r = httpx.get(f"{url}/v1/health", headers={"X-Big": "a" * 20_000})
    assert r.status_code in (400, 431, 494), r.status_code
    # slow bodies are buffered by nginx: a normal submission beside 8 of them is answered at once
    slow = [_connect_from_port(port, "127.0.0.2") for _ in range(8)]
    try:
        for s in slow:
            s.sendall(_post_head(10_000) + b" ")
        time.sleep(0.5)
        t0 = time.monotonic()
        assert httpx.post(f"{url}/v1/jobs", json=quick_doc(seed=8), timeout=60).status_code == 202
        assert time.monotonic() - t0 < 5.0
    finally:
        for s in slow:
            s.close()
    # limit_conn: 20 requests at once from one address (bodies still arriving); the 21st gets 503
    held = [_connect_from_port(port, "127.0.0.3") for _ in range(20)]
    try:
        for s in held:
            s.sendall(_post_head(10_000) + b" ")
        time.sleep(0.5)
        with _connect_from_port(port, "127.0.0.3") as s:
            s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\n\r\n")
            assert _answer(s).startswith(b"HTTP/1.1 503")
        with _connect_from_port(port, "127.0.0.4") as s:  # another address is not affected
            s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
            assert _answer(s).startswith(b"HTTP/1.1 200")
    finally:
        for s in held:
            s.close()


def _connect_from_port(port: int, address: str) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=10, source_address=(address, 0))
