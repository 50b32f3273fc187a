"""Dask distributed against the local process pool: throughput, overhead per task, break-even batch size.

Barry et al. 1993 configuration A, backward, 3 reflections, on this machine:
1. throughput (paths/s) of one job at the default batch size: in-process, the local
   pool of 2 processes, and Dask LocalClusters (127.0.0.1, one thread per worker
   process) of 1 and 2 workers; warm (workers started, scenes cached);
2. overhead per task: the same job at several batch sizes, in-process against one
   Dask worker: the extra wall time per batch, as a fraction of the batch's own time,
   and the batch size at which it falls under 5 %; and 2 Dask workers against the
   local pool of 2 processes at the same batch sizes.
Every process runs with the glibc malloc thresholds the Dask workers get from
engine.run.execution_dask (the script re-runs itself with MALLOC_MMAP_THRESHOLD_ and
MALLOC_TRIM_THRESHOLD_ set), so the comparison measures dispatch, not malloc;
--glibc-defaults keeps the defaults for the local runs. All executors stay up
together and each repeat runs every one of them in turn (the best time of each is
kept), so slow drifts of the host's load hit them alike. Every run of a job must give
the same bits (checked). On a 2-core machine the Dask
scheduler and the client share the cores with the workers.
Run: .venv/bin/python benchmarks/dask_scaling.py [--paths N] [--repeats R] [--batches 512,2048,...]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import barry_doc  # noqa: E402
from owcsim.engine.run.execution import ProcessExecutor  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402


def job(paths: int, batch: int) -> SceneSpec:
    return SceneSpec.model_validate(
        barry_doc(paths=paths, batch_size=batch, direction="backward", max_reflections=3, seed=1)
    )


def strip(result) -> dict:
    """The result document without the figures that differ between executors."""
    res = json.loads(result.model_dump_json())
    for key in ("wall_time_s", "workers"):
        res["run"].pop(key)
    return res


def dask_cluster(n_workers: int):
    from distributed import Client, LocalCluster

    cluster = LocalCluster(
        n_workers=n_workers,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        silence_logs=40,
    )
    return cluster, Client(cluster, set_as_default=False)


def round_robin(spec: SceneSpec, executors: dict, repeats: int) -> dict:
    """{name: (best wall time [s], result)}: one warm-up run each, then `repeats` rounds over all."""
    best = {}
    for name, ex in executors.items():
        best[name] = (float("inf"), simulate(spec, executor=ex))
    for _ in range(repeats):
        for name, ex in executors.items():
            t = time.perf_counter()
            res = simulate(spec, executor=ex)
            best[name] = (min(best[name][0], time.perf_counter() - t), res)
    return best


def worker_timeline(client, executor, spec: SceneSpec) -> tuple[float, float]:
    """One run on a 1-worker cluster: (mean compute time per batch task, mean idle time of the worker per task).

    Idle = (wall time of the job - time the worker spent computing batches) / tasks: what dispatch
    costs a worker machine of its own, without the contention of this host's 2 cores.
    """
    from distributed import get_task_stream

    with get_task_stream(client) as ts:
        t = time.perf_counter()
        simulate(spec, executor=executor)
        wall = time.perf_counter() - t
    compute = [
        sum(s["stop"] - s["start"] for s in d["startstops"] if s["action"] == "compute")
        for d in ts.data
        if str(d["key"]).startswith("owcsim-batch-")
    ]
    return sum(compute) / len(compute), (wall - sum(compute)) / len(compute)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", type=int, default=1_000_000, help="paths of the throughput job")
    ap.add_argument("--batch", type=int, default=16384, help="batch size of the throughput job")
    ap.add_argument("--batches", default="512,2048,8192,32768,131072", help="batch sizes of the overhead sweep")
    ap.add_argument("--sweep-paths", type=int, default=1 << 19, help="least paths per sweep point")
    ap.add_argument("--min-tasks", type=int, default=16, help="least batches per sweep point")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--window", type=int, default=None, help="Dask tasks in flight (default: the executor's)")
    ap.add_argument("--glibc-defaults", action="store_true", help="local runs keep glibc's malloc thresholds")
    args = ap.parse_args()
    from owcsim.engine.run.execution_dask import MALLOC_MMAP_THRESHOLD, MALLOC_TRIM_THRESHOLD, DaskExecutor

    env = {"MALLOC_MMAP_THRESHOLD_": str(MALLOC_MMAP_THRESHOLD), "MALLOC_TRIM_THRESHOLD_": str(MALLOC_TRIM_THRESHOLD)}
    if not args.glibc_defaults and any(os.environ.get(k) != v for k, v in env.items()):
        os.execve(sys.executable, [sys.executable, *sys.argv], {**os.environ, **env})  # malloc reads them at start
    logging.getLogger("distributed").setLevel(logging.ERROR)
    print(f"malloc thresholds of the local runs: {'glibc defaults' if args.glibc_defaults else env}")

    sweep = [int(b) for b in args.batches.split(",")]
    sweep_specs = {b: job(max(args.sweep_paths, args.min_tasks * b), b) for b in sweep}
    main_spec = job(args.paths, args.batch)

    # (A pool of 1 process is not measured: simulate() sends a job to worker processes only when the
    # executor has more than one worker.)
    executors = {"in-process": None, "local pool, 2 processes": ProcessExecutor(2)}
    clusters = []
    try:
        for n in (1, 2):
            t0 = time.perf_counter()
            cluster, client = dask_cluster(n)
            clusters.append((cluster, client))
            ex = DaskExecutor(client, window=args.window)
            t_start = time.perf_counter() - t0
            t = time.perf_counter()
            simulate(main_spec, executor=ex)
            print(
                f"Dask, {n} worker(s): cluster start {t_start:.2f} s, first (cold) job "
                f"{time.perf_counter() - t:.2f} s, window {ex.window}",
                flush=True,
            )
            executors[f"Dask, {n} worker{'s' if n > 1 else ''}"] = ex
        main_runs = round_robin(main_spec, executors, args.repeats)
        sweep_runs = {b: round_robin(s, executors, args.repeats) for b, s in sweep_specs.items()}
        streams = {b: worker_timeline(clusters[0][1], executors["Dask, 1 worker"], s) for b, s in sweep_specs.items()}
    finally:
        for ex in executors.values():
            if ex is not None:
                ex.close()
        for cluster, client in clusters:
            client.close()
            cluster.close()

    ref = strip(main_runs["in-process"][1])
    identical = all(strip(r) == ref for _, r in main_runs.values())
    for runs in sweep_runs.values():
        first = strip(runs["in-process"][1])
        identical &= all(strip(r) == first for _, r in runs.values())
    print(
        f"\nthroughput: Barry A, backward, K = 3, {args.paths:,d} paths in batches of {args.batch} "
        f"({-(-args.paths // args.batch)} tasks); best of {args.repeats}, warm"
    )
    base = main_runs["in-process"][0]
    print(f"{'executor':28s} {'time s':>7s} {'paths/s':>11s} {'vs in-process':>14s}")
    for name, (t, _) in main_runs.items():
        print(f"{name:28s} {t:7.3f} {args.paths / t:11,.0f} {base / t:13.2f}x")
    print(f"bit-identical results across all runs: {'yes' if identical else 'NO'}")

    print("\noverhead per task: one Dask worker against in-process; two Dask workers against the local pool of two")
    print(
        f"{'batch':>7s} {'tasks':>6s} {'in-proc ms/task':>16s} {'Dask1 +ms/task':>15s} {'Dask1 overhead':>15s} "
        f"{'worker ms/task':>15s} {'idle ms/task':>13s} {'idle/compute':>13s} "
        f"{'pool2 paths/s':>14s} {'Dask2 paths/s':>14s} {'Dask2/pool2':>12s}"
    )
    rows = []
    for b in sweep:
        paths = sweep_specs[b].simulation.n_paths
        n_tasks = -(-paths // b)
        runs = sweep_runs[b]
        tl, td = runs["in-process"][0], runs["Dask, 1 worker"][0]
        tp, td2 = runs["local pool, 2 processes"][0], runs["Dask, 2 workers"][0]
        per = tl / n_tasks
        od = (td - tl) / n_tasks
        comp, idle = streams[b]
        rows.append((b, per, od, comp, idle))
        print(
            f"{b:7d} {n_tasks:6d} {per * 1e3:16.2f} {od * 1e3:15.2f} {od / per:14.1%} "
            f"{comp * 1e3:15.2f} {idle * 1e3:13.2f} {idle / comp:12.1%} "
            f"{paths / tp:14,.0f} {paths / td2:14,.0f} {tp / td2:11.2f}x"
        )
    # Model: in-process time per batch a + c b (least squares); an overhead o per task (the median of the
    # measured ones) is under 5 % of a batch from b* = (o / 0.05 - a) / c.
    bs = np.array([r[0] for r in rows], float)
    c, a = np.polyfit(bs, np.array([r[1] for r in rows]), 1)
    print(f"fit: in-process {a * 1e3:.2f} ms + {c * 1e6:.3f} us/path per batch")
    for label, col in (("wall time against in-process (this host)", 2), ("worker idle time (dispatch)", 4)):
        o = float(np.median([r[col] for r in rows]))
        measured = next((r[0] for r in rows if r[col] / (r[1] if col == 2 else r[3]) < 0.05), None)
        print(
            f"overhead per task, {label}: {o * 1e3:.2f} ms (median); under 5 % from "
            f"{max((o / 0.05 - a) / c, 0):,.0f} paths per batch (model), smallest measured batch under 5 %: "
            f"{measured if measured else 'none'}"
        )


if __name__ == "__main__":
    main()
