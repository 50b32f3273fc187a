"""Fixed cost of one `owcsim run`: whole-command time of a small run, and where its imports go.

Runs `owcsim run examples/barry_config_a.json --paths 20000 --out DIR` (a 0.03-0.06 s simulation)
`--repeats` times per interpreter, interleaved, in a folder outside any source tree (so each
interpreter runs its own install), and prints the best and median wall times and the median CPU time
(user + sys of that process, os.wait4: on a busy host the better estimate of a quiet host's wall time);
then one run under `python -X importtime` per interpreter, with the cumulative import time of the heavy
packages (trimesh, scipy, matplotlib, pydantic, embreex, numpy) and of owcsim's modules. The simulation's
own time is in the command's last line ("20,000 paths in 0.03 s"). Each install runs once before the
timed runs, and the commands run without PYTHONDONTWRITEBYTECODE (bytecode cached, as an installed
package runs; `--no-bytecode-cache` keeps it). `--baseline COMMIT` adds the
interpreter of /tmp/owcsim-baseline-SHA/.venv (benchmarks/map_targets.py baseline_python makes it).
Issue 24: the default figure cost 0.75 s of a 1.37 s command (matplotlib's import and drawing): the
command now writes cir.svg directly (formats/svg.py); `--plot-format png` is the old figure.

`--python A --python B` compares installs in the same run, e.g. this worktree's .venv against a
worktree of the code before a change. Issue 10 measured 1.1 s of fixed overhead per call before
the heavy imports were made lazy (`import trimesh` pulled scipy in: 0.3-1.5 s; the PNG's
matplotlib: 0.5 s). Timings are noisy on a shared machine: compare figures of the same run.
Run: .venv/bin/python benchmarks/cli_overhead.py [--repeats 7] [--python PATH ...] [--baseline a1746be] [--no-plot]
(`--no-plot` also times the last install's `owcsim run --no-plot`: the command without a figure)
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "examples" / "barry_config_a.json"
PACKAGES = ("trimesh", "scipy", "matplotlib", "pydantic", "embreex", "numpy", "owcsim")


def command(python: str, out: str, *extra: str) -> list[str]:
    return [python, "-m", "owcsim", "run", str(SCENE), "--paths", "20000", "--out", out, *extra]


def import_times(python: str) -> dict[str, float]:
    """Import time [s] of each of PACKAGES in one run: the self times of all its modules (0: not imported)."""
    with tempfile.TemporaryDirectory() as out:
        proc = subprocess.run(
            [python, "-X", "importtime", *command(python, out)[1:]],
            capture_output=True,
            text=True,
            check=True,
            cwd=out,
            env=ENV,
        )
    found = dict.fromkeys(PACKAGES, 0.0)
    for line in proc.stderr.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+\d+ \|\s*(\S+)", line)
        if m:
            top = m.group(2).split(".")[0]
            if top in found:
                found[top] += int(m.group(1)) / 1e6
    found["total"] = (
        sum(int(m.group(1)) for line in proc.stderr.splitlines() if (m := re.match(r"import time:\s+(\d+) \|", line)))
        / 1e6
    )
    return found


def child_env(bytecode: bool) -> dict[str, str]:
    """The commands' environment: with `bytecode`, PYTHONDONTWRITEBYTECODE dropped, so that every run after the
    first loads cached .pyc files as an installed owcsim does (compiling owcsim's ~100 modules from source
    costs ~0.2-0.3 s a run where that variable is set)."""
    env = dict(os.environ)
    if bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


ENV = child_env(True)


def timed(argv: list[str], cwd: str) -> tuple[float, float, str]:
    """(wall [s], CPU user + sys [s] of that process, its last stdout line) of one command."""
    with tempfile.TemporaryFile() as so, tempfile.TemporaryFile() as se:
        t = time.perf_counter()
        proc = subprocess.Popen(argv, stdout=so, stderr=se, cwd=cwd, env=ENV)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        proc.returncode = os.waitstatus_to_exitcode(status)
        so.seek(0), se.seek(0)
        if proc.returncode:
            raise RuntimeError(se.read().decode()[-2000:])
        last = so.read().decode().strip().splitlines()[-1]
    return wall, usage.ru_utime + usage.ru_stime, last


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--python", action="append", help="interpreter of an install (default: this one)")
    ap.add_argument("--baseline", metavar="COMMIT", help="first, the install of this commit (its own venv)")
    ap.add_argument("--no-plot", action="store_true", help="also time `--no-plot` (installs that have the flag)")
    ap.add_argument("--png", action="store_true", help="also time the last install's `--plot-format png`")
    ap.add_argument(
        "--no-bytecode-cache", action="store_true", help="keep PYTHONDONTWRITEBYTECODE: compile from source every run"
    )
    args = ap.parse_args()
    global ENV
    ENV = child_env(not args.no_bytecode_cache)
    pythons = args.python or [sys.executable]
    if args.baseline:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from map_targets import baseline_python

        pythons = [baseline_python(args.baseline), *pythons]
    cases = (
        [(p, ()) for p in pythons]
        + ([(pythons[-1], ("--no-plot",))] if args.no_plot else [])
        + ([(pythons[-1], ("--plot-format", "png"))] if args.png else [])
    )
    times: dict[tuple, list[float]] = {c: [] for c in cases}
    cpu: dict[tuple, list[float]] = {c: [] for c in cases}
    sim_s: dict[tuple, str] = {}
    with tempfile.TemporaryDirectory() as out:
        for case in cases:  # one run each first: imports cached (.pyc), files in the page cache
            timed(command(case[0], out, *case[1]), out)
        for _ in range(args.repeats):
            for case in cases:  # interleaved: a load change hits every install alike
                wall, used, last = timed(command(case[0], out, *case[1]), out)
                times[case].append(wall)
                cpu[case].append(used)
                sim_s[case] = last.split(";")[0]
    print(
        f"owcsim run {SCENE.name} --paths 20000 (whole command, {args.repeats} runs each; "
        f"{time.strftime('%Y-%m-%d %H:%M')} UTC, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
    )
    for case in cases:
        label = case[0] + "".join(f" {a}" for a in case[1])
        print(
            f"  {label}: best {min(times[case]):.2f} s, median {statistics.median(times[case]):.2f} s, "
            f"CPU median {statistics.median(cpu[case]):.2f} s  ({sim_s[case]})"
        )
    base, base_cpu = statistics.median(times[cases[0]]), statistics.median(cpu[cases[0]])
    for case in cases[1:]:
        label = case[0] + "".join(f" {a}" for a in case[1])
        print(
            f"  median ratio {label} / {cases[0][0]}: wall {statistics.median(times[case]) / base:.2f}, "
            f"CPU {statistics.median(cpu[case]) / base_cpu:.2f}"
        )
    print("import time [s] in one run, by package (self times of its modules; 0: not imported)")
    rows = {p: import_times(p) for p in pythons}
    print(f"  {'package':26s}" + "".join(f"{i:>10d}" for i in range(len(pythons))))
    for pkg in (*PACKAGES, "total"):
        print(f"  {pkg:26s}" + "".join(f"{rows[p][pkg]:10.3f}" for p in pythons))
    for i, p in enumerate(pythons):
        print(f"  [{i}] {p}")


if __name__ == "__main__":
    main()
