"""A job's memory estimate (engine/run/budget.py) against the measured peak RSS of real jobs.

Each job runs as the service runs it: in a fresh process from a forkserver with the engine
imported, simulate + the result's JSON + every render (server.formats.render_all). The
child reports its peak RSS (VmHWM). Prints one row per job: links, bins, K, batch, the
estimate and its terms, the measured peak, and estimate / measured (>= 1 is what the
budget needs; the address-space cap adds worker_memory_headroom_bytes on top).

    .venv/bin/python benchmarks/job_memory.py
"""

from __future__ import annotations

import multiprocessing as mp
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _peak_rss() -> int:
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return 0


def _child(doc: dict, conn) -> None:
    from owcsim.engine.run.simulate import simulate
    from owcsim.schemas import SceneSpec
    from owcsim.server.formats import render_all

    t0 = time.perf_counter()
    result = simulate(SceneSpec.model_validate(doc))
    text = result.model_dump_json()  # as the worker stores it
    with tempfile.TemporaryDirectory() as tmp:
        render_all(result, text, Path(tmp))
    conn.send(
        (
            _peak_rss(),
            time.perf_counter() - t0,
            result.time_bins.n_bins,
            result.scene.simulation.max_reflections or result.modeled.max_reflections,
        )
    )
    conn.close()


def _grid(n_side: int, **sim) -> dict:
    from tests.server.helpers import quick_doc

    doc = quick_doc(**{"paths": 2048, "direction": "forward", "max_reflections": 1, **sim})
    doc["receivers"] = []
    doc["receiver_grids"] = [
        {"id_prefix": "g", "origin": [0.5, 0.5, 0.0], "size": [4.0, 4.0], "spacing": 4.0 / (n_side - 1), "area": 1e-4}
    ]
    return doc


def jobs() -> list[tuple[str, dict]]:
    from tests.scenes import barry_doc
    from tests.server.helpers import quick_doc

    return [
        ("1 link, 50 bins", quick_doc(paths=4000)),
        ("1 link, 200 000 bins", quick_doc(paths=4000, time_bin_s=1e-12, t_max_s=2e-7)),
        ("Barry A, auto K and window", barry_doc(paths=20_000, max_reflections=None, t_max_s=None)),
        ("900 links x 200 bins", _grid(30, t_max_s=2e-7, batch_size=1024)),
        ("3 600 links x 200 bins, K=3", _grid(60, t_max_s=2e-7, max_reflections=3, batch_size=2048)),
        ("2 500 links x 50 bins, batch 16 384", _grid(50, batch_size=16384, paths=16384)),
        ("10 000 links x 100 bins", _grid(100, t_max_s=1e-7, batch_size=1024, paths=1024)),
    ]


def main() -> None:
    from owcsim.engine.run.budget import memory_estimate
    from owcsim.schemas import SceneSpec
    from owcsim.server.dispatcher import start_forkserver

    start_forkserver()
    ctx = mp.get_context("forkserver")
    print(
        f"{'job':38s} {'links':>6s} {'bins':>7s} {'K':>3s} {'estimate':>9s} {'measured':>9s} {'ratio':>6s} "
        f"{'time':>6s}  terms [MB]: accumulators batch result devices"
    )
    for name, doc in jobs():
        est = memory_estimate(SceneSpec.model_validate(doc))
        receive, send = ctx.Pipe(duplex=False)
        p = ctx.Process(target=_child, args=(doc, send))
        p.start()
        send.close()
        peak, wall, bins, k = receive.recv()
        p.join()
        spec = SceneSpec.model_validate(doc)
        links = len(spec.transmitters) * (len(spec.receivers) + sum(g.count for g in spec.receiver_grids))
        mb = 2**20
        print(
            f"{name:38s} {links:6d} {bins:7d} {k:3d} {est.total / mb:8.0f}M {peak / mb:8.0f}M "
            f"{est.total / peak:6.2f} {wall:5.1f}s  {est.accumulators / mb:.0f} {est.batch / mb:.0f} "
            f"{est.result / mb:.0f} {est.devices / mb:.0f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
