"""What particle smoke costs: the Mie computation per spec, and sampling a tabulated phase function.

1. Wall time of engine.media.mie.particle_optics (size nodes, table of 2001 angles) for a few
   particle specs, from small soot to the largest size parameter the schema accepts
   (the cache is cleared before each).
2. Phase sampling: sample_cos of HG(0.7) against a 4001-point table of the same HG and
   the 2001-point Mie table of soot, per million cosines (ratio to HG).
3. Whole engine: algorithm 5 in Barry configuration A with HG(g) and with the Mie table of
   the same g (ratio of run times, same paths).
Timings are wall-clock, best of N; on a shared machine they are noisy.
Run: .venv/bin/python benchmarks/mie_cost.py [--repeats 3] [--paths 100000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import barry_doc, best_of  # noqa: E402
from owcsim.engine.media import mie  # noqa: E402
from owcsim.engine.media.phase import HenyeyGreenstein, MiePhase, Tabulated  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402
from owcsim.schemas.medium import MAX_SIZE_PARAMETER, SIZE_WINDOW_SIGMAS, ParticlesSpec  # noqa: E402

SOOT = {
    "geometric_mean_diameter": 1.5e-7,
    "geometric_std": 1.8,
    "refractive_index": {"real": 1.57, "imag": 0.56},
    "wavelength": 8.5e-7,
}
CASES = {
    "soot, D_g 0.15 um, sigma_g 1.8, 850 nm": SOOT,
    "soot, D_g 0.5 um, sigma_g 2.0, 450 nm": {
        **SOOT,
        "geometric_mean_diameter": 5e-7,
        "geometric_std": 2.0,
        "wavelength": 4.5e-7,
    },
    "water fog, D_g 4 um, sigma_g 1.5, 850 nm": {
        **SOOT,
        "geometric_mean_diameter": 4e-6,
        "geometric_std": 1.5,
        "refractive_index": {"real": 1.33, "imag": 0.0},
    },
    "largest accepted size parameter, non-absorbing": {
        "geometric_mean_diameter": 0.999
        * MAX_SIZE_PARAMETER
        * 8.5e-7
        / np.pi
        / np.exp(2 * np.log(1.5) ** 2 + SIZE_WINDOW_SIGMAS * np.log(1.5)),
        "geometric_std": 1.5,
        "refractive_index": {"real": 1.5, "imag": 0.0},
        "wavelength": 8.5e-7,
    },
    "largest accepted size parameter, soot": {
        "geometric_mean_diameter": 0.999
        * MAX_SIZE_PARAMETER
        * 8.5e-7
        / np.pi
        / np.exp(2 * np.log(2.0) ** 2 + SIZE_WINDOW_SIGMAS * np.log(2.0)),
        "geometric_std": 2.0,
        "refractive_index": {"real": 1.57, "imag": 0.56},
        "wavelength": 8.5e-7,
    },
}


def _optics(p):
    mie._optics.cache_clear()
    return mie.particle_optics(p)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--paths", type=int, default=100_000)
    args = ap.parse_args()

    print("1. Mie optics of a size distribution (size nodes x 2001 angles)")
    soot = None
    for name, doc in CASES.items():
        p = ParticlesSpec.model_validate(doc)
        t, o = best_of(args.repeats, lambda p=p: _optics(p))
        soot = soot or o
        print(f"   {name:62s} {t:7.3f} s  nodes {o.nodes:5d}  g {o.g:.4f}  albedo {o.c_sca / o.c_ext:.3f}")

    print("2. sample_cos, 1e6 cosines")
    u = np.random.default_rng(1).random(1_000_000)
    c = np.cos(np.pi * (np.arange(4001) / 4000) ** 2)[::-1].copy()
    c[0], c[-1] = -1.0, 1.0
    hg = HenyeyGreenstein(0.7)
    fns = {
        "HG(0.7) closed form": hg,
        "4001-point table of HG(0.7)": Tabulated(c, hg.eval(c)),
        "2001-point Mie table (soot)": MiePhase(soot.cos_theta, soot.phase),
    }
    base = None
    for name, f in fns.items():
        t, _ = best_of(args.repeats, lambda f=f: f.sample_cos(u))
        base = base or t
        print(f"   {name:40s} {t * 1e3:7.1f} ms  x{t / base:.2f}")

    print(f"3. algorithm 5, Barry configuration A, {args.paths:,d} paths")
    g = soot.g
    media = {
        f"HG(g = {g:.3f})": {"type": "hg", "g": g},
        "Mie table of the same g": {
            "type": "tabulated",
            "cos_theta": soot.cos_theta.tolist(),
            "values": soot.phase.tolist(),
        },
    }
    base = None
    for name, phase in media.items():
        doc = barry_doc(algorithm=5, paths=args.paths, max_reflections=3, max_scattering=5, seed=3)
        doc["medium"] = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.2, "phase": phase}
        spec = SceneSpec.model_validate(doc)
        t, res = best_of(args.repeats, lambda spec=spec: simulate(spec))
        base = base or t
        lk = res.links[0]
        print(f"   {name:40s} {t:7.2f} s  x{t / base:.2f}  H0 {lk.dc_gain:.5g} +- {lk.dc_gain_stderr:.2g}")


if __name__ == "__main__":
    main()
