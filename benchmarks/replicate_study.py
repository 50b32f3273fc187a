"""Replicate study of the error bars in smoke (issue 12): is the reported standard error the real one?

For each case (the 5 x 5 x 3 m room with smoke sigma_s 0.2 /m, sigma_a 0, and an
unbounded medium sigma_s 0.2, sigma_a 0.05 /m; HG g = 0, 0.7, 0.9; devices 0.5 m and
3 m apart) and each estimator (algorithms 2, 3, 5 one-sided as `simulate` runs them,
and algorithms 2, 3, 4, 5 from both devices, engine/medium_nee.py), the script runs
`--seeds` independent seeds of `--paths` paths (per side) and prints:
- ratio: the spread (sample standard deviation) of H0 over the seeds / the median
  reported standard error (1 when the error bars are honest; the issue asks 0.7-1.5);
- max z: the largest |H0 - reference| / (its own reported standard error), the reference
  being the mean of the two-sided runs of the same algorithm (leave-one-out for those);
- flagged: runs whose result would carry engine/reliability.py's warning.
Room: Tx (2.5, 2.5, 3) down, Rx 0.5 m or 3 m below it facing up, K = 3 (algorithm 5: S = 3).
Unbounded: Tx at the origin facing +x, Rx at (D, 0, 0) facing it, S = 2.
Run: .venv/bin/python benchmarks/replicate_study.py [--seeds 10] [--paths 4096] [--json out/replicates.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from owcsim.engine import reliability  # noqa: E402
from owcsim.engine.medium_nee import simulate_two_sided  # noqa: E402
from owcsim.engine.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

VARIANTS = [(2, "one"), (3, "one"), (5, "one"), (2, "two"), (3, "two"), (4, "two"), (5, "two")]


def scene(geometry: str, g: float, D: float, algorithm: int, paths: int, seed: int) -> dict:
    sim = {"algorithm": algorithm, "paths": paths, "seed": seed, "batch_size": max(64, paths // 16),
           "time_bin_s": 1e-9, "t_max_s": 2e-7, "segment_time_step_s": 5e-9, "max_strata": 8}
    if geometry == "room":
        sim.update(max_reflections=3, **({"max_scattering": 3} if algorithm == 5 else {}))
        return {"room": {"size": [5, 5, 3], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": 0.8}},
                "transmitters": [{"id": "tx", "position": [2.5, 2.5, 3.0], "normal": [0, 0, -1],
                                  "lambertian_order": 1}],
                "receivers": [{"id": "rx", "position": [2.5, 2.5, 3.0 - D], "normal": [0, 0, 1], "area": 1e-4,
                               "fov_deg": 90}],
                "medium": {"type": "homogeneous", "sigma_a": 0.0, "sigma_s": 0.2, "phase": {"type": "hg", "g": g}},
                "simulation": sim}
    sim.update(max_reflections=0, **({"max_scattering": 2} if algorithm == 5 else {}))
    return {"transmitters": [{"id": "tx", "position": [0, 0, 0], "normal": [1, 0, 0], "lambertian_order": 1}],
            "receivers": [{"id": "rx", "position": [D, 0, 0], "normal": [-1, 0, 0], "area": 1e-4, "fov_deg": 90}],
            "medium": {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": g}},
            "simulation": sim}


def _with_reliability_warnings(build):
    """build_result plus engine/reliability.py's warning: the integration the result needs (see docs)."""
    def wrapped(spec, scene, accs, settings, los_gain, *a, **kw):
        doc = build(spec, scene, accs, settings, los_gain, *a, **kw)
        rel = reliability.from_accumulators(accs.values(), los_gain)
        doc["warnings"] = doc["warnings"] + reliability.warnings(rel, [f"{lk['transmitter']}-{lk['receiver']}"
                                                                       for lk in doc["links"]])
        return doc
    return wrapped


import owcsim.engine.result as _result  # noqa: E402
import owcsim.engine.simulate as _simulate  # noqa: E402

_result.build_result = _with_reliability_warnings(_result.build_result)
_simulate.build_result = _result.build_result


def run(doc: dict, sides: str) -> dict:
    spec = SceneSpec.model_validate(doc)
    res = simulate(spec) if sides == "one" else simulate_two_sided(spec)
    return res


def _flagged(res) -> bool:
    return any("unreliable error bar" in w for w in res.get("warnings", []))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--paths", type=int, default=4096)
    ap.add_argument("--json", default=None)
    ap.add_argument("--geometries", default="room,unbounded")
    args = ap.parse_args()
    rows = []
    t0 = time.perf_counter()
    print(f"{args.seeds} seeds x {args.paths} paths per side; ratio = spread / median stderr of H0; "
          "max z = worst |H0 - ref| / own stderr")
    print(f"{'case':26s} " + " ".join(f"{a}{'/2s' if s == 'two' else '/1s'}".rjust(15) for a, s in VARIANTS))
    for geometry in args.geometries.split(","):
        for g in (0.0, 0.7, 0.9):
            for D in (0.5, 3.0):
                out = {}
                for algorithm, sides in VARIANTS:
                    vals, errs, flags = [], [], 0
                    for seed in range(args.seeds):
                        case_seed = zlib.crc32(repr((geometry, g, D, algorithm, sides)).encode()) % 100_000  # not shared
                        res = run(scene(geometry, g, D, algorithm, args.paths, 1000 * seed + case_seed), sides)
                        link = res["links"][0]
                        vals.append(link["dc_gain"])
                        errs.append(link["dc_gain_stderr"])
                        flags += _flagged(res)
                    out[(algorithm, sides)] = (np.array(vals), np.array(errs), flags)
                cells = []
                for algorithm, sides in VARIANTS:
                    vals, errs, flags = out[(algorithm, sides)]
                    ratio = float(np.std(vals, ddof=1) / np.median(errs))
                    ref_vals = out[(algorithm, "two")][0] if (algorithm, "two") in out else vals
                    if sides == "two":
                        ref = np.array([(ref_vals.sum() - v) / (len(ref_vals) - 1) for v in vals])
                    else:
                        ref = np.full(len(vals), ref_vals.mean())
                    z = float(np.max(np.abs(vals - ref) / errs))
                    rows.append({"geometry": geometry, "g": g, "D": D, "algorithm": algorithm, "sides": sides,
                                 "ratio": ratio, "max_z": z, "flagged": flags, "mean": float(vals.mean()),
                                 "median_stderr": float(np.median(errs))})
                    cells.append(f"{ratio:5.2f} {z:4.1f} {flags:2d}")
                print(f"{geometry + f' g={g} D={D}':26s} " + " ".join(c.rjust(15) for c in cells), flush=True)
    print(f"cells: ratio, max z, runs flagged unreliable (of {args.seeds}); 1s = one-sided as simulate runs it, "
          f"2s = from both devices; {time.perf_counter() - t0:.0f} s (one process, CPU shared with other jobs)")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
