"""Throughput of the Algorithm 1 pipeline against raw Embree, and scaling with workers.

Barry et al. 1993 configuration A at 3 reflections. Prints paths/s and rays/s
(intersection + shadow) of the whole pipeline on one core, the raw Embree rays/s
for the same number of rays of each kind in batches of the same size (random rays
inside the room, prepared float32 arrays: only `EmbreeScene.run` is timed), their
ratio, and paths/s with 2 worker processes (warm pool) against 1.
Run: .venv/bin/python benchmarks/throughput.py [--paths N]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import barry_doc, best_of, raw_embree  # noqa: E402
from owcsim.engine.run.execution import ProcessExecutor  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.engine.scene.scene import build_scene  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402


def solo(paths: int, batch: int) -> None:
    """Time one serial job (used as a subprocess to measure the hardware's own 2-process scaling)."""
    spec = SceneSpec.model_validate(barry_doc(paths=paths, batch_size=batch, direction="backward", max_reflections=3))
    simulate(SceneSpec.model_validate(barry_doc(paths=batch)))  # warm caches and imports
    t = time.perf_counter()
    simulate(spec)
    print(time.perf_counter() - t)


def hardware_ceiling(paths: int, batch: int) -> float:
    """Throughput of two independent single-process jobs run at once, relative to one alone.

    No code is shared between them, so this is what the machine itself allows
    (memory bandwidth, shared caches, SMT siblings), the ceiling for any pool.
    """
    cmd = [sys.executable, __file__, "--solo", "--paths", str(paths), "--batch", str(batch)]
    alone = float(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout)
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True) for _ in range(2)]
    both = max(float(p.communicate()[0]) for p in procs)
    return 2 * alone / both


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", type=int, default=400_000)
    ap.add_argument("--batch", type=int, default=16384)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--solo", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.solo:
        return solo(args.paths, args.batch)
    rng = np.random.default_rng(0)
    print(f"Barry configuration A, 3 reflections, {args.paths:,d} paths, batches of {args.batch}")
    print(f"{'case':44s} {'time s':>7s} {'paths/s':>10s} {'Mrays/s':>8s} {'raw Embree':>10s} {'ratio':>6s}")
    for direction in ("forward", "backward"):
        for cast_shadows in (True, False):
            spec = SceneSpec.model_validate(
                barry_doc(paths=args.paths, batch_size=args.batch, direction=direction, max_reflections=3)
            )
            scene = build_scene(spec)
            if cast_shadows:
                scene.all_visible = False  # cast every shadow ray, as in a furnished room
            el, res = best_of(args.repeats, lambda spec=spec, scene=scene: simulate(spec, scene=scene))
            n_i, n_o = res.run.rays_intersect, res.run.rays_occluded
            raw = min(raw_embree(scene, n_i, n_o, args.batch, rng) for _ in range(args.repeats))
            rays = n_i + n_o
            label = f"{direction}, shadow rays {'cast' if cast_shadows else 'skipped (convex room)'}"
            print(
                f"{label:44s} {el:7.3f} {args.paths / el:10.0f} {rays / el / 1e6:8.2f} "
                f"{rays / raw / 1e6:10.2f} {raw / el:6.2f}"
            )
    # Scaling: the same job on a warm pool of 2 workers against 1 process.
    spec = SceneSpec.model_validate(
        barry_doc(paths=args.paths, batch_size=args.batch, direction="backward", max_reflections=3)
    )
    t1, r1 = best_of(args.repeats, lambda: simulate(spec))
    pool = ProcessExecutor(2)
    try:
        simulate(spec, executor=pool)  # warm-up: workers start and build the scene
        t2, r2 = best_of(args.repeats, lambda: simulate(spec, executor=pool))
    finally:
        pool.close()
    assert r1.links[0].dc_gain == r2.links[0].dc_gain  # same seed, same bits
    print(
        f"1 worker: {args.paths / t1:,.0f} paths/s; 2 workers (warm pool): {args.paths / t2:,.0f} paths/s; "
        f"speed-up {t1 / t2:.2f}x"
    )
    print(
        f"hardware ceiling (two independent single-process jobs at once): "
        f"{hardware_ceiling(args.paths, args.batch):.2f}x"
    )


if __name__ == "__main__":
    main()
