"""Faults and hostile clients against a real `owcsim serve` (issue 25, items 3, 4 and 5): the figures.

- disk full (item 3, root only: a tmpfs of 8 MiB filled while jobs run): CPU share of the server
  process while the disk is full, health's answer, tracebacks in its log, jobs finished once the
  space is back;
- slow bodies (item 4): 8 connections sending their bodies 1 byte every 0.5 s; the time a normal
  submission takes beside them;
- slow headers (item 5): 400 connections from one address (127.0.0.2) that never end their request
  head; 50 health checks from another address (127.0.0.1): answers and latency.

    .venv/bin/python benchmarks/service_faults.py [--root OTHER_CHECKOUT] [--only disk,bodies,headers]

`--root`: run the server of another checkout (e.g. `git archive main | tar -x -C /tmp/base`), with this
interpreter: the same script measures before and after.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import httpx  # noqa: E402

from tests.server.helpers import ServerProcess, quick_doc  # noqa: E402


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def disk_full(root: Path, tmp: Path) -> None:
    mnt = tmp / "small"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mnt)]).returncode:
        print("disk full: skipped (a tmpfs needs root)")
        return
    log = tmp / "disk.log"
    try:
        with ServerProcess(mnt / "jobs.sqlite", log=log, root=root, max_concurrent_jobs=1) as srv:
            ids = [
                httpx.post(f"{srv.url}/v1/jobs", json=quick_doc(paths=3_000_000, batch_size=4096, seed=i)).json()["id"]
                for i in range(3)
            ]
            with open(mnt / "filler", "wb", buffering=0) as f:
                try:
                    while True:
                        f.write(b"\0" * 65536)
                except OSError:
                    pass
            time.sleep(5)  # the running job ends meanwhile and tries to store its outcome
            cpu0, t0 = _cpu_s(srv.proc.pid), time.monotonic()
            time.sleep(5)
            share = (_cpu_s(srv.proc.pid) - cpu0) / (time.monotonic() - t0)
            h = httpx.get(f"{srv.url}/v1/health")
            reason = h.json().get("reason")
            sub = httpx.post(f"{srv.url}/v1/jobs", json=quick_doc(seed=99)).status_code
            (mnt / "filler").unlink()
            t0 = time.monotonic()
            while time.monotonic() - t0 < 90:
                states = [httpx.get(f"{srv.url}/v1/jobs/{i}").json()["status"] for i in ids]
                if all(s in ("succeeded", "failed", "cancelled") for s in states):
                    break
                time.sleep(0.5)
            back = time.monotonic() - t0
        text = log.read_text()
        print(
            f"disk full: server CPU {100 * share:.0f} % of a core over 5 s; health {h.status_code} ({reason}); "
            f"a submission {sub}; tracebacks in the log {text.count('Traceback')}; after the space came back "
            f"in {back:.1f} s: jobs {states}"
        )
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _from(port: int, address: str) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=10, source_address=(address, 0))


def slow_bodies(root: Path, tmp: Path) -> None:
    with ServerProcess(tmp / "bodies.sqlite", root=root) as srv:
        slow = [_from(srv.port, "127.0.0.2") for _ in range(8)]
        stop = threading.Event()
        for s in slow:
            s.sendall(
                b"POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 10000\r\n\r\n"
            )

        def trickle():
            while not stop.is_set():
                for s in slow:
                    try:
                        s.sendall(b" ")
                    except OSError:
                        pass
                stop.wait(0.5)

        threading.Thread(target=trickle, daemon=True).start()
        time.sleep(1.0)
        times = []
        for i in range(3):
            t0 = time.monotonic()
            r = httpx.post(f"{srv.url}/v1/jobs", json=quick_doc(seed=i), timeout=120)
            times.append((time.monotonic() - t0, r.status_code))
        stop.set()
        for s in slow:
            s.close()
    print("slow bodies: 3 normal submissions beside 8 slow bodies: " + ", ".join(f"{t:.2f} s ({c})" for t, c in times))


def slow_headers(root: Path, tmp: Path) -> None:
    with ServerProcess(tmp / "headers.sqlite", root=root) as srv:
        socks = [_from(srv.port, "127.0.0.2") for _ in range(400)]
        for s in socks:
            try:
                s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: x\r\n")
            except OSError:
                pass
        time.sleep(0.5)
        codes, took = [], []
        for _ in range(50):
            t0 = time.perf_counter()
            with httpx.Client(timeout=10) as h:
                codes.append(h.get(f"{srv.url}/v1/health").status_code)
            took.append(time.perf_counter() - t0)
        for s in socks:
            s.close()
    counts = {c: codes.count(c) for c in sorted(set(codes))}
    print(
        f"slow headers: 400 slow-header connections from one address; 50 health checks from another: {counts}, "
        f"p50 {1e3 * statistics.median(took):.1f} ms, max {1e3 * max(took):.1f} ms"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=ROOT, help="checkout whose server runs (default: this one)")
    ap.add_argument("--only", default="disk,bodies,headers")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="owcsim-faults-"))
    try:
        for name, run in (("disk", disk_full), ("bodies", slow_bodies), ("headers", slow_headers)):
            if name in args.only.split(","):
                run(args.root.resolve(), tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
