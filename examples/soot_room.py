"""Soot smoke from its particles at two concentrations, against the Henyey-Greenstein fits of the report.

The report (section 3.5) notes that smoke particles call for Mie theory and that, Mie
being "complicated to apply", one usually replaces its phase function by Henyey-Greenstein
lobes (eq. 3.3). For examples/soot_room_light.json and soot_room_dense.json (50 and 250 mg/m^3
of soot in Barry et al.'s configuration A, 850 nm) this script prints what owcsim derives
from the particles (sigma_a, sigma_s, albedo, g, Koschmieder visibility, the table's
normalisation and mean cosine), then runs algorithm 5 three times with the same sigma_a,
sigma_s and seed:
  - the size-averaged Mie phase function (the particle medium itself),
  - one HG lobe with the Mie g (the usual moment fit),
  - two HG lobes fitted to the Mie table (least squares on log p, report eq. 3.3),
and prints H0, the scattered part and the rms delay spread of each, and plots the CIRs.

Run: .venv/bin/python examples/soot_room.py --out out/soot [--paths 200000]
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
from scipy.optimize import least_squares  # noqa: E402

from owcsim.engine.media import mie, report  # noqa: E402
from owcsim.engine.media.phase import HenyeyGreenstein  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

HERE = Path(__file__).resolve().parent


def two_hg_fit(cos_theta: np.ndarray, phase: np.ndarray) -> tuple[float, float, float]:
    """(w, g1, g2) of w HG(g1) + (1 - w) HG(g2) closest to the table in log p, points uniform in theta."""
    theta = np.linspace(0.0, np.pi, 721)
    c = np.cos(theta)
    target = np.log(np.interp(c, cos_theta, phase))

    def residual(v):
        w, g1, g2 = v
        mix = w * HenyeyGreenstein(g1).eval(c) + (1 - w) * HenyeyGreenstein(g2).eval(c)
        return np.log(mix) - target

    fit = least_squares(residual, x0=[0.9, 0.6, -0.2], bounds=([0.0, 0.0, -0.95], [1.0, 0.95, 0.95]))
    return tuple(float(v) for v in fit.x)


def run(doc: dict, medium: dict, paths: int) -> dict:
    d = copy.deepcopy(doc)
    d["medium"] = medium
    d["simulation"].update(
        algorithm=5, direction="auto", max_reflections=6, max_scattering=20, paths=paths, time_bin_s=5e-10, t_max_s=6e-8
    )
    return simulate(SceneSpec.model_validate(d)).links[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/soot")
    ap.add_argument("--paths", type=int, default=200_000)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for ax, name in zip(axes, ("light", "dense")):
        doc = json.loads((HERE / f"soot_room_{name}.json").read_text())
        spec = SceneSpec.model_validate(doc)
        info = report.describe(spec.medium)
        optics = mie.particle_optics(spec.medium.particles)
        w, g1, g2 = two_hg_fit(optics.cos_theta, optics.phase)
        print(f"\n{doc['name']}")
        print(
            f"  N = {info['number_concentration_per_m3']:.4g} /m^3, sigma_a = {info['sigma_a']:.4g} /m, "
            f"sigma_s = {info['sigma_s']:.4g} /m, albedo = {info['albedo']:.4f}, g = {info['g']:.4f}, "
            f"visibility = {info['visibility_m']:.3g} m"
        )
        print(
            f"  Mie table: {info['phase']['points']} points, normalisation {info['phase']['normalisation']:.7f}, "
            f"mean cosine {info['phase']['mean_cosine']:.6f}"
        )
        print(f"  two-HG fit: {w:.3f} HG({g1:.3f}) + {1 - w:.3f} HG({g2:.3f}), mean cosine {w * g1 + (1 - w) * g2:.4f}")
        hom = {"type": "homogeneous", "sigma_a": info["sigma_a"], "sigma_s": info["sigma_s"]}
        cases = {
            "Mie (particles)": doc["medium"],
            f"HG, g = {info['g']:.3f}": {**hom, "phase": {"type": "hg", "g": info["g"]}},
            "two-HG fit": {
                **hom,
                "phase": {
                    "type": "mixture",
                    "components": [
                        {"weight": w, "phase": {"type": "hg", "g": g1}},
                        {"weight": 1 - w, "phase": {"type": "hg", "g": g2}},
                    ],
                },
            },
        }
        for label, medium in cases.items():
            link = run(doc, medium, args.paths)
            scattered = sum(link.dc_gain_by_scattering_order[1:])
            print(
                f"  {label:16s} H0 = {link.dc_gain:.5g} +- {link.dc_gain_stderr:.2g}  "
                f"(LOS {link.los_gain:.4g}, scattered {scattered:.4g}), "
                f"tau_rms = {link.rms_delay_spread_s * 1e9:.3f} ns"
            )
            cir = np.asarray(link.cir.total, float)
            t = (np.arange(len(cir)) + 0.5) * 5e-10
            ax.semilogy(t * 1e9, np.where(cir > 0, cir, np.nan), label=label, lw=1)
        ax.set_title(f"soot {name}: V = {info['visibility_m']:.3g} m")
        ax.set_xlabel("t [ns]")
        ax.set_ylabel("h(t) per bin [1/W]")
        ax.legend()
    fig.tight_layout()
    fig.savefig(out / "soot_room_cir.png", dpi=120)
    print(f"\nCIR plot: {out / 'soot_room_cir.png'}")


if __name__ == "__main__":
    main()
