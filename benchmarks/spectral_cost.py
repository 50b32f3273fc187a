"""What wavelength bands cost: time per path with B = 8 and 32 bands relative to one band, same run.

Barry et al.'s configuration A (5 x 5 x 3 m, one LED, one photodiode), algorithm 1, K = 3, a fixed
number of paths, from the transmitter. Spectral surfaces (a different reflectance per band on the
walls, floor and ceiling) make the kernel carry one throughput per band and path (engine/spectral/spectra.py);
every band is tallied as its own channel plus the optical, electrical and luminous combinations.
Cases: the grey scene (no `spectral`), one band, 8 and 32 bands over 400-900 nm; optionally the same
with smoke per band (algorithm 1: a transmittance ratio per band and segment).
Targets (issue 15): 8 bands < 1.5x and 32 bands < 3x the one-band cost per path.
Timings are wall-clock, best of N rounds with the cases interleaved; on a shared machine they are noisy.
BLAS runs on one thread
(OPENBLAS_NUM_THREADS=1, set here): under load, OpenBLAS's threads made the small per-batch matrix
product of tally.BatchBuilder.finish take 30-120 ms instead of 0.2 ms, swamping what is measured.
Run: .venv/bin/python benchmarks/spectral_cost.py [--paths 200000] [--repeats 3] [--smoke]
"""

from __future__ import annotations

import argparse
import copy
import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see the module docstring
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import barry_doc, best_of  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402


def scene(n_bands: int | None, paths: int, smoke: bool) -> SceneSpec:
    doc = barry_doc(algorithm=1, max_reflections=3, paths=paths, direction="forward", t_max_s=1e-7)
    if smoke:
        doc["medium"] = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.0}
    if n_bands is not None:
        edges = np.linspace(400e-9, 900e-9, n_bands + 1)
        x = np.linspace(0.0, 1.0, n_bands)
        doc["spectral"] = {"band_edges": edges.tolist()}
        rr = doc["room"]["reflectance"]
        rr["walls"] = {"type": "spectral", "reflectance": (0.5 + 0.3 * x).tolist()}
        rr["floor"] = {"type": "spectral", "reflectance": (0.3 - 0.1 * x).tolist()}
        rr["ceiling"] = {"type": "spectral", "reflectance": (0.8 - 0.05 * x).tolist()}
        doc["receivers"][0]["responsivity"] = {"type": "named", "name": "silicon_pin"}
        doc["transmitters"][0]["spectrum"] = {"type": "named", "name": "white_led_cool"}
        if smoke:
            doc["spectral"]["medium"] = {"sigma_a": (0.08 - 0.04 * x).tolist(), "sigma_s": [0.0] * n_bands}
    return SceneSpec.model_validate(copy.deepcopy(doc))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=200_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--smoke", action="store_true", help="also with smoke per band (algorithm 1)")
    args = ap.parse_args()
    for smoke in (False, True) if args.smoke else (False,):
        print(
            f"\nBarry configuration A, algorithm 1, K = 3, {args.paths} paths"
            + (", smoke per band" if smoke else "")
            + f" (best of {args.repeats})"
        )
        cases = {"grey": None, "1 band": 1, "8 bands": 8, "32 bands": 32}
        specs = {label: scene(b, args.paths, smoke) for label, b in cases.items()}
        for spec in specs.values():
            simulate(spec)  # warm-up: imports, Mie or V(lambda) tables, Embree build
        # Cases interleaved, best of the rounds: a load change on a shared machine hits every case alike.
        times, results = {label: float("inf") for label in cases}, {}
        for _ in range(args.repeats):
            for label, spec in specs.items():
                t, results[label] = best_of(1, lambda s=spec: simulate(s))
                times[label] = min(times[label], t)
        base = times["1 band"]
        for label, t in times.items():
            ratio = f"{t / base:5.2f}x one band" if cases[label] else ""
            res = results[label]
            h0 = res["links"][0]["dc_gain"] if isinstance(res, dict) else res.links[0].dc_gain  # typed result
            print(f"  {label:9s} {t / args.paths * 1e6:7.2f} us/path  H0 = {h0:.5g}  {ratio}")
        print(
            f"  targets: 8 bands < 1.5x -> {times['8 bands'] / base:.2f}x, "
            f"32 bands < 3x -> {times['32 bands'] / base:.2f}x"
        )


if __name__ == "__main__":
    main()
