"""Cost of random orientation on a map (docs/orientation.md): the same map with and without `orientation`.

Komine's office (examples/komine_map.json, four lamps, one group), a grid of N x N points at desk
height; each point with `samples` orientations becomes samples + 1 receivers. Prints, measured in
this run: the wall time of simulate() for the plain map and the oriented one, their ratio, and the
time per receiver, in line of sight (exact) and with reflections (K = 3, a fixed number of forward
paths per lamp: the cost of the extra receivers' connections).

Run: .venv/bin/python benchmarks/orientation_cost.py [--points 50] [--samples 32] [--paths 20000] [--skip-mc]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from owcsim.engine.run.simulate import simulate
from owcsim.schemas import SceneSpec

ROOT = Path(__file__).resolve().parent.parent


def office(points: int, samples: int | None, simulation: dict) -> SceneSpec:
    doc = json.loads((ROOT / "examples" / "komine_map.json").read_text())
    grid = doc["receiver_grids"][0]
    grid["spacing"] = grid["size"][0] / (points - 1)
    if samples:
        grid["orientation"] = {"model": "sitting", "samples": samples}
    doc["simulation"] = {"seed": 1, **simulation}
    return SceneSpec.model_validate(doc)


def timed(spec: SceneSpec) -> tuple[float, int]:
    t0 = time.perf_counter()
    result = simulate(spec)
    return time.perf_counter() - t0, len(result.receivers)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=50, help="grid points per side (line of sight)")
    ap.add_argument("--mc-points", type=int, default=10, help="grid points per side (with reflections)")
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--paths", type=int, default=20_000, help="forward paths per lamp (with reflections)")
    ap.add_argument("--skip-mc", action="store_true", help="line of sight only")
    args = ap.parse_args()
    cases = [("line of sight", args.points, {"max_reflections": 0})]
    if not args.skip_mc:
        mc = {"max_reflections": 3, "algorithm": 1, "direction": "forward", "paths": args.paths}
        cases.append((f"K = 3, {args.paths} paths", args.mc_points, mc))
    for label, points, sim in cases:
        plain, n_plain = timed(office(points, None, sim))
        held, n_held = timed(office(points, args.samples, sim))
        print(
            f"{label}, {points} x {points} points: plain {plain:.2f} s ({n_plain} receivers), "
            f"{args.samples} orientations {held:.2f} s ({n_held} receivers): ratio {held / plain:.1f}, "
            f"{1e6 * held / n_held:.0f} us per receiver"
        )


if __name__ == "__main__":
    main()
