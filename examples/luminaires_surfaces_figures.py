"""CIR plots of the luminaire and glossy-floor examples, each next to its Lambertian counterpart.

1. `office_luminaires.json`: four batwing downlights (downlight_batwing.ies) and a
   direct/indirect pendant (pendant_direct_indirect.ldt), against the same room with
   Lambertian (m = 1) emitters at the same places. The receiver's CIR is the sum over the
   five emitters (all sending the same signal, 1 W each).
2. `barry_glossy_floor.json`: Barry's configuration A with a Phong floor (60 % diffuse,
   exponent 30), against the Lambertian floor of the same reflectance (0.3), plus a
   variant whose receiver hangs 1 m above the floor looking down at it (where the gloss
   shows: the specular image of the transmitter).

Run: .venv/bin/python examples/luminaires_surfaces_figures.py --out out/luminaires [--paths 200000]
Writes one PNG per case and the result documents (JSON) next to them.
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


def lambertian_twin(doc: dict) -> dict:
    """The same scene with every luminaire replaced by a Lambertian emitter (m = 1) and every material by its rho."""
    twin = copy.deepcopy(doc)
    for tx in twin["transmitters"]:
        tx.pop("photometry", None)
        tx["lambertian_order"] = 1
    refl = twin["room"]["reflectance"]
    for face, value in list(refl.items()):
        if isinstance(value, dict):
            refl[face] = value["reflectance"]
    return twin


def run(doc: dict, paths: int) -> dict:
    doc = copy.deepcopy(doc)
    doc["simulation"]["paths"] = paths
    return simulate(SceneSpec.model_validate(doc), base_dir=HERE)


def receiver_cir(result: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """(bin start times [ns], h(t) [1/s] summed over the transmitters, total H0)."""
    tb = result.time_bins
    t = (tb.t_min_s + np.arange(tb.n_bins) * tb.time_bin_s) * 1e9
    h = sum(np.asarray(link.cir.total) for link in result.links) / tb.time_bin_s
    return t, h, sum(link.dc_gain for link in result.links)


def plot(case: str, results: dict[str, dict], out: Path, title: str) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, res in results.items():
        t, h, h0 = receiver_cir(res)
        ax.step(t, h, where="post", label=f"{label} (H0 = {h0:.3e})")
    ax.set_xlabel("delay t [ns]")
    ax.set_ylabel("h(t) [1/s]")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / f"{case}.png", dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--paths", type=int, default=200_000)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    office = json.loads((HERE / "office_luminaires.json").read_text())
    glossy = json.loads((HERE / "barry_glossy_floor.json").read_text())
    desk = copy.deepcopy(glossy)
    desk["name"] += ", receiver looking down at the floor"
    desk["receivers"][0].update(position=[1.5, 1.5, 1.0], normal=[0, 0, -1])
    cases = {
        "office_luminaires": (office, "Office: luminaires from .ies / .ldt vs Lambertian emitters"),
        "barry_glossy_floor": (glossy, "Barry A: glossy (Phong) floor vs Lambertian floor"),
        "barry_glossy_floor_desk": (desk, "Barry A, receiver 1 m above the floor facing it: glossy vs Lambertian"),
    }
    for case, (doc, title) in cases.items():
        results = {"photometric / glossy": run(doc, args.paths), "Lambertian": run(lambertian_twin(doc), args.paths)}
        for label, res in results.items():
            name = "lambertian" if label == "Lambertian" else "model"
            (args.out / f"{case}.{name}.json").write_text(res.model_dump_json(indent=1))
        plot(case, results, args.out, title)
        print(f"{case}: " + ", ".join(f"{k} H0 = {receiver_cir(v)[2]:.4e}" for k, v in results.items()))


if __name__ == "__main__":
    main()
