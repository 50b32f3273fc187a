"""Speed against accuracy of the five algorithms in a smoke-filled room.

Barry et al.'s configuration A (5 x 5 x 3 m, walls and ceiling 0.8, floor 0.3, Rx at
(0.5, 1, 0), FOV 85 deg) filled with smoke: sigma_s = 0.2, sigma_a = 0.05 /m, HG
g = 0.7, up to K = 6 reflections for every algorithm. Reference: a long algorithm-5
run (all scattering orders up to S = 30, same K; algorithm 5 below uses S = 30 too,
with another seed). For each algorithm and path
budget the script prints the wall time, H0 with its error bar, the relative error
of H0 against the reference and the relative L2 error of the CIR (1 ns bins), and
plots error against time (PNG). The error of algorithms 1-4 includes their model
error: the path families they leave out (physics.md section 4).
Run: .venv/bin/python benchmarks/smoke_accuracy.py [--out out/bench] [--ref-paths 2000000]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import barry_doc  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

MEDIUM = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.7}}
# Algorithms 2-4 in a medium run from both devices (engine/integrator/weights.py); 5 one-sided here for comparison
# (its default, direction "auto" in a medium, runs from both devices too).
CASES = [(1, "auto"), (2, "both"), (3, "both"), (4, "both"), (5, "forward"), (5, "backward"), (5, "both")]


def run(algorithm: int, direction: str, paths: int, seed: int, max_scattering: int | None = None):
    """One run; `max_scattering` for algorithm 5 only (1-4 count their own orders: 0, 1, 1, 2)."""
    doc = barry_doc(
        algorithm=algorithm,
        direction="auto" if direction == "both" else direction,
        max_reflections=6,
        **({"max_scattering": max_scattering} if max_scattering is not None else {}),
        paths=paths,
        seed=seed,
        time_bin_s=1e-9,
        t_max_s=2e-7,
        batch_size=8192,
    )
    doc["medium"] = MEDIUM
    spec = SceneSpec.model_validate(doc)
    t = time.perf_counter()
    res = simulate(spec)
    return time.perf_counter() - t, res.links[0]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="out/bench")
    ap.add_argument("--ref-paths", type=int, default=2_000_000)
    ap.add_argument("--budgets", default="8192,32768,131072")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_ref, ref = run(5, "backward", args.ref_paths, seed=999, max_scattering=30)
    h_ref = np.asarray(ref.cir.total)
    print(
        f"reference: algorithm 5 backward, S = 30, {args.ref_paths:,d} paths, {t_ref:.1f} s: "
        f"H0 = {ref.dc_gain:.5e} ± {ref.dc_gain_stderr:.1e} "
        f"(by scattering order {[f'{v:.2e}' for v in ref.dc_gain_by_scattering_order[:4]]})"
    )
    print(f"{'algorithm':14s} {'paths':>8s} {'time s':>7s} {'H0':>12s} {'stderr':>8s} {'H0 err':>8s} {'CIR err':>8s}")
    rows = []
    for algorithm, direction in CASES:
        for paths in map(int, args.budgets.split(",")):
            el, link = run(algorithm, direction, paths, seed=1, max_scattering=30 if algorithm == 5 else None)
            h = np.asarray(link.cir.total)
            h0_err = abs(link.dc_gain - ref.dc_gain) / ref.dc_gain
            cir_err = float(np.linalg.norm(h - h_ref) / np.linalg.norm(h_ref))
            label = f"{algorithm} {direction}"
            rows.append(
                {
                    "algorithm": algorithm,
                    "direction": direction,
                    "paths": paths,
                    "time_s": el,
                    "dc_gain": link.dc_gain,
                    "dc_gain_stderr": link.dc_gain_stderr,
                    "h0_rel_error": h0_err,
                    "cir_rel_error": cir_err,
                }
            )
            print(
                f"{label:14s} {paths:8d} {el:7.2f} {link.dc_gain:12.5e} {link.dc_gain_stderr:8.1e} "
                f"{h0_err:8.2%} {cir_err:8.2%}"
            )
    (out / "smoke_accuracy.json").write_text(
        json.dumps(
            {
                "reference": {k: getattr(ref, k) for k in ("dc_gain", "dc_gain_stderr", "dc_gain_by_scattering_order")},
                "rows": rows,
            },
            indent=1,
        )
    )
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for algorithm, direction in CASES:
        sel = [r for r in rows if r["algorithm"] == algorithm and r["direction"] == direction]
        t = [r["time_s"] for r in sel]
        for ax, key in zip(axes, ("h0_rel_error", "cir_rel_error")):
            ax.loglog(t, [r[key] for r in sel], "o-", label=f"algorithm {algorithm} ({direction})")
    for ax, title in zip(axes, ("relative error of H0", "relative L2 error of the CIR (1 ns bins)")):
        ax.set_xlabel("wall time [s], one process")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.suptitle("Smoke room (sigma_s 0.2, sigma_a 0.05 /m, g 0.7), K = 6; reference: algorithm 5, S = 30", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "smoke_accuracy.png", dpi=120)
    print(f"wrote {out / 'smoke_accuracy.png'} and {out / 'smoke_accuracy.json'}")


if __name__ == "__main__":
    main()
