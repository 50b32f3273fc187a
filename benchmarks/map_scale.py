"""Coverage maps at scale: the Komine-Nakagawa room (4 LED lamps, one signal) on a work-plane grid.

Prints, each case run in its own process (peak memory is that process's maximum RSS):
 (a) line of sight only on the 50 x 50 grid: in-process time of `simulate` and the time of the whole
     `owcsim run` command (Python start-up, files written); targets 0.2 s and 5 s;
 (b) every reflection order (automatic K), until every point's DC gain has a relative standard error
     of 1 % or less: time, paths, peak memory, size of the output folder; targets 60 s, 2 GB, 50 MB;
 (c) time and peak memory for 100, 2 500 and 10 000 receivers at a fixed number of paths per
     receiver (receiver-side paths) and per lamp (transmitter-side paths), and time per receiver
     relative to the 100-receiver run: cost must grow no faster than linearly with receivers;
 (d) the two estimator directions on a 10 x 10 grid at fixed paths: time, median and largest relative
     standard error over the points, and the time each would need for 1 % at the worst point
     (time x (rel. error / 1 %)^2): what `auto` chooses for maps;
 (e) cost against receivers, every order at 1 % per point (10 x 10 ... 100 x 100): in-process time, paths,
     peak memory and the points' errors, with this tree and, with --baseline PYTHON, another install's
     interpreter (e.g. main's) in the same run; the exponent of time against receivers fitted on log-log
     (target <= 0.8), and the whole `owcsim run` command for the largest sizes.
 (f) the error bars of a map run per point: a 6 x 6 map at 1 % per point (K = 3) with 12 seeds against a
     fixed-path run of 20 000 paths per point: the fraction of z-scores within 2 and the mean of z^2
     (a Student t with 255 degrees of freedom: 95.4 % and 1.008).
 (g) a map of handheld receivers (8 x 8 points, 16 walking orientations each: 1 024 receivers facing
     different ways) at 2 % per receiver, K = 3: in-process time, paths and batches, this tree and --baseline.
Run: .venv/bin/python benchmarks/map_scale.py [--quick] [--only abcdefg] [--baseline /work/main/.venv/bin/python]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if "MAP_SCALE_BASELINE" not in os.environ:  # a baseline install's child imports its own owcsim
    sys.path.insert(0, str(ROOT))
EXAMPLE = ROOT / "examples" / "komine_map.json"


def komine(points_per_side: int, **simulation) -> dict:
    doc = json.loads(EXAMPLE.read_text())
    g = doc["receiver_grids"][0]
    g["spacing"] = g["size"][0] / (points_per_side - 1)
    doc["simulation"] = {"seed": 1, **simulation}
    return doc


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def child(case: dict) -> dict:
    """One measurement in this process (called with --child)."""
    from owcsim.engine.run.simulate import simulate
    from owcsim.schemas import SceneSpec

    spec = SceneSpec.model_validate(case["doc"])
    if case.get("warm"):
        simulate(spec)  # imports and first-call costs out of the way
    t = time.perf_counter()
    res = simulate(spec)
    elapsed = time.perf_counter() - t
    out = {
        "batches": res.run.batches,
        "time_s": elapsed,
        "peak_mb": _peak_mb(),
        "paths": res.run.paths_total,
        "stop": str(res.run.stop_reason),
        "rule": res.run.direction_choice.rule,
        "K": res.modeled.max_reflections,
    }
    rows = res.channels or res.links
    rel = sorted(r.dc_gain_stderr / r.dc_gain for r in rows if r.dc_gain and r.dc_gain_stderr is not None)
    out["rel_median"] = rel[len(rel) // 2] if rel else None
    out["rel_max"] = rel[-1] if rel else None
    out["rel_min"] = rel[0] if rel else None
    if case.get("write"):
        from owcsim.formats.result_files import write_outputs

        folder = Path(tempfile.mkdtemp(prefix="owcsim-map-"))
        t = time.perf_counter()
        files = write_outputs(res, folder)
        out["write_s"] = time.perf_counter() - t
        out["output_mb"] = sum(f.stat().st_size for f in files) / 2**20
        shutil.rmtree(folder)
    return out


def run_child(case: dict, python: str = sys.executable) -> dict:
    env = dict(os.environ)
    if python != sys.executable:
        env["MAP_SCALE_BASELINE"] = "1"
    cmd = [python, __file__, "--child"]
    proc = subprocess.run(cmd, input=json.dumps(case), capture_output=True, text=True, env=env, cwd="/")
    if proc.returncode:
        raise RuntimeError(proc.stderr[-2000:])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def whole_command(doc: dict, python: str = sys.executable) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "scene.json"
        scene.write_text(json.dumps(doc))
        owcsim = Path(python).with_name("owcsim")
        t = time.perf_counter()
        subprocess.run(
            [str(owcsim), "run", str(scene), "--out", str(Path(tmp) / "out")], check=True, capture_output=True
        )
        return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="smaller runs (a smoke test of the script)")
    ap.add_argument("--only", default="abcdefg", help="the sections to run, e.g. 'ae'")
    ap.add_argument("--baseline", help="another install's python: section (e) runs with it too, same machine")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(json.loads(sys.stdin.read()))))
        return
    side = 12 if args.quick else 50
    print(f"Komine room, 4 lamps in one group, grid at 0.85 m, FOV 85 deg, 1 cm^2; {side} x {side} points")
    if "e" in args.only:
        scaling(args.quick, args.baseline)
    if "f" in args.only:
        coverage(4 if args.quick else 12)
    if "g" in args.only:
        oriented(args.baseline)
    if "a" not in args.only and "b" not in args.only and "c" not in args.only and "d" not in args.only:
        return

    # (a) line of sight only
    los = komine(side, max_reflections=0)
    a = run_child({"doc": los, "warm": True})
    cmd = min(whole_command(los) for _ in range(2))
    print(
        f"(a) LOS only: in-process {a['time_s']:.3f} s (target 0.2 s); whole `owcsim run` {cmd:.2f} s "
        f"(target 5 s), including a heatmap per quantity"
    )

    # (b) every order, 1 % on every point
    target = 0.03 if args.quick else 0.01
    b = run_child({"doc": komine(side, target_rel_error=target), "write": True})
    print(
        f"(b) all orders (K = {b['K']}), {target:.0%} on every point: {b['time_s']:.1f} s (target 60 s), "
        f"{b['paths']:,d} paths, peak {b['peak_mb']:.0f} MB (target 2048 MB), output {b['output_mb']:.1f} MB "
        f"(target 50 MB); worst point {b['rel_max']:.4f}, median {b['rel_median']:.4f} ({b['stop']})"
    )
    print(f"    direction: {b['rule']}")

    # (c) scaling with receivers
    sides = (5, 10, 20) if args.quick else (10, 50, 100)
    print("(c) receivers   direction   paths/source   time [s]   peak [MB]   time per receiver vs the first")
    for direction, paths in (("backward", 200 if args.quick else 1000), ("forward", 500 if args.quick else 2000)):
        base = None
        for n in sides:
            r = run_child({"doc": komine(n, max_reflections=8, t_max_s=1e-7, paths=paths, direction=direction)})
            per_rx = r["time_s"] / n**2
            base = base or per_rx
            print(
                f"    {n * n:>9,d}   {direction:<9}   {paths:>12,d}   {r['time_s']:>8.2f}   {r['peak_mb']:>9.0f}"
                f"   {per_rx / base:>6.2f}"
            )

    # (d) the two directions on the same map
    print("(d) direction   paths/source   time [s]   median rel.err   worst rel.err   est. time to 1 % at worst")
    for direction, paths in (("forward", 4000), ("backward", 1000)):
        r = run_child({"doc": komine(10, max_reflections=8, t_max_s=1e-7, paths=paths, direction=direction)})
        need = r["time_s"] * (r["rel_max"] / 0.01) ** 2
        print(
            f"    {direction:<9}   {paths:>12,d}   {r['time_s']:>8.2f}   {r['rel_median']:>14.4f}   "
            f"{r['rel_max']:>13.4f}   {need:>10.1f} s"
        )


def scaling(quick: bool, baseline: str | None) -> None:
    """(e) every order at 1 % per point against receivers: this tree and the baseline's interpreter."""
    sides = (4, 8, 12) if quick else (10, 25, 50, 100)
    target = 0.03 if quick else 0.01
    print(f"(e) every order, {target:.0%} per point: in-process time against receivers (fit: time ~ receivers^p)")
    print("    install    receivers   time [s]   paths/point   peak [MB]   rel. error min / median / max")
    for name, python in (("this", sys.executable), ("baseline", baseline)):
        if python is None:
            continue
        times = []
        for n in sides:
            r = run_child({"doc": komine(n, target_rel_error=target)}, python)
            times.append(r["time_s"])
            print(
                f"    {name:<9}  {n * n:>9,d}   {r['time_s']:>8.2f}   {r['paths'] / n**2:>11,.0f}   "
                f"{r['peak_mb']:>9.0f}   {r['rel_min']:.4f} / {r['rel_median']:.4f} / {r['rel_max']:.4f}"
            )
        x, y = np.log([n * n for n in sides]), np.log(times)
        p = np.polyfit(x, y, 1)[0]
        tail = np.polyfit(x[-2:], y[-2:], 1)[0]
        print(
            f"    {name}: exponent p = {p:.2f} over {sides[0] ** 2:,d}-{sides[-1] ** 2:,d} receivers "
            f"({tail:.2f} between the two largest); target <= 0.8"
        )
        if not quick:
            for n in sides[-2:]:
                cmd = whole_command(komine(n, target_rel_error=target), python)
                print(f"    {name}: whole `owcsim run`, {n} x {n}: {cmd:.1f} s (targets: 50 x 50 20 s, 100 x 100 40 s)")


def coverage(n_seeds: int) -> None:
    """(f) z-scores of every point of a 6 x 6 map at 1 % per point against a long fixed-path run."""
    from owcsim.engine.run.simulate import simulate
    from owcsim.schemas import SceneSpec

    def channels(**simulation):
        res = simulate(SceneSpec.model_validate(komine(6, max_reflections=3, t_max_s=1e-7, **simulation)))
        return np.array([[c.dc_gain, c.dc_gain_stderr, c.paths] for c in res.channels], float).T

    ref, se_ref, _ = channels(paths=20_000, seed=99)
    z, paths = [], []
    for seed in range(n_seeds):
        x, se, n = channels(target_rel_error=0.01, seed=seed)
        z.append((x - ref) / np.sqrt(se**2 + se_ref**2))
        paths.append(n)
    zz, nn = np.concatenate(z), np.concatenate(paths)
    print(
        f"(f) 6 x 6 map at 1 % per point, {n_seeds} seeds, {len(zz)} points against 20 000 paths per point: "
        f"{np.mean(np.abs(zz) <= 2):.1%} within 2 sigma (t_255: 95.4 %), mean z^2 {np.mean(zz**2):.2f} "
        f"(1.008), mean z {np.mean(zz):+.3f} +- {1 / np.sqrt(len(zz)):.3f}; paths per point "
        f"{nn.min():.0f} to {nn.max():.0f}, mean {nn.mean():.0f}"
    )


def oriented(baseline: str | None) -> None:
    """(g) receivers facing different ways: one grid of walking users' orientations, to 2 % per receiver."""
    doc = komine(8, target_rel_error=0.02, max_reflections=3, t_max_s=1e-7)
    doc["receiver_grids"][0]["orientation"] = {"model": "walking", "samples": 16}
    for name, python in (("this", sys.executable), ("baseline", baseline)):
        if python is not None:
            r = run_child({"doc": doc}, python)
            print(
                f"(g) {name:<8} 8 x 8 points x 16 orientations, 2 % per receiver: {r['time_s']:.2f} s, "
                f"{r['paths']:,d} paths in {r['batches']:,d} batches, rel. error median {r['rel_median']:.4f}, "
                f"max {r['rel_max']:.4f} ({r['stop']})"
            )


if __name__ == "__main__":
    main()
