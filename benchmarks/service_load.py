"""Load figures of the HTTP service: 50 clients submitting jobs and downloading results, health polled.

A real `owcsim serve` on 127.0.0.1 (2 jobs at once, a queue of 50 so clients meet 429 and
retry). Each of CLIENTS threads submits PER_CLIENT small jobs with the Python client, and
after each submission downloads a finished job's result (JSON, CSV, NPZ or PNG in turn) and
polls a job's status; one large result (900 links x 200 bins, ~19 MB of CSV) is in the mix.
A monitor calls /v1/health every 0.1 s; the server process's RSS is sampled every 0.05 s.
Prints throughput, latency percentiles of submit (incl. its 429 retries), result GETs,
status GETs and health, the 429s met, and the server's peak RSS.

    .venv/bin/python benchmarks/service_load.py [--clients 50] [--per-client 6] [--baseline /work/main]

`--baseline DIR`: run the same load against the server of another checkout too (its own
.venv), e.g. the code before issue 11, and print both.
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import httpx  # noqa: E402

from benchmarks._common import rss_mb  # noqa: E402
from owcsim.clients import Client, RetryPolicy  # noqa: E402
from tests.server.helpers import ServerProcess, quick_doc  # noqa: E402


def pct(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(round(q / 100 * (len(values) - 1))))] if values else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--per-client", type=int, default=6)
    ap.add_argument("--baseline", type=Path, help="another checkout to measure the same way")
    args = ap.parse_args()
    failed = run(args, ROOT, sys.executable, "this checkout")
    if args.baseline:
        failed |= run(args, args.baseline, str(args.baseline / ".venv" / "bin" / "python"), f"baseline {args.baseline}")
    return failed


def run(args, root: Path, python: str, label: str) -> int:
    print(f"--- {label}", flush=True)
    tmp = Path(tempfile.mkdtemp(prefix="owcsim-load-"))
    lat: dict[str, list[float]] = {"submit": [], "result": [], "status": [], "health": []}
    statuses: dict[int, int] = {}
    lock = threading.Lock()
    done_ids: list[str] = []
    errors: list[str] = []

    def count(response):
        with lock:
            statuses[response.status_code] = statuses.get(response.status_code, 0) + 1

    with ServerProcess(
        tmp / "jobs.sqlite",
        root=root,
        python=python,
        max_concurrent_jobs=2,
        max_queued_jobs=50,
        retry_after_s=1,
        max_queued_per_key=50,
        max_connections=500,
        max_connections_per_client=0,  # every client is 127.0.0.1 here
    ) as srv:
        big = quick_doc(paths=1024, direction="forward", t_max_s=2e-7)
        big["receivers"] = []
        big["receiver_grids"] = [
            {"id_prefix": "g", "origin": [0.5, 0.5, 0.0], "size": [4.0, 4.0], "spacing": 4.0 / 29, "area": 1e-4}
        ]
        with Client(srv.url) as owc:
            big_job = owc.submit(big)
            big_job.wait(timeout=300)
        done_ids.append(big_job.id)
        stop = threading.Event()
        peak = [rss_mb(srv.proc.pid)]

        def sampler():
            while not stop.is_set():
                peak[0] = max(peak[0], rss_mb(srv.proc.pid))
                time.sleep(0.05)

        def monitor():
            with httpx.Client(base_url=srv.url, timeout=30) as h:
                while not stop.is_set():
                    t0 = time.perf_counter()
                    r = h.get("/v1/health")
                    with lock:
                        lat["health"].append(time.perf_counter() - t0)
                    if r.status_code != 200:
                        errors.append(f"health {r.status_code}")
                    time.sleep(0.1)

        def client(i: int):
            rng = random.Random(i)
            suffixes = ["result", "result.csv", "result.npz", "plot.png"]
            try:
                http = httpx.Client(base_url=srv.url, timeout=120, event_hooks={"response": [count]})
                with (
                    Client(srv.url, retry=RetryPolicy(retries=200, backoff_s=0.2, max_backoff_s=2.0), http=http) as owc,
                    httpx.Client(base_url=srv.url, timeout=120) as h,
                ):
                    for k in range(args.per_client):
                        t0 = time.perf_counter()
                        job = owc.submit(quick_doc(seed=i * 1000 + k))
                        with lock:
                            lat["submit"].append(time.perf_counter() - t0)
                        t0 = time.perf_counter()
                        h.get(f"/v1/jobs/{job.id}")
                        with lock:
                            lat["status"].append(time.perf_counter() - t0)
                            pick = rng.choice(done_ids)
                        t0 = time.perf_counter()
                        with h.stream("GET", f"/v1/jobs/{pick}/{suffixes[k % 4]}") as r:
                            for _ in r.iter_raw():
                                pass
                        with lock:
                            lat["result"].append(time.perf_counter() - t0)
                        if r.status_code != 200:
                            errors.append(f"result {r.status_code}")
                        finished = len(done_ids) < 20 and job.refresh().status == "succeeded"
                        if finished:
                            with lock:
                                done_ids.append(job.id)
            except Exception as exc:  # noqa: BLE001
                errors.append(repr(exc))

        threads = [threading.Thread(target=f) for f in (sampler, monitor)]
        for t in threads:
            t.start()
        workers = [threading.Thread(target=client, args=(i,)) for i in range(args.clients)]
        t0 = time.perf_counter()
        for t in workers:
            t.start()
        for t in workers:
            t.join()
        t_submitted = time.perf_counter() - t0
        with httpx.Client(base_url=srv.url, timeout=30) as h:
            while h.get("/v1/health").json()["queued"] or h.get("/v1/health").json()["running"]:
                time.sleep(0.1)
        t_all = time.perf_counter() - t0
        stop.set()
        for t in threads:
            t.join()
    n = args.clients * args.per_client
    print(
        f"{args.clients} clients x {args.per_client} jobs = {n} jobs, each followed by a status GET and a result "
        "download (JSON/CSV/NPZ/PNG in turn, one 19 MB CSV result among the finished jobs)"
    )
    print(
        f"submissions accepted per second: {n / t_submitted:.1f} ({n} in {t_submitted:.1f} s); all done after "
        f"{t_all:.1f} s ({n / t_all:.1f} jobs/s)"
    )
    for name in ("submit", "status", "result", "health"):
        v = lat[name]
        print(
            f"{name:7s} latency p50 / p95 / p99 / max: {pct(v, 50) * 1e3:7.0f} / {pct(v, 95) * 1e3:7.0f} / "
            f"{pct(v, 99) * 1e3:7.0f} / {max(v) * 1e3:7.0f} ms  ({len(v)} requests)"
        )
    print(
        f"429 answers met (and retried): {statuses.get(429, 0)}; 5xx: {sum(c for s, c in statuses.items() if s >= 500)}"
    )
    print(f"server peak RSS: {peak[0]:.0f} MB (the server process; workers and pre-flights are separate)")
    if errors:
        print(f"errors: {len(errors)}: {errors[:5]}")
    sys.stdout.flush()
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
