"""Error bars of single scattering in forward-peaked smoke (issue 22, item 5): a replicate study.

Open medium (no walls): Tx at the origin facing +x (Lambertian, m = 1), Rx (1 cm^2, FOV 90 deg) at
(D, 0, 0) facing it, D = 3 m, sigma_s 0.2 /m, sigma_a 0.05 /m, HG phase with g = 0.9, 0.99, 0.999,
-0.999; K = 0, S = 1 (the single-scattering family Tx -> p -> Rx only), `--paths` paths a side,
`--seeds` seeds, algorithm 5 at its defaults (from both devices; engine/integrator/weights.py), or those
given by `--algorithms`. Reference: tests/reference_peaked.py, an independent volume quadrature in
coordinates adapted to the peak (its refined grid printed next to it). Per g the table prints:
- bias: mean of the runs / reference - 1 (the 20-seed mean's own relative standard error after it);
- median: the median run's relative error;
- spread/SE: the sample standard deviation of the runs / their median reported standard error
  (1 when the error bars are honest; the issue asks <= 1.5);
- flagged: runs carrying engine/tally/reliability.py's "unreliable error bar" warning;
- worst z: max |H1 - reference| / reported SE over the unflagged runs; >4 SE: how many of them
  lie more than 4 reported standard errors from the reference (the issue asks 0).
`--direction forward` / `backward`: algorithm 5 from one side only.
Run: .venv/bin/python benchmarks/peaked_phase.py [--seeds 20] [--paths 100000] [--gs 0.9,0.99,0.999,-0.999]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from owcsim.engine.run import simulate as engine  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402
from tests.reference_peaked import converged  # noqa: E402

D, M, AREA, SIGMA_S, SIGMA_A = 3.0, 1.0, 1e-4, 0.2, 0.05


def doc(g: float, seed: int, paths: int, algorithm: int | str = "auto", direction: str = "auto") -> dict:
    return {
        "transmitters": [{"id": "tx", "position": [0, 0, 0], "normal": [1, 0, 0], "lambertian_order": M}],
        "receivers": [{"id": "rx", "position": [D, 0, 0], "normal": [-1, 0, 0], "area": AREA, "fov_deg": 90}],
        "medium": {"type": "homogeneous", "sigma_a": SIGMA_A, "sigma_s": SIGMA_S, "phase": {"type": "hg", "g": g}},
        "simulation": {
            "algorithm": algorithm,
            "direction": direction,
            "paths": paths,
            "seed": seed,
            "max_reflections": 0,
            "max_scattering": 1,
            "time_bin_s": 1e-9,
            "t_max_s": 4e-7,  # 120 m of path: the power arriving later is ~e^-30 of the rest
        },
    }


def run_seeds(g: float, seeds, paths: int, algorithm: int | str = "auto", direction: str = "auto") -> list[dict]:
    """Per seed: the single-scattering gain H1 = H0 - LOS, its reported standard error, the flag."""
    rows = []
    for seed in seeds:
        spec = SceneSpec.model_validate(doc(g, seed, paths, algorithm, direction))
        res = json.loads(engine.simulate(spec).model_dump_json())
        link = res["links"][0]
        rows.append(
            {
                "h1": link["dc_gain"] - link["los_gain"],
                "se": link["dc_gain_stderr"],
                "flagged": any("unreliable error bar" in w for w in res["warnings"]),
            }
        )
    return rows


def summary(rows: list[dict], ref: float) -> dict:
    h1 = np.array([r["h1"] for r in rows])
    se = np.array([r["se"] for r in rows])
    flagged = np.array([r["flagged"] for r in rows])
    z = np.abs(h1 - ref) / np.where(se > 0, se, np.inf)
    return {
        "bias": h1.mean() / ref - 1,
        "bias_se": h1.std(ddof=1) / np.sqrt(len(h1)) / ref,
        "median": float(np.median(h1)) / ref - 1,
        "ratio": h1.std(ddof=1) / np.median(se),
        "flagged": int(flagged.sum()),
        "worst_z": float(z[~flagged].max()) if (~flagged).any() else float("nan"),
        "beyond_4": int((z[~flagged] > 4).sum()),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--paths", type=int, default=100_000)
    ap.add_argument("--gs", default="0.9,0.99,0.999,-0.999")
    ap.add_argument("--algorithms", default="auto", help="comma-separated: auto, 2, 3, 4, 5")
    ap.add_argument("--direction", default="auto", help="auto (both devices in smoke), forward or backward (5 only)")
    args = ap.parse_args()
    print(
        f"open medium, D = {D} m, sigma_s {SIGMA_S}, sigma_a {SIGMA_A} /m, K = 0, S = 1; "
        f"{args.seeds} seeds x {args.paths:,d} paths a side; direction {args.direction}"
    )
    print(
        f"{'g':>7s} {'alg':>4s} {'reference H1':>13s} {'refined':>13s} {'bias':>17s} {'median':>8s} "
        f"{'spread/SE':>9s} {'flagged':>7s} {'worst z':>7s} {'>4 SE':>5s} {'time':>6s}"
    )
    for g in (float(x) for x in args.gs.split(",")):
        ref, fine = converged(D, M, AREA, SIGMA_S, SIGMA_A + SIGMA_S, g)
        for alg in args.algorithms.split(","):
            t = time.perf_counter()
            rows = run_seeds(g, range(args.seeds), args.paths, alg if alg == "auto" else int(alg), args.direction)
            s = summary(rows, ref)
            print(
                f"{g:7.4g} {alg:>4s} {ref:13.6e} {fine:13.6e} {s['bias']:+8.2%} +- {s['bias_se']:5.2%} "
                f"{s['median']:+8.2%} {s['ratio']:9.2f} {s['flagged']:7d} {s['worst_z']:7.2f} {s['beyond_4']:5d} "
                f"{time.perf_counter() - t:5.0f}s",
                flush=True,
            )


if __name__ == "__main__":
    main()
