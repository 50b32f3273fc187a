"""Per-path cost toward the ray-casting limit (issue 13), before against after in one run.

Times are the process's CPU time (`time.process_time`, one thread: numpy and Embree run on the
calling thread), which other jobs on the host disturb far less than wall time; on an idle host the
two agree.

Scenes. The clear room: 5 x 5 x 3 m, walls and ceiling 0.8, floor 0.3, Tx (2.5, 2.5, 3) down
m = 1, Rx (1, 1, 0) up, FOV 90 deg, 1 cm^2. The smoky room: the same with a homogeneous
medium sigma_s 0.2, sigma_a 0 /m, Henyey-Greenstein g 0.5. Everything runs on one core
(SerialExecutor), imports and warm-up excluded.

Figures (each for the code under test and, with `--baseline REV`, for that commit, measured
alternately in the same run, figure by figure in one long-lived process per tree, best of `--repeats`):
- rays: Barry configuration A, K = 3, backward, batches of 16 384: pipeline rays/s (intersection +
  shadow) over raw Embree rays/s for the same ray counts in batches of the same size (random rays in
  the room, only `EmbreeScene.run` timed), with every shadow ray cast and with shadow rays skipped
  (the plain empty room, convex); each side the least time of 3 alternate runs per repeat (one run
  of each moved the ratio by +-0.1 on a loaded host);
- cost per path [us]: the clear room (algorithm 1, K = 200 with roulette, backward) and the smoky
  room (algorithm 5, K = 200, S = 35, run from both devices as the automatic settings choose);
  paths counted over both devices;
- time to accuracy: the full automatic job (pilots included) to 0.03 % on the clear room and 0.3 % on
  the smoky room: CPU time, paths, H0, and the CPU time of its pilots (the truncation pilot that chooses
  K / S / the window, the direction pilot) with their share;
- `--profile`: the split Embree / numpy / interpreter of the cost-per-path runs (10 s of them per
  room and tree), from py-spy (`py-spy record --native -r 25`: at 500 samples/s its native unwinding
  stalled the process it samples; samples classified by their innermost frames: Embree's library,
  numpy's or another native library, else the interpreter); without py-spy, cProfile with the
  time inside `Intersector.intersect`/`occluded` as Embree (says which).

The baseline runs from a `git worktree` of REV under /tmp, imported through a symlink farm that maps
`owcsim.engine` etc. to its folders (the same venv, the same numpy and Embree).
Run: .venv/bin/python benchmarks/path_cost.py [--baseline d42d4e1] [--repeats 3] [--profile] [--markdown]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.append(str(ROOT))  # after a baseline's farm: `benchmarks` is this tree's, `owcsim` the farm's
from benchmarks._common import engine_module, use_baseline_tree  # noqa: E402

use_baseline_tree()

#: The commit this work started from (issue 13's "today").
DEFAULT_BASELINE = "d42d4e1"
SMOKE = {"type": "homogeneous", "sigma_a": 0.0, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.5}}


# --- scenes -------------------------------------------------------------------------------------
def room_doc(smoke: bool, **simulation) -> dict:
    doc = json.loads((ROOT / "examples" / "barry_config_a.json").read_text())
    doc["receivers"][0].update(position=[1.0, 1.0, 0.0], fov_deg=90.0)
    doc["simulation"] = {"time_bin_s": 1e-9, "t_max_s": 4e-7, "batch_size": 16384, "seed": 1, **simulation}
    if smoke:
        doc["medium"] = SMOKE
    return doc


def _simulate(doc: dict, scene=None):
    simulate = engine_module("run.simulate").simulate
    from owcsim.schemas import SceneSpec

    spec = SceneSpec.model_validate(doc)
    t = time.process_time()
    res = simulate(spec, scene=scene)
    el = time.process_time() - t
    if not isinstance(res, dict):  # the typed result (the baseline returned the document)
        res = json.loads(res.model_dump_json())
    return el, res


COST_CASES = {
    "clear": lambda paths: room_doc(False, algorithm=1, max_reflections=200, direction="backward", paths=paths),
    "smoky": lambda paths: room_doc(
        True, algorithm=5, max_reflections=200, max_scattering=35, direction="auto", paths=paths
    ),
}
COST_PATHS = {"clear": 262144, "smoky": 32768}
ACCURACY_CASES = {
    "clear": lambda: room_doc(False, algorithm="auto", max_reflections=200, direction="auto", target_rel_error=3e-4),
    "smoky": lambda: room_doc(True, algorithm="auto", max_reflections=200, direction="auto", target_rel_error=3e-3),
}


# --- measurements (run inside the tree under test) ------------------------------------------------


def measure_rays(paths: int = 200_000, repeats: int = 3) -> dict:
    """Pipeline and raw Embree `repeats` times each, alternately; the least time of each (host load only adds)."""
    from benchmarks._common import barry_doc, raw_embree

    build_scene = engine_module("scene.scene").build_scene
    from owcsim.schemas import SceneSpec

    out = {}
    rng = np.random.default_rng(0)
    for cast in (True, False):
        doc = barry_doc(paths=paths, batch_size=16384, direction="backward", max_reflections=3)
        scene = build_scene(SceneSpec.model_validate(doc))
        scene.all_visible = not cast
        el = raw = np.inf
        for _ in range(repeats):
            t, res = _simulate(doc, scene)
            n_i, n_o = res["run"]["rays_intersect"], res["run"]["rays_occluded"]
            el = min(el, t)
            raw = min(raw, raw_embree(scene, n_i, n_o, 16384, rng, clock=time.process_time))
        out["shadows cast" if cast else "empty room"] = _rays_figures(el, raw, n_i + n_o, paths)
    return out


def _rays_figures(el: float, raw: float, rays: int, paths: int) -> dict:
    """The rays figures of a pipeline time `el` and a raw Embree time `raw` [s] for the same `rays`."""
    return {
        "time_s": el,
        "raw_s": raw,
        "rays": rays,
        "paths": paths,
        "pipeline_Mrays_s": rays / el / 1e6,
        "embree_Mrays_s": rays / raw / 1e6,
        "ratio": raw / el,
        "paths_s": paths / el,
    }


def measure_cost(case: str, paths: int | None = None) -> dict:
    el, res = _simulate(COST_CASES[case](paths or COST_PATHS[case]))
    link = res["links"][0]
    traced = res["run"]["paths_total"]
    return {
        "time_s": el,
        "paths": traced,
        "us_per_path": el / traced * 1e6,
        "dc_gain": link["dc_gain"],
        "dc_gain_stderr": link["dc_gain_stderr"],
        "rel_std_per_path": link["dc_gain_stderr"] / link["dc_gain"] * np.sqrt(traced),
        "rays_per_path": (res["run"]["rays_intersect"] + res["run"]["rays_occluded"]) / traced,
    }


#: The job runner's pilots: the truncation pilot (inside `_resolve`) and the direction pilot.
PILOT_STEPS = ("_resolve", "_choose_directions")


def measure_accuracy(case: str) -> dict:
    """The automatic job to its target; `pilot_s` is the CPU time of its pilots (the outermost pilot step)."""
    sim_mod = engine_module("run.simulate")

    spent, depth, original = {"pilot": 0.0}, [0], {}

    def timed(f):
        def run(*args, **kwargs):
            depth[0] += 1
            t = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                depth[0] -= 1
                if depth[0] == 0:
                    spent["pilot"] += time.process_time() - t

        return run

    timing = all(hasattr(sim_mod, name) for name in PILOT_STEPS)  # an older tree has other pilot steps
    for name in PILOT_STEPS if timing else ():
        original[name] = getattr(sim_mod, name)
        setattr(sim_mod, name, timed(original[name]))
    try:
        el, res = _simulate(ACCURACY_CASES[case]())
    finally:
        for name, f in original.items():
            setattr(sim_mod, name, f)
    link = res["links"][0]
    return {
        "time_s": el,
        "paths": res["run"]["paths_total"],
        "dc_gain": link["dc_gain"],
        "rel_stderr": link["dc_gain_stderr"] / link["dc_gain"],
        "stop": res["run"]["stop_reason"],
        **({"pilot_s": spent["pilot"]} if timing else {}),
    }


#: Algorithms 1-5 on both rooms, fixed paths per side (K = 6, S = 3 for algorithm 5): the results must stay
#: within their error bars of the baseline's (`--what algorithms` prints the z-scores).
ALGORITHM_PATHS = {1: 65536, 2: 8192, 3: 8192, 4: 4096, 5: 16384}


def measure_algorithms() -> dict:
    out = {}
    for smoke in (False, True):
        for a, paths in ALGORITHM_PATHS.items():
            sim = {"algorithm": a, "max_reflections": 6, "paths": paths, "seed": 7}
            if a == 5:
                sim["max_scattering"] = 3
            el, res = _simulate(room_doc(smoke, **sim))
            link = res["links"][0]
            out[f"{'smoky' if smoke else 'clear'} {a}"] = {
                "time_s": el,
                "dc_gain": link["dc_gain"],
                "dc_gain_stderr": link["dc_gain_stderr"],
                "mean_delay_s": link.get("mean_delay_s"),
                "paths": res["run"]["paths_total"],
            }
    return out


def measure_qmc(replicates: int = 96, paths: int = 4096) -> dict:
    """Variance per path of H0 with quasi-random first dimensions (engine/core/qmc.py: Sobol blocks of 256 paths,
    one random digital shift each) against pseudo-random ones.

    `replicates` independent batches (their own streams) of `paths` paths per side; the variance per
    path is the spread of the batch means x paths (valid for both, unlike the per-path formula under QMC).
    The rooms run as in the cost figures (clear: backward; smoky: both devices, summed).
    """
    import dataclasses

    kernel_mod = engine_module("integrator.kernel")
    WorkItem, trace_batch = kernel_mod.WorkItem, kernel_mod.trace_batch
    kernel_settings = engine_module("run.simulate").kernel_settings
    build_scene = engine_module("scene.scene").build_scene
    from owcsim.schemas import SceneSpec

    out = {}
    for case, sides in (("clear", ("backward",)), ("smoky", ("forward", "backward"))):
        spec = SceneSpec.model_validate(COST_CASES[case](paths))
        scene = build_scene(spec)
        base = kernel_settings(spec, scene)
        for label, block in (("pseudo-random", 1), ("Sobol blocks", 256)):
            settings = dataclasses.replace(base, qmc_block=block)
            t = time.process_time()
            means = [
                sum(trace_batch(scene, WorkItem(d, 0, (0,), r, paths, 11), settings).s1[0, 0] / paths for d in sides)
                for r in range(replicates)
            ]
            el = time.process_time() - t
            out[f"{case} {label}"] = {
                "mean": float(np.mean(means)),
                "se": float(np.std(means, ddof=1) / np.sqrt(replicates)),
                "var_per_path": float(np.var(means, ddof=1) * paths),
                "time_s": el,
                "replicates": replicates,
                "paths": paths,
            }
    return out


def measure(what: list[str], warm: bool = True) -> dict:
    if warm:
        _simulate(COST_CASES["smoky"](2048))  # warm imports and caches
    kernel = engine_module("integrator.kernel")

    out = {"tree": os.environ.get("OWCSIM_TREE", "this tree"), "kernel": kernel.__file__}
    if "rays" in what:
        out["rays"] = measure_rays()
    for case in ("clear", "smoky"):
        if "cost" in what:
            out[f"cost {case}"] = measure_cost(case)
        if "accuracy" in what:
            out[f"accuracy {case}"] = measure_accuracy(case)
    if "algorithms" in what:
        out["algorithms"] = measure_algorithms()
    if "qmc" in what and "qmc_block" in kernel.KernelSettings.__dataclass_fields__:  # not in the baseline
        out["qmc"] = measure_qmc()
    return out


#: CPU seconds of cost-per-path runs a profile records (at 25 samples/s: ~250 samples, +-3 % on a share)
PROFILE_SECONDS = 10.0


def _profile_target(case: str) -> None:
    """Cost-per-path runs for PROFILE_SECONDS (the process py-spy records)."""
    _simulate(COST_CASES[case](2048))
    start = time.process_time()
    while time.process_time() - start < PROFILE_SECONDS:
        measure_cost(case, 4 * COST_PATHS[case])


# --- the profile split --------------------------------------------------------------------------
def _classify(stack: list[str]) -> str:
    """'embree', 'numpy' or 'interpreter' for a py-spy stack (outermost frame first).

    Any Embree frame counts as Embree. Otherwise the innermost frame outside libc (allocation,
    memcpy) and unnamed addresses decides: a numpy (or other native extension) library is numpy,
    the Python library or a Python frame is the interpreter.
    """
    if any("embree" in f.lower() for f in stack):
        return "embree"
    for frame in reversed(stack):
        if "libc.so" in frame or "ld-linux" in frame or frame.endswith("(?)"):
            continue
        if "libpython" in frame or ".py:" in frame or "(<" in frame:
            return "interpreter"
        return "numpy"
    return "numpy"


def profile_split(python: str, env: dict, case: str) -> dict:
    """Fractions of samples in Embree / numpy (and other native libraries) / the interpreter."""
    spy = shutil.which("py-spy") or str(Path(sys.executable).parent / "py-spy")
    if Path(spy).exists():
        with tempfile.NamedTemporaryFile(suffix=".txt", delete=False) as f:
            raw = f.name
        cmd = [
            spy,
            "record",
            "--native",
            "-r",
            "25",
            "-f",
            "raw",
            "-o",
            raw,
            "--",
            python,
            __file__,
            "--profile-target",
            case,
        ]
        try:
            subprocess.run(cmd, env=env, check=True, capture_output=True, timeout=900)
        except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as e:  # py-spy's native unwinding may stall
            return {
                "tool": f"py-spy failed ({type(e).__name__})",
                **dict.fromkeys(("embree", "numpy", "interpreter"), np.nan),
            }
        counts = {"embree": 0, "numpy": 0, "interpreter": 0}
        for line in Path(raw).read_text().splitlines():
            stack, _, n = line.rpartition(" ")
            frames = stack.split(";")
            if not any("measure_cost" in fr for fr in frames):  # imports, start-up and warm-up
                continue
            counts[_classify(frames)] += int(n)
        os.unlink(raw)
        total = max(sum(counts.values()), 1)
        return {"tool": "py-spy --native", **{k: v / total for k, v in counts.items()}}
    code = (
        f"import cProfile, pstats, sys; sys.argv = ['x', '--profile-target', {case!r}]; "
        f"sys.path.insert(0, {str(ROOT)!r}); import benchmarks.path_cost as b; "
        f"p = cProfile.Profile(); p.enable(); b._profile_target({case!r}); p.disable(); s = pstats.Stats(p); "
        "tot = s.total_tt; emb = sum(v[3] for k, v in s.stats.items() if k[2] in ('intersect', 'occluded') "
        "and k[0].endswith('geometry.py')); print(emb / tot)"
    )
    out = subprocess.run([python, "-c", code], env=env, capture_output=True, text=True)
    emb = float(out.stdout.split()[-1]) if out.returncode == 0 and out.stdout.split() else float("nan")
    return {
        "tool": "cProfile (Embree = time in Intersector.intersect/occluded)",
        "embree": emb,
        "numpy": float("nan"),
        "interpreter": float("nan"),
    }


# --- the baseline tree --------------------------------------------------------------------------
def baseline_env(rev: str) -> dict:
    """Environment whose `owcsim` package is commit `rev` (a git worktree under /tmp + a symlink farm)."""
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", rev], check=True, capture_output=True, text=True
    ).stdout.strip()
    tree = Path(tempfile.gettempdir()) / f"owcsim-baseline-{sha}"
    if not tree.exists():
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), sha], check=True, capture_output=True
        )
    farm = Path(tempfile.gettempdir()) / f"owcsim-baseline-{sha}-pkg"
    if not farm.exists():
        pkg = farm / "owcsim"
        pkg.mkdir(parents=True)
        for item in (tree / "owcsim").iterdir():
            (pkg / item.name).symlink_to(item)
        for sub in ("engine", "schemas", "server", "clients"):
            (pkg / sub).symlink_to(tree / sub)
        (farm / "benchmarks").symlink_to(ROOT / "benchmarks")  # this script and _common, not the old ones
    env = dict(os.environ)
    env["PYTHONPATH"] = str(farm)
    env["OWCSIM_TREE"] = f"baseline {sha}"
    return env


#: Result lines of a measuring process start with this (anything else it prints is passed over).
RESULT = "RESULT "


def serve() -> None:
    """A measuring process: warm up once, then measure each JSON list of figures read from stdin."""
    _simulate(COST_CASES["smoky"](2048))  # warm imports and caches
    for line in sys.stdin:
        print(RESULT + json.dumps(measure(json.loads(line), warm=False)), flush=True)


class TreeProcess:
    """One long-lived measuring process per tree, so that the trees take turns measure by measure (seconds
    apart, not a whole run apart: the host's load drifts over seconds)."""

    def __init__(self, env: dict):
        self.name = env.get("OWCSIM_TREE", "this tree")
        cmd = [sys.executable, __file__, "--serve"]
        self.proc = subprocess.Popen(cmd, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def measure(self, what: list[str]) -> dict:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(what) + "\n")
        self.proc.stdin.flush()
        for line in self.proc.stdout:
            if line.startswith(RESULT):
                return json.loads(line[len(RESULT) :])
        raise RuntimeError(f"{self.name}: the measuring process ended (exit code {self.proc.wait()})")

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        self.proc.wait()


def _best(runs: list[dict]) -> dict:
    """Per figure, the least time over the runs (the others are slowed by host load); the rays figures from
    the least pipeline time and the least raw Embree time."""
    best: dict = {}
    for run in runs:
        for key, value in run.items():
            if key not in best or key in ("tree", "kernel", "algorithms", "qmc"):
                best.setdefault(key, value)
            elif key == "rays":
                for sub, v in value.items():
                    b = best[key][sub]
                    best[key][sub] = _rays_figures(
                        min(b["time_s"], v["time_s"]), min(b["raw_s"], v["raw_s"]), v["rays"], v["paths"]
                    )
            elif value["time_s"] < best[key]["time_s"]:
                best[key] = value
    return best


def report(results: dict[str, dict], profiles: dict[str, dict], markdown: bool) -> str:
    names = list(results)
    lines = []
    head = "| figure | " + " | ".join(names) + (" | after / before |" if len(names) == 2 else " |")
    lines += [head, "|---" * (len(names) + 1 + (len(names) == 2)) + "|"]

    def row(label, values, fmt, ratio=True):
        cells = [fmt.format(v) for v in values]
        extra = ""
        if len(values) == 2:
            extra = f" {values[1] / values[0]:.2f} |" if ratio and values[0] else " |"
        lines.append(f"| {label} | " + " | ".join(cells) + " |" + extra)

    first = results[names[0]]
    lines.append(
        "| kernel | "
        + " | ".join(results[n]["kernel"].replace(str(ROOT), ".") for n in names)
        + " |"
        + (" |" if len(names) == 2 else "")
    )
    if "rays" in first:
        for sub in first["rays"]:
            row(
                f"rays, {sub}: pipeline / raw Embree rays/s",
                [results[n]["rays"][sub]["ratio"] for n in names],
                "{:.2f}",
            )
            row(
                f"rays, {sub}: pipeline Mrays/s", [results[n]["rays"][sub]["pipeline_Mrays_s"] for n in names], "{:.2f}"
            )
    for case in ("clear", "smoky"):
        key = f"cost {case}"
        if key in first:
            row(f"cost per path, {case} room [us]", [results[n][key]["us_per_path"] for n in names], "{:.2f}")
            row(f"rel. std per path, {case} room", [results[n][key]["rel_std_per_path"] for n in names], "{:.3f}")
            row(f"H0, {case} room (fixed paths)", [results[n][key]["dc_gain"] for n in names], "{:.5e}", False)
            if len(names) == 2:
                a, b = (results[n][key] for n in names)
                z = (b["dc_gain"] - a["dc_gain"]) / np.hypot(a["dc_gain_stderr"], b["dc_gain_stderr"])
                lines.append(f"| z of H0 after - before, {case} | {z:+.2f} | | |")
    for case, target in (("clear", "0.03 %"), ("smoky", "0.3 %")):
        key = f"accuracy {case}"
        if key in first:
            row(f"time to {target}, {case} room [s]", [results[n][key]["time_s"] for n in names], "{:.2f}")
            row(f"paths to {target}, {case} room", [results[n][key]["paths"] for n in names], "{:,d}")
            if all("pilot_s" in results[n][key] for n in names):
                row(f"pilots' time in it, {case} room [s]", [results[n][key]["pilot_s"] for n in names], "{:.3f}")
                row(
                    f"pilots' share of it, {case} room",
                    [results[n][key]["pilot_s"] / results[n][key]["time_s"] for n in names],
                    "{:.0%}",
                    False,
                )
    if "algorithms" in first and len(names) == 2:
        a, b = (results[n]["algorithms"] for n in names)
        for key in a:
            z = (b[key]["dc_gain"] - a[key]["dc_gain"]) / np.hypot(a[key]["dc_gain_stderr"], b[key]["dc_gain_stderr"])
            before, after = (f"{r[key]['dc_gain']:.5e} +- {r[key]['dc_gain_stderr']:.1e}" for r in (a, b))
            lines.append(
                f"| {key.split()[0]} room, algorithm {key.split()[1]}: H0 | {before} | {after} "
                f"| z {z:+.2f}, time x{b[key]['time_s'] / a[key]['time_s']:.2f} |"
            )
    if "qmc" in results[names[-1]]:
        q = results[names[-1]]["qmc"]
        for case in ("clear", "smoky"):
            mc, sob = q[f"{case} pseudo-random"], q[f"{case} Sobol blocks"]
            ratio = sob["var_per_path"] / mc["var_per_path"]
            z = (sob["mean"] - mc["mean"]) / np.hypot(sob["se"], mc["se"])
            rel = np.sqrt(2.0 / (mc["replicates"] - 1)) * np.sqrt(2.0)  # rough relative error of a variance ratio
            lines.append(
                f"| QMC, {case} room: variance per path, Sobol / pseudo-random | {ratio:.2f} "
                f"(+- {rel * ratio:.2f}) | means differ by z {z:+.2f} | {mc['replicates']} x "
                f"{mc['paths']} paths |"
            )
    for case in profiles.get(names[0], {}):
        for part in ("embree", "numpy", "interpreter"):
            row(f"profile {case} room: {part}", [profiles[n][case][part] for n in names], "{:.0%}", False)
    if profiles:
        lines.append(f"\nProfile: {next(iter(profiles[names[0]].values()))['tool']}.")
    text = "\n".join(lines)
    return text if markdown else text.replace("| ", "").replace(" |", "  ")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", default=DEFAULT_BASELINE, help="git revision to compare against ('' for none)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--what", default="rays,cost,accuracy")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--profile-target", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if "OWCSIM_TREE" not in os.environ:  # the baseline's farm holds `benchmarks` (and its own `owcsim`)
        sys.path.insert(0, str(ROOT))
    if args.serve:
        return serve()
    if args.profile_target:
        return _profile_target(args.profile_target)
    trees = {}
    if args.baseline:
        trees[f"before ({args.baseline})"] = baseline_env(args.baseline)
    trees["after (this tree)"] = {k: v for k, v in os.environ.items() if k != "OWCSIM_TREE"}
    what = args.what.split(",")
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    procs = {name: TreeProcess(e) for name, e in trees.items()}
    try:
        for rep in range(args.repeats):  # the trees take turns figure by figure, so that host load hits both alike
            for part in what:
                if part in ("algorithms", "qmc") and rep:  # fixed paths and seeds: not timings, once is enough
                    continue
                for name, proc in procs.items():
                    runs[name].append(proc.measure([part]))
    finally:
        for proc in procs.values():
            proc.close()
    results = {name: _best(r) for name, r in runs.items()}
    profiles = {}
    if args.profile:
        profiles = {
            name: {case: profile_split(sys.executable, e, case) for case in ("clear", "smoky")}
            for name, e in trees.items()
        }
    print(f"one core, CPU time, best of {args.repeats}; host load average {os.getloadavg()[0]:.1f} (2 cores)")
    print(report(results, profiles, args.markdown))


if __name__ == "__main__":
    main()
