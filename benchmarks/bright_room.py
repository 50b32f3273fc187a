"""Bright rooms: every order traced (automatic K past the pilot, roulette) against 40 orders plus a geometric tail.

The 5 x 5 x 3 m room with every surface at rho, Tx at the ceiling centre facing down, Rx (1, 1, 0)
facing up (issue 22, item 4). Per rho, over `--seeds` independent runs of `--paths` paths:
- "auto": the automatic settings (K chosen past the pilot's 40 orders when the tail needs it);
- "K=40": the old automatic choice (the pilot's cap), nothing added;
- "K=40 + tail(rho)": plus the geometric tail H_40 rho / (1 - rho) (the a-priori ratio);
- "K=40 + tail(fit)": plus H_40 r / (1 - r), r = (H_31 + .. + H_40) / (H_30 + .. + H_39) of the same run.
It prints the mean H0 against the radiosity reference (tests/reference_radiosity.py, first order exact;
about 0.4 % low at its coarse patches, tests/engine/test_bright_room.py), the spread over seeds, the mean
wall time of a run, and the time a run needs for a root-mean-square error (spread and bias) of 1 % of H0
(infinite when the bias alone exceeds it).
Run: .venv/bin/python benchmarks/bright_room.py [--seeds 5] [--paths 20000] [--rho 0.9 0.99]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np
from _common import ROOT

sys.path.insert(0, str(ROOT))

from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402
from tests.reference import first_bounce_box_dc_gain  # noqa: E402
from tests.reference_radiosity import box_dc_gain  # noqa: E402

SIZE, TX, RX = (5.0, 5.0, 3.0), (2.5, 2.5, 3.0), (1.0, 1.0, 0.0)


def reference(rhos) -> dict[float, float]:
    out = {}
    faces = ("floor", "ceiling", "wall_x_min", "wall_x_max", "wall_y_min", "wall_y_max")
    for rho, (h0, h1) in zip(rhos, box_dc_gain(SIZE, rhos, TX, (0, 0, -1), 1.0, RX, (0, 0, 1), 1e-4)):
        exact = first_bounce_box_dc_gain(
            SIZE, dict.fromkeys(faces, rho), TX, (0, 0, -1), 1.0, RX, (0, 0, 1), 1e-4, math.pi / 2, rel_tol=1e-4
        )
        out[rho] = h0 - h1 + exact
    return out


def doc(rho: float, paths: int, seed: int, **sim) -> SceneSpec:
    d = {
        "room": {"size": list(SIZE), "reflectance": {"floor": rho, "ceiling": rho, "walls": rho}},
        "transmitters": [{"id": "tx", "position": list(TX), "normal": [0, 0, -1], "lambertian_order": 1}],
        "receivers": [{"id": "rx", "position": list(RX), "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 90}],
        "simulation": {"paths": paths, "seed": seed, **sim},
    }
    return SceneSpec.model_validate(d)


def run(spec: SceneSpec):
    t = time.perf_counter()
    res = json.loads(simulate(spec).model_dump_json())
    return time.perf_counter() - t, res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--paths", type=int, default=20_000)
    ap.add_argument("--rho", type=float, nargs="+", default=[0.9, 0.95, 0.99])
    args = ap.parse_args()
    ref = reference(args.rho)
    print(
        f"{'rho':>5s} {'method':18s} {'K':>5s} {'mean H0':>11s} {'bias':>8s} {'spread':>8s} {'time':>7s} {'t(1%)':>9s}"
    )
    for rho in args.rho:
        rows: dict[str, list] = {"auto": [], "K=40": [], "K=40 + tail(rho)": [], "K=40 + tail(fit)": []}
        times: dict[str, list] = {k: [] for k in rows}
        ks = {}
        for seed in range(args.seeds):
            t, res = run(doc(rho, args.paths, seed))
            rows["auto"].append(res["links"][0]["dc_gain"])
            times["auto"].append(t)
            ks["auto"] = res["modeled"]["max_reflections"]
            t, res = run(doc(rho, args.paths, seed, max_reflections=40, t_max_s=res["modeled"]["time_window_s"][1]))
            link = res["links"][0]
            h = np.asarray(link["dc_gain_by_reflection_order"])
            r_fit = h[31:41].sum() / h[30:40].sum()
            for name, extra in (
                ("K=40", 0.0),
                ("K=40 + tail(rho)", h[40] * rho / (1 - rho)),
                ("K=40 + tail(fit)", h[40] * r_fit / (1 - r_fit) if r_fit < 1 else math.inf),
            ):
                rows[name].append(link["dc_gain"] + extra)
                times[name].append(t)
                ks[name] = 40
        for name, values in rows.items():
            v = np.asarray(values) / ref[rho]
            bias, spread = v.mean() - 1, v.std(ddof=1)
            t = float(np.mean(times[name]))
            # time for an rms error of 1e-2: the spread falls as 1/sqrt(time), the bias does not
            need = math.inf if abs(bias) >= 1e-2 else t * spread**2 / (1e-4 - bias**2)
            print(
                f"{rho:5.2f} {name:18s} {ks[name]:5d} {np.mean(values):11.4e} {bias:+8.2%} {spread:8.3%} "
                f"{t:6.2f}s {need:8.1f}s"
            )
    print("reference (radiosity, first order exact): " + ", ".join(f"{r}: {h:.4e}" for r, h in ref.items()))


if __name__ == "__main__":
    main()
