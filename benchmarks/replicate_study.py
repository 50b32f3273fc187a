"""Replicate study of the error bars in smoke (issue 12): is the reported standard error the real one?

For each case (the 5 x 5 x 3 m room with smoke sigma_s 0.2 /m, sigma_a 0, and an
unbounded medium sigma_s 0.2, sigma_a 0.05 /m; HG g = 0, 0.7, 0.9; devices 0.5 m and
3 m apart) and each estimator (algorithms 2, 3, 5 one-sided as `simulate` runs them,
and algorithms 2, 3, 4, 5 from both devices, engine/run/simulate.simulate_two_sided), the script runs
`--seeds` independent seeds of `--paths` paths (per side) and prints:
- ratio: the spread (sample standard deviation) of H0 over the seeds / the median
  reported standard error (1 when the error bars are honest; the issue asks 0.7-1.5);
- max z: the largest |H0 - reference| / (its own reported standard error), the reference
  being the mean of the two-sided runs of the same algorithm (leave-one-out for those);
- flagged: runs whose result would carry engine/tally/reliability.py's warning.
Room: Tx (2.5, 2.5, 3) down, Rx 0.5 m or 3 m below it facing up, K = 3 (algorithm 5: S = 3).
Unbounded: Tx at the origin facing +x, Rx at (D, 0, 0) facing it, S = 2.
Run: .venv/bin/python benchmarks/replicate_study.py [--seeds 10] [--paths 4096] [--json out/replicates.json]

`--study accuracy`: accuracy mode (paths = None, target_rel_error) over `--seeds` seeds at
targets 3 % and 1 % on the smoky rooms (Tx (2.5, 2.5, 3) down, Rx (1, 1, 0) up, FOV 90,
sigma_s 0.2, sigma_a 0, g 0.5 and g 0.9; K = S = 8): "before" = algorithm 5 as `simulate`
runs it on main (one side, chosen by the pilot, roulette theta = 1) stopping on the per-path
error alone; "after" =
algorithm 5 from both devices with engine/tally/reliability.py's stopping rule. The true error
is measured against a long two-sided run (`--ref-paths` per side) of the same K, S.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from owcsim.engine.run import simulate as engine  # noqa: E402
from owcsim.schemas import SceneSpec  # noqa: E402


def simulate(*args, **kwargs) -> dict:
    """The result document (as result.json holds it): this study edits and compares documents."""
    return json.loads(engine.simulate(*args, **kwargs).model_dump_json())


def simulate_two_sided(*args, **kwargs) -> dict:
    return json.loads(engine.simulate_two_sided(*args, **kwargs).model_dump_json())


VARIANTS = [(2, "one"), (3, "one"), (5, "one"), (2, "two"), (3, "two"), (4, "two"), (5, "two")]


def scene(geometry: str, g: float, D: float, algorithm: int, paths: int, seed: int, quasi_random: bool = True) -> dict:
    sim = {
        "quasi_random": quasi_random,
        "algorithm": algorithm,
        "paths": paths,
        "seed": seed,
        "batch_size": max(64, paths // 16),
        "time_bin_s": 1e-9,
        "t_max_s": 2e-7,
        "segment_time_step_s": 5e-9,
        "max_strata": 8,
    }
    if geometry == "room":
        sim.update(max_reflections=3, **({"max_scattering": 3} if algorithm == 5 else {}))
        return {
            "room": {"size": [5, 5, 3], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": 0.8}},
            "transmitters": [{"id": "tx", "position": [2.5, 2.5, 3.0], "normal": [0, 0, -1], "lambertian_order": 1}],
            "receivers": [
                {"id": "rx", "position": [2.5, 2.5, 3.0 - D], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 90}
            ],
            "medium": {"type": "homogeneous", "sigma_a": 0.0, "sigma_s": 0.2, "phase": {"type": "hg", "g": g}},
            "simulation": sim,
        }
    sim.update(max_reflections=0, **({"max_scattering": 2} if algorithm == 5 else {}))
    return {
        "transmitters": [{"id": "tx", "position": [0, 0, 0], "normal": [1, 0, 0], "lambertian_order": 1}],
        "receivers": [{"id": "rx", "position": [D, 0, 0], "normal": [-1, 0, 0], "area": 1e-4, "fov_deg": 90}],
        "medium": {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": g}},
        "simulation": sim,
    }


def run(doc: dict, sides: str) -> dict:
    spec = SceneSpec.model_validate(doc)
    res = simulate(spec) if sides == "one" else simulate_two_sided(spec)
    return res


def _flagged(res) -> bool:
    return any("unreliable error bar" in w for w in res.get("warnings", []))


def smoky_room(g: float, seed: int, **sim) -> dict:
    doc = scene("room", g, 3.0, 5, 4096, seed)
    doc["receivers"][0]["position"] = [1.0, 1.0, 0.0]
    doc["simulation"].update(max_reflections=8, max_scattering=8, t_max_s=3e-7, **sim)
    return doc


def accuracy_study(args) -> None:
    import owcsim.engine.run.simulate as sim_mod

    print(
        f"accuracy mode, {args.seeds} seeds per row; true error against a long two-sided run "
        f"({args.ref_paths:,d} paths per side); batch_size 1024; "
        f"{'pseudo-random paths' if args.pseudo_random else 'quasi-random blocks of 256 paths'}"
    )
    print(
        f"{'scene':22s} {'target':>6s} {'variant':8s} {'within 2x':>9s} {'median paths':>12s} "
        f"{'median |err|/target':>19s} {'worst |err|/target':>18s} {'median s':>8s}"
    )
    for g in (0.5, 0.9):
        t = time.perf_counter()
        ref = simulate_two_sided(
            SceneSpec.model_validate(smoky_room(g, 999_999, paths=args.ref_paths, batch_size=32768))
        )["links"][0]
        print(
            f"reference g={g}: H0 = {ref['dc_gain']:.6e} +- {ref['dc_gain_stderr'] / ref['dc_gain']:.3%} "
            f"({time.perf_counter() - t:.0f} s)",
            flush=True,
        )
        for target in (0.03, 0.01):
            for variant in args.variants.split(","):
                errs, paths, times = [], [], []
                for seed in range(args.seeds):
                    doc = smoky_room(
                        g, 500 + seed, paths=None, target_rel_error=target, batch_size=1024, time_budget_s=600
                    )
                    doc["simulation"]["quasi_random"] = not args.pseudo_random
                    if variant == "before":
                        doc["simulation"]["direction"] = "auto"
                        keep = sim_mod.reliability.may_stop, sim_mod.kernel_settings
                        sim_mod.reliability.may_stop = lambda *a, **k: True  # the old rule: per-path error only
                        sim_mod.kernel_settings = lambda spec, _k=keep[1]: dataclasses.replace(
                            _k(spec), rr_threshold=1.0
                        )  # and the old roulette
                        try:
                            t = time.perf_counter()
                            res = simulate(SceneSpec.model_validate(doc))
                        finally:
                            sim_mod.reliability.may_stop, sim_mod.kernel_settings = keep
                    else:
                        t = time.perf_counter()
                        res = simulate_two_sided(SceneSpec.model_validate(doc))
                    times.append(time.perf_counter() - t)
                    link = res["links"][0]
                    errs.append(abs(link["dc_gain"] - ref["dc_gain"]) / ref["dc_gain"] / target)
                    paths.append(res["run"]["paths_total"])
                errs = np.array(errs)
                print(
                    f"{'smoky room g=' + str(g):22s} {target:6.0%} {variant:8s} "
                    f"{int((errs <= 2).sum()):4d}/{len(errs):<4d} {int(np.median(paths)):12,d} "
                    f"{np.median(errs):19.2f} {errs.max():18.2f} {np.median(times):8.2f}",
                    flush=True,
                )


def clear_room(seed: int, **sim) -> dict:
    """The S1 link of issue 12: the smoky room's geometry without smoke (algorithm 1, K = 40)."""
    doc = smoky_room(0.5, seed, **sim)
    del doc["medium"]
    doc["simulation"].update(algorithm=1, max_reflections=40)
    doc["simulation"].pop("max_scattering", None)
    return doc


ROULETTE = [(3, 1.0), (5, 1.0), (8, 1.0), (3, 0.5), (3, 0.25), (5, 0.5), (5, 0.25), (3, 0.1), (1000, 1.0)]


def roulette_study(args) -> None:
    """Variance per path x cost per path of roulette start depths and thresholds (KernelSettings)."""
    print(
        f"roulette: start depth d (k + s) and threshold theta, survival min(1, w / (theta w0)); "
        f"{args.paths:,d} paths per side per setting; efficiency = 1 / (rel. variance per path x s per path), "
        "relative to d = 3, theta = 1 (the old rule); d = 1000: no roulette"
    )
    cases = [
        (
            "clear room S1, algorithm 1 backward",
            lambda seed: clear_room(seed, paths=args.paths, batch_size=16384),
            "backward",
            0.0003,
        ),
        (
            "smoky room g 0.5, algorithm 5 both",
            lambda seed: smoky_room(0.5, seed, paths=args.paths, batch_size=16384),
            "both",
            0.003,
        ),
    ]
    for name, make, direction, target in cases:
        print(name)
        print(
            f"{'d':>5s} {'theta':>6s} {'rel std/path':>12s} {'us/path':>8s} {'rays/path':>9s} {'efficiency':>10s} "
            f"{'paths to ' + format(target, '.2%'):>16s} {'s to target':>11s}"
        )
        base = None
        for depth, theta in ROULETTE:
            spec = SceneSpec.model_validate(make(11))
            t = time.perf_counter()
            res = simulate_two_sided(spec, direction=direction, rr_start_depth=depth, rr_threshold=theta)
            el = time.perf_counter() - t
            link = res["links"][0]
            n = res["run"]["paths_total"]
            sides = 2 if direction == "both" else 1
            rel_std = link["dc_gain_stderr"] / link["dc_gain"] * np.sqrt(n / sides)  # per path of one side
            per_path = el / n
            rays = (res["run"]["rays_intersect"] + res["run"]["rays_occluded"]) / n
            eff = 1.0 / (rel_std**2 * per_path)
            base = base or eff
            need = sides * (rel_std / target) ** 2
            print(
                f"{depth:5d} {theta:6.2f} {rel_std:12.3f} {per_path * 1e6:8.2f} {rays:9.2f} {eff / base:10.2f} "
                f"{need:16,.0f} {need * per_path:11.1f}",
                flush=True,
            )


def speed_study(args) -> None:
    """Paths and wall time to 0.03 % on the clear room (S1) and 0.3 % on the smoky room (g 0.5), accuracy mode,
    before (roulette from depth 3 with survival min(1, w / w0), one side) and after, in the same run."""
    from owcsim.engine.integrator.path import KernelSettings

    after = {"rr_start_depth": args.rr_depth, "rr_threshold": args.rr_theta}
    before = {"rr_start_depth": 3, "rr_threshold": 1.0}
    print(
        f"speed to a target (accuracy mode, batches of 16384 (clear) / 2048 (smoky) paths, "
        f"engine/tally/reliability.py's stopping rule); after: roulette "
        f"from depth {args.rr_depth} with theta {args.rr_theta} (kernel default theta "
        f"{KernelSettings.__dataclass_fields__['rr_threshold'].default}); timings on a shared CPU"
    )
    print(f"{'case':44s} {'paths':>10s} {'time s':>7s} {'H0':>13s} {'rel err':>8s}")
    cases = [
        (
            "clear room S1 to 0.03 %",
            clear_room,
            3e-4,
            16384,
            [("before, backward", "backward", before), ("after, backward", "backward", after)],
        ),
        (
            "smoky room g 0.5 to 0.3 %",
            lambda seed, **kw: smoky_room(0.5, seed, **kw),
            3e-3,
            2048,
            [("before, algorithm 5 backward", "backward", before), ("after, algorithm 5 both sides", "both", after)],
        ),
    ]
    for name, make, target, batch, variants in cases:
        for label, direction, rr in variants:
            spec = SceneSpec.model_validate(
                make(21, paths=None, target_rel_error=target, batch_size=batch, time_budget_s=900)
            )
            t = time.perf_counter()
            res = simulate_two_sided(spec, direction=direction, **rr)
            el = time.perf_counter() - t
            link = res["links"][0]
            print(
                f"{name + ': ' + label:44s} {res['run']['paths_total']:10,d} {el:7.1f} {link['dc_gain']:13.6e} "
                f"{link['dc_gain_stderr'] / link['dc_gain']:8.3%}",
                flush=True,
            )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--study", choices=["replicates", "accuracy", "roulette", "speed"], default="replicates")
    ap.add_argument("--rr-depth", type=int, default=3)
    ap.add_argument("--rr-theta", type=float, default=0.25)
    ap.add_argument("--ref-paths", type=int, default=500_000)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--paths", type=int, default=4096)
    ap.add_argument("--json", default=None)
    ap.add_argument("--geometries", default="room,unbounded")
    ap.add_argument("--pseudo-random", action="store_true", help="quasi_random: false (default: the blocks)")
    ap.add_argument("--variants", default="before,after", help="accuracy study: before (main's old rules), after")
    args = ap.parse_args()
    if args.study == "accuracy":
        accuracy_study(args)
        return
    if args.study == "roulette":
        roulette_study(args)
        return
    if args.study == "speed":
        speed_study(args)
        return
    rows = []
    t0 = time.perf_counter()
    print(
        f"{args.seeds} seeds x {args.paths} paths per side, "
        f"{'pseudo-random paths' if args.pseudo_random else 'quasi-random blocks of 256 paths'}; "
        "ratio = spread / median stderr of H0; "
        "max z = worst |H0 - ref| / own stderr"
    )
    print(f"{'case':26s} " + " ".join(f"{a}{'/2s' if s == 'two' else '/1s'}".rjust(15) for a, s in VARIANTS))
    for geometry in args.geometries.split(","):
        for g in (0.0, 0.7, 0.9):
            for D in (0.5, 3.0):
                out = {}
                for algorithm, sides in VARIANTS:
                    vals, errs, flags = [], [], 0
                    for seed in range(args.seeds):
                        # not shared between cases
                        case_seed = zlib.crc32(repr((geometry, g, D, algorithm, sides)).encode()) % 100_000
                        res = run(
                            scene(
                                geometry, g, D, algorithm, args.paths, 1000 * seed + case_seed, not args.pseudo_random
                            ),
                            sides,
                        )
                        link = res["links"][0]
                        vals.append(link["dc_gain"])
                        errs.append(link["dc_gain_stderr"])
                        flags += _flagged(res)
                    out[(algorithm, sides)] = (np.array(vals), np.array(errs), flags)
                cells = []
                for algorithm, sides in VARIANTS:
                    vals, errs, flags = out[(algorithm, sides)]
                    ratio = float(np.std(vals, ddof=1) / np.median(errs))
                    ref_vals = out[(algorithm, "two")][0] if (algorithm, "two") in out else vals
                    if sides == "two":
                        ref = np.array([(ref_vals.sum() - v) / (len(ref_vals) - 1) for v in vals])
                    else:
                        ref = np.full(len(vals), ref_vals.mean())
                    z = float(np.max(np.abs(vals - ref) / errs))
                    rows.append(
                        {
                            "geometry": geometry,
                            "g": g,
                            "D": D,
                            "algorithm": algorithm,
                            "sides": sides,
                            "ratio": ratio,
                            "max_z": z,
                            "flagged": flags,
                            "mean": float(vals.mean()),
                            "median_stderr": float(np.median(errs)),
                        }
                    )
                    cells.append(f"{ratio:5.2f} {z:4.1f} {flags:2d}")
                print(f"{geometry + f' g={g} D={D}':26s} " + " ".join(c.rjust(15) for c in cells), flush=True)
    print(
        f"cells: ratio, max z, runs flagged unreliable (of {args.seeds}); 1s = one-sided as simulate runs it, "
        f"2s = from both devices; {time.perf_counter() - t0:.0f} s (one process, CPU shared with other jobs)"
    )
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
