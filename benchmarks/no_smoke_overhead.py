"""A scene without smoke pays nothing for smoke support.

Barry configuration A, K = 3, algorithm chosen automatically, timed with: no medium;
a medium with sigma_t = 0 (auto drops it: vacuum paths); a smoke box region outside
the room (auto: dropped, as it cannot touch any path; algorithm 1: rays never enter it,
the medium code only clips segments against the box);
and, for scale, the same room filled with that smoke (algorithm 1, extinction only).
Prints best-of-N times and ratios against the first; medium evaluations are counted.
Run: .venv/bin/python benchmarks/no_smoke_overhead.py [--paths 400000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks._common import barry_doc, best_of  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

SMOKE = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.7}}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", type=int, default=400_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    cases = {
        "no medium": None,
        "medium with sigma_t = 0": {"type": "homogeneous", "sigma_a": 0.0, "sigma_s": 0.0},
        "smoke box outside the room (auto)": dict(
            SMOKE, region={"type": "box", "min": [10, 10, 0], "max": [12, 12, 3]}
        ),
        "smoke box outside the room (algorithm 1)": dict(
            SMOKE, region={"type": "box", "min": [10, 10, 0], "max": [12, 12, 3]}
        ),
        "room full of smoke (algorithm 1)": SMOKE,
    }
    print(f"Barry configuration A, K = 3, {args.paths:,d} paths, best of {args.repeats}")
    base = None
    for name, medium in cases.items():
        doc = barry_doc(paths=args.paths, max_reflections=3, direction="backward", algorithm="auto")
        if medium is not None:
            doc["medium"] = medium
        if name.endswith("(algorithm 1)"):
            doc["simulation"]["algorithm"] = 1
        spec = SceneSpec.model_validate(doc)
        t, res = best_of(args.repeats, lambda spec=spec: simulate(spec))
        base = base or t
        print(
            f"{name:42s} {t:7.3f} s  x{t / base:5.2f}  algorithm {res.algorithm}, "
            f"medium evaluations {res.diagnostics.medium_evaluations:,d}"
        )


if __name__ == "__main__":
    main()
