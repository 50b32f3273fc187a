"""Shared set-up of the benchmarks: the Barry room document and timing helpers."""

from __future__ import annotations

import importlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def use_baseline_tree() -> None:
    """In a baseline tree (OWCSIM_TREE set: its symlink farm on PYTHONPATH), drop this editable install's
    import finder so that `owcsim` is the baseline's. Call before the first owcsim import."""
    if "OWCSIM_TREE" in os.environ:
        sys.meta_path[:] = [
            f
            for f in sys.meta_path
            if "editable" not in getattr(f, "__module__", "")
            and "editable" not in type(f).__module__
            and "editable" not in repr(f)
        ]


def engine_module(name: str):
    """The engine module `name` ("run.simulate"), or its flat name in a baseline tree from before the
    engine's folders (issue 23: owcsim.engine.simulate)."""
    try:
        return importlib.import_module(f"owcsim.engine.{name}")
    except ModuleNotFoundError:
        return importlib.import_module(f"owcsim.engine.{name.rsplit('.', 1)[-1]}")


def barry_doc(**simulation) -> dict:
    doc = json.loads((ROOT / "examples" / "barry_config_a.json").read_text())
    doc["simulation"].update(simulation)
    return doc


def best_of(repeats: int, fn):
    """(best wall time [s], last return value) over `repeats` calls."""
    best, value = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - t)
    return best, value


def rss_mb(pid: int) -> float:
    """Resident memory of process `pid` [MB] (Linux /proc), 0 when it is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def raw_embree(scene, n_intersect: int, n_occluded: int, batch: int, rng, clock=time.perf_counter) -> float:
    """Seconds Embree alone takes for the given ray counts, in batches of `batch` rays (random rays in the
    scene's bounding box; only `EmbreeScene.run` timed, by `clock`)."""
    emb = scene.intersector._scene
    lo = scene.geometry.vertices.min(axis=0) - scene.intersector.center
    hi = scene.geometry.vertices.max(axis=0) - scene.intersector.center
    total = 0.0
    for count, query in ((n_intersect, "INTERSECT"), (n_occluded, "OCCLUDED")):
        done = 0
        while done < count:
            n = min(batch, count - done)
            o = (lo + rng.random((n, 3)) * (hi - lo)).astype(np.float32)
            d = rng.normal(size=(n, 3))
            d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
            dist = np.full(n, 1.0 if query == "OCCLUDED" else 1e30, np.float32)
            t = clock()
            if query == "INTERSECT":
                emb.run(o, d, dists=dist, output=1)
            else:
                emb.run(o, d, dists=dist, query="OCCLUDED")
            total += clock() - t
            done += n
    return total
