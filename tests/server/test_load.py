"""Load: 200 submissions from 20 concurrent clients against a real server on 127.0.0.1.

The queue is kept short (50) so that clients meet 429 + Retry-After and must retry.
Every job must be accounted for (200 distinct ids, all succeeded, all listed), and the
server must stay responsive: a monitor polls /v1/health throughout. Bounded: 200 jobs,
at most LOAD_TIMEOUT_S. The figures are printed (run with -s to see them).
"""

import statistics
import threading
import time

import httpx
import pytest

from owcsim.clients import Client, RetryPolicy

from .helpers import ServerProcess, quick_doc

CLIENTS, PER_CLIENT = 20, 10
LOAD_TIMEOUT_S = 150.0


def _pct(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, int(round(q / 100 * (len(values) - 1))))]


@pytest.mark.slow
def test_200_submissions_from_20_clients(tmp_path):
    statuses: dict[int, int] = {}
    lock = threading.Lock()

    def count(response):
        with lock:
            statuses[response.status_code] = statuses.get(response.status_code, 0) + 1

    with ServerProcess(tmp_path / "jobs.sqlite", max_concurrent_jobs=2, max_queued_jobs=50, retry_after_s=1) as srv:
        submitted: list[tuple[str, float]] = []
        errors: list[BaseException] = []
        health: list[float] = []
        stop = threading.Event()
        t_end = time.monotonic() + LOAD_TIMEOUT_S

        def monitor():
            with httpx.Client(base_url=srv.url, timeout=10) as h:
                while not stop.is_set() and time.monotonic() < t_end:
                    t0 = time.perf_counter()
                    r = h.get("/v1/health")
                    health.append(time.perf_counter() - t0)
                    assert r.status_code == 200
                    time.sleep(0.1)

        def client(i: int):
            try:
                http = httpx.Client(base_url=srv.url, timeout=30, event_hooks={"response": [count]})
                with Client(
                    srv.url, retry=RetryPolicy(retries=100, backoff_s=0.2, max_backoff_s=2.0), http=http
                ) as owc:
                    for k in range(PER_CLIENT):
                        t0 = time.perf_counter()
                        job = owc.submit(quick_doc(seed=i * PER_CLIENT + k))
                        with lock:
                            submitted.append((job.id, time.perf_counter() - t0))
                http.close()
            except BaseException as exc:  # reported below
                errors.append(exc)

        mon = threading.Thread(target=monitor, daemon=True)
        mon.start()
        t0 = time.perf_counter()
        threads = [threading.Thread(target=client, args=(i,)) for i in range(CLIENTS)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(max(0.0, t_end - time.monotonic()))
        t_submitted = time.perf_counter() - t0
        assert not errors, errors[:3]
        assert not any(t.is_alive() for t in threads), "submissions did not finish in time"

        with Client(srv.url) as owc:
            while True:
                done = {j.id: j.status for j in owc.jobs(status=["succeeded", "failed", "cancelled"])}
                if len(done) >= CLIENTS * PER_CLIENT or time.monotonic() > t_end:
                    break
                time.sleep(0.25)
            t_all = time.perf_counter() - t0
            stop.set()
            mon.join()
            listed = {j.id: j.status for j in owc.jobs()}

    ids = [i for i, _ in submitted]
    latency = [s for _, s in submitted]
    assert len(ids) == len(set(ids)) == CLIENTS * PER_CLIENT  # no duplicate, none lost
    assert set(listed) == set(ids) and set(listed.values()) == {"succeeded"}
    assert statuses.get(500, 0) == 0
    assert len(health) >= 10 and max(health) < 2.0, f"health check took up to {max(health):.2f} s"
    print(
        f"\nload: {len(ids)} jobs from {CLIENTS} clients; submitted in {t_submitted:.1f} s "
        f"({len(ids) / t_submitted:.1f} submissions/s), all {len(listed)} succeeded after {t_all:.1f} s "
        f"({len(ids) / t_all:.1f} jobs/s)"
    )
    print(
        f"load: submit latency incl. retries p50 {_pct(latency, 50):.3f} s, p95 {_pct(latency, 95):.3f} s, "
        f"p99 {_pct(latency, 99):.3f} s, max {max(latency):.3f} s; answers {dict(sorted(statuses.items()))}"
    )
    print(
        f"load: /v1/health during the run ({len(health)} probes): p50 {1e3 * statistics.median(health):.1f} ms, "
        f"p99 {1e3 * _pct(health, 99):.1f} ms, max {1e3 * max(health):.1f} ms"
    )


@pytest.mark.slow
def test_health_answers_while_60_clients_download_large_results(tmp_path):
    """Issue 11, item 3: 60 concurrent CSV downloads of a result of 900 links x 200 bins (~19 MB each)
    must not hold up /v1/health (the old routes rendered each CSV in the shared thread pool: 60 s)."""
    doc = quick_doc(paths=1024, direction="forward", t_max_s=2e-7)
    doc["receivers"] = []
    doc["receiver_grids"] = [
        {"id_prefix": "g", "origin": [0.5, 0.5, 0.0], "size": [4.0, 4.0], "spacing": 4.0 / 29, "area": 1e-4}
    ]
    with ServerProcess(tmp_path / "jobs.sqlite", max_connections=500, max_connections_per_client=0) as srv:
        with Client(srv.url) as owc:
            job = owc.submit(doc)
            job.wait(timeout=120)
        url = f"{srv.url}/v1/jobs/{job.id}/result.csv"
        health: list[float] = []
        failures: list[str] = []
        stop = threading.Event()

        def download():
            try:
                with httpx.Client(timeout=120, headers={"Accept-Encoding": "identity"}) as h:
                    for _ in range(2):
                        with h.stream("GET", url) as r:
                            assert r.status_code == 200
                            for _chunk in r.iter_raw():
                                pass
            except Exception as exc:  # noqa: BLE001
                failures.append(repr(exc))

        def monitor():
            with httpx.Client(base_url=srv.url, timeout=30) as h:
                while not stop.is_set():
                    t0 = time.perf_counter()
                    assert h.get("/v1/health").status_code == 200
                    health.append(time.perf_counter() - t0)
                    time.sleep(0.05)

        mon = threading.Thread(target=monitor)
        mon.start()
        threads = [threading.Thread(target=download) for _ in range(60)]
        t0 = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.perf_counter() - t0
        stop.set()
        mon.join()
    print(
        f"\n60 clients x 2 CSV downloads in {wall:.1f} s; /v1/health p50 {_pct(health, 50) * 1e3:.0f} ms, "
        f"p99 {_pct(health, 99) * 1e3:.0f} ms, max {max(health) * 1e3:.0f} ms over {len(health)} calls"
    )
    assert not failures, failures[:3]
    assert max(health) < 2.0  # the container's health check allows 5 s


@pytest.mark.slow
def test_submissions_and_health_under_slow_and_greedy_clients(tmp_path):
    """Issue 25, items 4 and 5, under load: 10 clients submit 50 jobs while 300 connections from another
    address never end their request heads and 8 send their bodies 1 byte every 0.5 s. Every job succeeds,
    health answers 200 throughout, no submission waits behind a slow body."""
    import socket

    with ServerProcess(tmp_path / "jobs.sqlite", max_concurrent_jobs=2) as srv:

        def attacker(address: str) -> socket.socket:
            return socket.create_connection(("127.0.0.1", srv.port), timeout=10, source_address=(address, 0))

        heads = [attacker("127.0.0.2") for _ in range(300)]
        bodies = [attacker("127.0.0.3") for _ in range(8)]
        stop = threading.Event()

        def hostile():
            for s in heads:
                try:
                    s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\n")
                except OSError:
                    pass
            for s in bodies:
                s.sendall(b"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n")
                s.sendall(b"Content-Length: 100000\r\n\r\n")
            while not stop.wait(0.5):
                for s in bodies:
                    try:
                        s.sendall(b" ")
                    except OSError:
                        pass

        health: list[tuple[int, float]] = []
        latency: list[float] = []
        errors: list[BaseException] = []
        lock = threading.Lock()

        def monitor():
            while not stop.is_set():
                t0 = time.perf_counter()
                with httpx.Client(timeout=10) as h:
                    code = h.get(f"{srv.url}/v1/health").status_code
                health.append((code, time.perf_counter() - t0))
                time.sleep(0.1)

        def client(i: int):
            try:
                with Client(srv.url, retry=RetryPolicy(retries=20, backoff_s=0.2, max_backoff_s=2.0)) as owc:
                    for k in range(5):
                        t0 = time.perf_counter()
                        owc.submit(quick_doc(seed=1000 + 5 * i + k))
                        with lock:
                            latency.append(time.perf_counter() - t0)
            except BaseException as exc:  # reported below
                errors.append(exc)

        side = [threading.Thread(target=f, daemon=True) for f in (hostile, monitor)]
        for t in side:
            t.start()
        time.sleep(1.0)
        threads = [threading.Thread(target=client, args=(i,)) for i in range(10)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        with Client(srv.url) as owc:
            deadline = time.monotonic() + 120
            while len(done := list(owc.jobs(status=["succeeded"]))) < 50 and time.monotonic() < deadline:
                time.sleep(0.5)
        stop.set()
        for t in side:
            t.join(15)
        for s in heads + bodies:
            s.close()
    assert not errors, errors[:3]
    assert len(latency) == 50 and len(done) == 50
    codes = [c for c, _ in health]
    assert codes and set(codes) == {200}, {c: codes.count(c) for c in set(codes)}
    print(
        f"\nslow and greedy clients: 50 submissions, p50 {_pct(latency, 50):.3f} s, max {max(latency):.3f} s; "
        f"health {len(health)} probes all 200, p99 {1e3 * _pct([t for _, t in health], 99):.0f} ms"
    )
    assert max(latency) < 10.0
