"""Hostile and large bodies against a real server (issue 25, items 1, 2, 9, 14): answer, time, memory, health.

A real `owcsim serve` on 127.0.0.1. Each case posts its body (`--copies` at once for the large
ones) while a monitor calls /v1/health every 0.05 s and samples the server process's RSS
(its own, not its pre-flight processes') every 0.02 s. Prints per case: the status and problem
type of the answer, its size, the time to answer, the server's RSS before and its peak, and
the health latency p99 during the case.

    .venv/bin/python benchmarks/hostile_bodies.py [--baseline DIR] [--scale 1.0]

`--baseline DIR`: the same cases against another checkout's server (run with this interpreter,
DIR on PYTHONPATH), e.g. a worktree of the code before issue 25's items.
`--scale`: multiplies the body sizes (1.0: bodies of 2-5 MB; the issue's were 14-24 MB).
"""

from __future__ import annotations

import argparse
import base64
import json
import struct
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import httpx  # noqa: E402

from benchmarks._common import rss_mb  # noqa: E402
from tests.server.helpers import ServerProcess, quick_doc  # noqa: E402


def ies_file(n_v: int, n_h: int = 1) -> bytes:
    """A valid IES LM-63-2002 file of n_v vertical x n_h horizontal angles."""
    v = " ".join(f"{180 * i / (n_v - 1):.5f}" for i in range(n_v))
    h = " ".join(f"{90 * i / (n_h - 1):.4f}" for i in range(n_h)) if n_h > 1 else "0"
    cd = "\n".join(" ".join(["100"] * n_v) for _ in range(n_h))
    return f"IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 {n_v} {n_h} 1 2 0 0 0\n1 1 10\n{v}\n{h}\n{cd}\n".encode()


def glb_of_nodes(n: int) -> bytes:
    """A GLB of `n` empty root nodes (a few MB of JSON)."""
    text = json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": list(range(n))}], "nodes": [{}] * n})
    text += " " * (-len(text) % 4)
    head = struct.pack("<4sII", b"glTF", 2, 20 + len(text)) + struct.pack("<I4s", len(text), b"JSON")
    return head + text.encode()


def cases(scale: float) -> list[tuple[str, bytes, int]]:
    """(name, body, copies posted at once)."""
    out = []
    doc = quick_doc()
    doc.update({f"k{i}": 0 for i in range(int(300_000 * scale))})
    out.append((f"{int(300_000 * scale):,d} unknown keys", doc, 2))
    doc = quick_doc()
    rx = doc["receivers"][0]
    doc["receivers"] = [dict(rx, id=f"r{i}", position=[1, 1, "x"]) for i in range(int(30_000 * scale))]
    out.append((f"{int(30_000 * scale):,d} receivers, bad position", doc, 1))
    doc = quick_doc()
    doc["transmitters"][0].pop("lambertian_order", None)
    ies = ies_file(int(200_000 * scale))
    doc["transmitters"][0]["photometry"] = {"data_base64": base64.b64encode(ies).decode(), "format": "ies"}
    out.append((f"IES of {int(200_000 * scale):,d} vertical angles", doc, 2))
    doc = quick_doc()
    doc["receivers"] = [dict(rx, id=f"r{i}") for i in range(int(150_000 * scale))]
    out.append((f"{int(150_000 * scale):,d} receivers (valid, over max_receivers)", doc, 2))
    doc = quick_doc()
    tx = doc["transmitters"][0]
    doc["transmitters"] = [dict(tx, id=f"t{i}") for i in range(int(20_000 * scale))]
    out.append((f"{int(20_000 * scale):,d} transmitters", doc, 1))
    doc = quick_doc()
    comp = {"weight": 1.0, "phase": {"type": "hg", "g": 0.5}}
    phase = {"type": "mixture", "components": [comp] * int(20_000 * scale)}
    doc["medium"] = {"type": "homogeneous", "sigma_a": 0.01, "sigma_s": 0.05, "phase": phase}
    out.append((f"mixture of {int(20_000 * scale):,d} components", doc, 1))
    doc = quick_doc()
    glb = base64.b64encode(glb_of_nodes(int(200_000 * scale))).decode()
    doc["meshes"] = [{"data_base64": glb, "format": "glb", "reflectance": 0.5}]
    out.append((f"GLB of {int(200_000 * scale):,d} root nodes", doc, 1))
    return [(name, json.dumps(d).encode(), copies) for name, d, copies in out]


def measure(srv: ServerProcess, body: bytes, copies: int) -> dict:
    stop = threading.Event()
    health: list[float] = []
    peak = [rss_mb(srv.proc.pid)]

    def monitor():
        with httpx.Client(base_url=srv.url, timeout=60) as c:
            while not stop.is_set():
                t0 = time.perf_counter()
                c.get("/v1/health")
                health.append(time.perf_counter() - t0)
                stop.wait(0.05)

    def sampler():
        while not stop.is_set():
            peak[0] = max(peak[0], rss_mb(srv.proc.pid))
            stop.wait(0.02)

    answers: list[tuple[httpx.Response, float]] = []

    def post():
        t0 = time.perf_counter()
        r = httpx.post(srv.url + "/v1/jobs", content=body, headers={"content-type": "application/json"}, timeout=300)
        answers.append((r, time.perf_counter() - t0))

    rss0 = rss_mb(srv.proc.pid)
    threads = [threading.Thread(target=f) for f in (monitor, sampler)]
    posts = [threading.Thread(target=post) for _ in range(copies)]
    for t in threads + posts:
        t.start()
    for t in posts:
        t.join()
    stop.set()
    for t in threads:
        t.join()
    r, seconds = max(answers, key=lambda a: a[1])
    kind = r.json().get("type", "").rsplit(":", 1)[-1] if r.status_code >= 400 else "accepted"
    health.sort()
    p99 = health[min(len(health) - 1, int(0.99 * (len(health) - 1)))] if health else float("nan")
    return {
        "status": r.status_code,
        "kind": kind,
        "bytes": len(r.content),
        "s": seconds,
        "rss0": rss0,
        "peak": peak[0],
        "p99": p99,
    }


def run(root: Path, label: str, scale: float) -> None:
    print(f"\n{label}")
    print(
        f"{'case':44s} {'copies':>6s} {'answer':>24s} {'bytes':>10s} {'time s':>7s} "
        f"{'RSS MB':>13s} {'health p99 s':>12s}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        with ServerProcess(Path(tmp) / "jobs.sqlite", root=root, max_queued_jobs=1000) as srv:
            for name, body, copies in cases(scale):
                m = measure(srv, body, copies)
                print(
                    f"{name:44s} {copies:6d} {m['status']:4d} {m['kind']:>19s} {m['bytes']:10,d} {m['s']:7.2f} "
                    f"{m['rss0']:5.0f} -> {m['peak']:5.0f} {m['p99']:12.3f}",
                    flush=True,
                )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, help="another checkout to measure the same way")
    ap.add_argument("--scale", type=float, default=1.0)
    args = ap.parse_args()
    print(f"bodies: {', '.join(f'{n} {len(b) / 1e6:.1f} MB' for n, b, _ in cases(args.scale))}")
    if args.baseline:
        run(args.baseline, f"baseline {args.baseline}", args.scale)
    run(ROOT, "this checkout", args.scale)
    return 0


if __name__ == "__main__":
    sys.exit(main())
