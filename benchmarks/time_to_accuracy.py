"""Time to accuracy: scene load to result at a target relative standard error on H0.

The 5 x 5 x 3 m room (walls and ceiling 0.8, floor 0.3), Tx (2.5, 2.5, 3) down m = 1,
Rx (1, 1, 0) up, 1 cm^2, FOV 90 deg, all reflection orders (max_reflections 200 with
Russian roulette), target 0.001. Timed in-process from the JSON text to the result
document (imports excluded), for each estimator direction, with 1 process and with
a warm pool of 2 workers. The anchor: a trusted general-purpose renderer takes 0.46 s
for this on this machine (scene load included).
Run: .venv/bin/python benchmarks/time_to_accuracy.py [--target 0.001] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import barry_doc  # noqa: E402
from owcsim.engine.run.execution import ProcessExecutor  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

ANCHOR_S = 0.46


def scene_text(target: float, direction: str) -> str:
    doc = barry_doc(
        paths=None,
        target_rel_error=target,
        max_reflections=200,
        direction=direction,
        time_bin_s=1e-9,
        t_max_s=4e-7,
        batch_size=16384,
    )
    doc["receivers"][0].update(position=[1.0, 1.0, 0.0], fov_deg=90.0)
    return json.dumps(doc)


def run_once(text: str, executor=None):
    t = time.perf_counter()
    spec = SceneSpec.model_validate_json(text)
    res = simulate(spec, executor=executor)
    return time.perf_counter() - t, res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--target", type=float, default=1e-3)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    pool = ProcessExecutor(2)
    try:
        run_once(scene_text(0.05, "backward"), pool)  # start the workers once
        print(f"target rel. stderr {args.target:g}, all orders; anchor renderer {ANCHOR_S} s")
        print(
            f"{'direction':10s} {'workers':>7s} {'time s':>7s} {'vs anchor':>9s} {'paths':>9s} "
            f"{'rel.err':>8s} {'H0':>13s}  stop"
        )
        for direction in ("backward", "forward", "auto"):
            for executor, label in ((None, "1"), (pool, "2 warm")):
                text = scene_text(args.target, direction)
                runs = [run_once(text, executor) for _ in range(args.repeats)]
                el, res = min(runs, key=lambda r: r[0])
                link = res.links[0]
                rel = link.dc_gain_stderr / link.dc_gain
                print(
                    f"{direction:10s} {label:>7s} {el:7.3f} {ANCHOR_S / el:8.2f}x {link.paths:9d} "
                    f"{rel:8.2e} {link.dc_gain:.6e}  {res.run.stop_reason} ({link.direction})"
                )
    finally:
        pool.close()


if __name__ == "__main__":
    main()
