"""Cost of a 60-frame timeline by reweighting one set of paths, against one frame's run and independent runs (issue 26).

Scene: a 6 x 4 x 3 m room (walls and ceiling 0.7, floor 0.3), one link: Tx at (1.5, 2, 2.4) facing down
(m = 1), Rx on a desk at (4.5, 2, 0.8) facing up (1 cm^2, FOV 90 deg). The medium: a 0.1 m grid of the room
(60 x 40 x 30 cells) holding smoke in a ceiling layer that grows with time, as a fire's hot layer does:
at frame f (0..F-1, fraction x = f / (F - 1)) the layer fills z > 3 - 1.5 x m, its extinction rising from
0.2 x /m at the layer's bottom to (0.2 + 2.3 x) /m under the ceiling, with a little horizontal
structure (+-10 % cell to cell, one fixed pattern), albedo 0.4 (0.3 at the bottom to 0.5 at the top),
isotropic phase function. Every run asks 1 % on H0 (target_rel_error 0.01) with the automatic settings.

Figures, all measured in this run, CPU time of this process (`time.process_time`: numpy and Embree run on the
calling thread, SerialExecutor), which other jobs on a shared host disturb far less than wall time:
- one frame's run: `simulate` of the last frame (the thickest smoke, the most paths), and of the middle one;
- the reweighted timeline: `simulate_reweighted` of all F frames (pilots included), its paths, its windows;
- independent runs: `simulate` of `--subset` frames evenly spaced, scaled by F / subset;
- the ratios: reweighted / one frame (the issue's target: at most 10), independent / reweighted.
Run: .venv/bin/python benchmarks/timeline_cost.py [--frames 60] [--subset 4] [--target 0.01] [--markdown]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from owcsim.engine.media.frames import MediumFrames  # noqa: E402
from owcsim.engine.run import frames_reweighted as fr  # noqa: E402
from owcsim.engine.run.simulate import simulate  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402

SIZE = (6.0, 4.0, 3.0)
SHAPE = (60, 40, 30)


def room(target: float, seed: int = 1) -> SceneSpec:
    return SceneSpec.model_validate(
        {
            "room": {"size": list(SIZE), "reflectance": {"floor": 0.3, "ceiling": 0.7, "walls": 0.7}},
            "transmitters": [{"id": "tx", "position": [1.5, 2.0, 2.4], "normal": [0, 0, -1], "lambertian_order": 1}],
            "receivers": [{"id": "rx", "position": [4.5, 2.0, 0.8], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 90}],
            "simulation": {"target_rel_error": target, "seed": seed},
        }
    )


def fire_frames(n: int) -> MediumFrames:
    """The growing ceiling layer of the module docstring, n frames 10 s apart."""
    rng = np.random.default_rng(26)
    pattern = rng.uniform(0.9, 1.1, SHAPE)
    z = (np.arange(SHAPE[2]) + 0.5) * SIZE[2] / SHAPE[2]  # cell centres [m]
    a, s = np.zeros((n,) + SHAPE), np.zeros((n,) + SHAPE)
    for f in range(n):  # a loop over frames, building the input only
        x = f / max(n - 1, 1)
        bottom = SIZE[2] - 1.5 * x
        depth = np.clip((z - bottom) / max(1.5 * x, 1e-9), 0.0, 1.0) * (z > bottom)  # 0 at the bottom, 1 at the top
        sigma_t = np.where(z > bottom, 0.2 * x + 2.3 * x * depth, 0.0)[None, None, :] * pattern
        albedo = 0.3 + 0.2 * depth
        s[f] = sigma_t * albedo[None, None, :]
        a[f] = sigma_t - s[f]
    return MediumFrames(np.arange(n) * 10.0, [0, 0, 0], list(SIZE), a, s)


def timed(fn):
    t = time.process_time()
    out = fn()
    return out, time.process_time() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--subset", type=int, default=4)
    ap.add_argument("--target", type=float, default=0.01)
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    F = args.frames
    frames = fire_frames(F)
    doc = room(args.target)
    picks = np.unique(np.linspace(0, F - 1, args.subset).round().astype(int))
    single = {}
    for f in picks:
        res, sec = timed(lambda f=f: simulate(fr._with_medium(doc, frames, int(f))))
        link = res.links[0]
        single[int(f)] = (sec, res.run.paths_total, link.dc_gain, link.dc_gain_stderr)
    (results, groups), sec_rw = timed(lambda: fr.simulate_reweighted(doc, frames))
    one = single[int(picks[-1])][0]
    mid = min(single, key=lambda f: abs(f - (F - 1) / 2))
    independent = np.mean([v[0] for v in single.values()]) * F
    rel = [r.links[0].dc_gain_stderr / r.links[0].dc_gain for r in results]
    rows = [
        ("frames", F),
        ("one frame's run, last frame [CPU s]", f"{one:.2f}"),
        (f"one frame's run, frame {mid} [CPU s]", f"{single[mid][0]:.2f}"),
        (f"independent runs, {len(picks)} frames x {F}/{len(picks)} [CPU s]", f"{independent:.1f}"),
        ("reweighted timeline [CPU s]", f"{sec_rw:.1f}"),
        ("reweighted / one frame (target <= 10)", f"{sec_rw / one:.1f}"),
        ("independent / reweighted", f"{independent / sec_rw:.1f}"),
        (
            "reweighted paths (one frame alone: last frame)",
            f"{results[0].run.paths_total} ({single[int(picks[-1])][1]})",
        ),
        ("algorithm (reweighted carrier)", str(results[0].algorithm)),
        ("worst frame's relative stderr of H0", f"{max(rel):.4f}"),
        ("windows (carriers)", str(len({_window(r) for r in results}))),
        ("smallest effective sample size over the carrier's", f"{min(_ess(r) for r in results):.2f}"),
    ]
    for f in picks:
        r = results[int(f)].links[0]
        sec, _, h, se = single[int(f)]
        rows.append(
            (
                f"frame {int(f)}: H0 reweighted / alone",
                f"{r.dc_gain:.4e} +- {r.dc_gain_stderr:.1e} / {h:.4e} +- {se:.1e}",
            )
        )
    if groups is not None:
        d = groups[1:, 0] - groups[:-1, 0]
        se_d = d.std(axis=1, ddof=1) / np.sqrt(d.shape[1])
        indep = np.hypot(
            [r.links[0].dc_gain_stderr for r in results[1:]], [r.links[0].dc_gain_stderr for r in results[:-1]]
        )
        rows.append(("stderr of H0(f+1) - H0(f) over independent runs' (median)", f"{np.median(se_d / indep):.2f}"))
    if args.markdown:
        print("| figure | value |\n|---|---|")
        for k, v in rows:
            print(f"| {k} | {v} |")
    else:
        for k, v in rows:
            print(f"{k:62s} {v}")


def _window(result) -> str:
    return next(w for w in result.warnings if w.startswith("frames:")).split("carrier of frames ")[1].split(" ")[0]


def _ess(result) -> float:
    text = next(w for w in result.warnings if w.startswith("frames:"))
    return float(text.split("effective sample size is ")[1].split(" ")[0])


if __name__ == "__main__":
    main()
