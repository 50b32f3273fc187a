"""Cost per path of real luminaires and glossy surfaces, relative to the Lambertian room (target <= 1.3x).

Barry configuration A (K = 3, algorithm 1), the same number of paths in each case, in one run:
  1. Lambertian room, Lambertian (m = 1) transmitter: the baseline;
  2. the transmitter from a photometric file (examples/downlight_batwing.ies): tabulated sampling + NEE;
  3. Phong floor and walls (modified Phong, n = 30 and 5): lobe selection, glossy sampling, BRDF in NEE;
  4. both; 5. a mirror floor (image connections) for scale.
The same five cases in the furnished room (a desk and a cabinet: shadow rays are cast, as in
most real scenes) show the overhead where the Lambertian baseline is not the bare box room.
Both estimator directions are timed (forward: the luminaire is sampled at every path start;
backward: it is evaluated at every next-event connection). Prints best-of-N wall and CPU
times (process time: less disturbed by other programs on a shared machine), CPU time per
path and the CPU-time ratio against case 1 of the same direction. The cases of one room and
direction are timed round robin (repeat 1 of every case, then repeat 2, ...), so that a slow
spell of a shared machine hits all of them.
Run: .venv/bin/python benchmarks/luminaires_surfaces.py [--paths 400000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import base64
import copy
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import ROOT, barry_doc  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

PHONG_FLOOR = {"type": "phong", "reflectance": 0.3, "diffuse_fraction": 0.6, "exponent": 30}
PHONG_WALLS = {"type": "phong", "reflectance": 0.8, "diffuse_fraction": 0.7, "exponent": 5}
MIRROR_FLOOR = {"type": "mirror", "reflectance": 0.3, "diffuse_fraction": 0.5}


def luminaire(doc: dict) -> dict:
    data = (ROOT / "examples" / "downlight_batwing.ies").read_bytes()
    tx = doc["transmitters"][0]
    tx.pop("lambertian_order")
    tx["photometry"] = {"data_base64": base64.b64encode(data).decode("ascii"), "format": "ies"}
    return doc


def glossy(doc: dict) -> dict:
    doc["room"]["reflectance"] = {"floor": PHONG_FLOOR, "ceiling": 0.8, "walls": PHONG_WALLS}
    return doc


def mirror(doc: dict) -> dict:
    doc["room"]["reflectance"]["floor"] = MIRROR_FLOOR
    return doc


CASES = {
    "Lambertian room, Lambertian Tx": [],
    "tabulated luminaire (.ies)": [luminaire],
    "Phong floor and walls": [glossy],
    "luminaire + Phong surfaces": [luminaire, glossy],
    "mirror floor (for scale)": [mirror],
}


FURNITURE = [
    {"name": "desk", "min": [1.5, 1.5, 0.0], "max": [3.0, 2.3, 0.75], "reflectance": 0.5},
    {"name": "cabinet", "min": [4.3, 0.2, 0.0], "max": [4.9, 1.4, 1.9], "reflectance": 0.6},
]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", type=int, default=400_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"Barry configuration A, K = 3, algorithm 1, {args.paths:,d} paths, best of {args.repeats}")
    for room, direction in (
        ("empty", "forward"),
        ("empty", "backward"),
        ("furnished", "forward"),
        ("furnished", "backward"),
    ):
        specs = {}
        for name, edits in CASES.items():
            doc = barry_doc(paths=args.paths, max_reflections=3, direction=direction, algorithm=1)
            if room == "furnished":
                doc["furniture"] = FURNITURE
            for edit in edits:
                doc = edit(copy.deepcopy(doc))
            specs[name] = SceneSpec.model_validate(doc)
            simulate(specs[name])  # warm-up (imports, Embree build)
        # round robin over the cases: a slow spell of the machine hits every case, not one
        wall = dict.fromkeys(specs, float("inf"))
        cpu = dict.fromkeys(specs, float("inf"))
        links = {}
        for _ in range(args.repeats):
            for name, spec in specs.items():
                t0, c0 = time.perf_counter(), time.process_time()
                links[name] = simulate(spec).links[0]
                wall[name] = min(wall[name], time.perf_counter() - t0)
                cpu[name] = min(cpu[name], time.process_time() - c0)
        base = cpu[next(iter(specs))]
        for name in specs:
            link = links[name]
            print(
                f"{room:9s} {direction:8s} {name:32s} wall {wall[name]:6.3f} s  cpu {cpu[name]:6.3f} s  "
                f"{cpu[name] / args.paths * 1e6:5.2f} us/path  x{cpu[name] / base:5.2f}  "
                f"H0 = {link.dc_gain:.4e} +- {link.dc_gain_stderr:.1e}"
            )


if __name__ == "__main__":
    main()
