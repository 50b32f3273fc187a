"""Reproduce the report's smoke figures (chapter 8, algorithm 3) as PNG plots.

Figure 8.3: the CIR for sigma_s = 0, 0.2, 0.4 (sigma_a = 0, g = 0); figures 8.4 and
8.5: sigma_s = 0.2 with g = 0, -0.5, -0.9 (backward scattering) and g = 0, 0.5, 0.9
(forward scattering). The room is Barry et al.'s configuration A, 3 reflections,
algorithm 3 (out-scattering toward the receiver), as in the report; `--algorithm 5`
adds every scattering order. Each curve is one `owcsim run` of the sweep; the
result documents are written next to the plots.

Run: .venv/bin/python examples/report_figures.py --out out/report [--paths 200000] [--algorithm 3]
"""

from __future__ import annotations

import argparse
import copy
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

HERE = Path(__file__).resolve().parent

FIGURES = {
    "fig8_3_sigma_s": ("sigma_s", [0.0, 0.2, 0.4], {"g": 0.0}, "Figure 8.3: sigma_s (sigma_a = 0, g = 0)"),
    "fig8_4_backward_g": ("g", [0.0, -0.5, -0.9], {"sigma_s": 0.2}, "Figure 8.4: backward scattering, sigma_s = 0.2"),
    "fig8_5_forward_g": ("g", [0.0, 0.5, 0.9], {"sigma_s": 0.2}, "Figure 8.5: forward scattering, sigma_s = 0.2"),
}


def scene(sigma_s: float, g: float, algorithm: int, paths: int) -> dict:
    doc = json.loads((HERE / "barry_config_a.json").read_text())
    doc["name"] = f"Barry A in smoke, sigma_s = {sigma_s}, g = {g}"
    doc["medium"] = {"type": "homogeneous", "sigma_a": 0.0, "sigma_s": sigma_s, "phase": {"type": "hg", "g": g}}
    doc["simulation"].update(algorithm=algorithm, max_reflections=3, paths=paths, time_bin_s=2e-10, t_max_s=8e-8)
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/report")
    ap.add_argument("--paths", type=int, default=200_000)
    ap.add_argument("--algorithm", type=int, default=3, choices=(2, 3, 4, 5))
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, (param, values, fixed, title) in FIGURES.items():
        fig, ax = plt.subplots(figsize=(8, 4))
        for value, colour in zip(values, ("tab:blue", "tab:red", "tab:green")):
            kw = dict(fixed, **{param: value})
            doc = scene(kw["sigma_s"], kw["g"], args.algorithm, args.paths)
            res = simulate(SceneSpec.model_validate(copy.deepcopy(doc)), workers=args.workers)
            (out / f"{name}_{param}_{value:+.1f}.json").write_text(res.model_dump_json())
            link, tb = res.links[0], res.time_bins
            t = (tb.t_min_s + tb.time_bin_s * (np.arange(tb.n_bins) + 0.5)) * 1e9
            h = np.asarray(link.cir.total) / tb.time_bin_s
            ax.plot(t, h, colour, lw=0.9, label=f"{param} = {value:g}: H0 = {link.dc_gain:.3e}")
            print(
                f"{name}: {param} = {value:+.1f}  H0 = {link.dc_gain:.4e} ± {link.dc_gain_stderr:.1e}  "
                f"(scattered part {sum(link.dc_gain_by_scattering_order[1:]):.3e})"
            )
        ax.set_yscale("log")
        ax.set_xlim(10, 60)
        ax.set_ylim(1e-2, None)
        ax.set_xlabel("delay t [ns]")
        ax.set_ylabel("h(t) [1/s]")
        ax.set_title(f"{title}; algorithm {args.algorithm}, {args.paths:,d} paths", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / f"{name}.png", dpi=120)
        plt.close(fig)
    print(f"wrote {out}/*.png")


if __name__ == "__main__":
    main()
