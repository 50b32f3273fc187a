"""Fixed cost of one `owcsim run`: whole-command time of a small run, and where its imports go.

Runs `owcsim run examples/barry_config_a.json --paths 20000 --out DIR` (a 0.03-0.06 s simulation)
`--repeats` times per interpreter, interleaved, in a folder outside any source tree (so each
interpreter runs its own install), and prints the best and median wall times; then one run under
`python -X importtime` per interpreter, with the cumulative import time of the heavy packages
(trimesh, scipy, matplotlib, pydantic, embreex, numpy) and of owcsim's modules. The simulation's
own time is in the command's last line ("20,000 paths in 0.03 s").

`--python A --python B` compares installs in the same run, e.g. this worktree's .venv against a
worktree of the code before a change. Issue 10 measured 1.1 s of fixed overhead per call before
the heavy imports were made lazy (`import trimesh` pulled scipy in: 0.3-1.5 s; the PNG's
matplotlib: 0.5 s). Timings are noisy on a shared machine: compare figures of the same run.
Run: .venv/bin/python benchmarks/cli_overhead.py [--repeats 7] [--python PATH ...] [--no-plot]
(`--no-plot` also times the last install's `owcsim run --no-plot`: the command without matplotlib)
"""

from __future__ import annotations

import argparse
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
            [python, "-X", "importtime", *command(python, out)[1:]], capture_output=True, text=True, check=True, cwd=out
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


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--python", action="append", help="interpreter of an install (default: this one)")
    ap.add_argument("--no-plot", action="store_true", help="also time `--no-plot` (installs that have the flag)")
    args = ap.parse_args()
    pythons = args.python or [sys.executable]
    cases = [(p, ()) for p in pythons] + ([(pythons[-1], ("--no-plot",))] if args.no_plot else [])
    times: dict[tuple, list[float]] = {c: [] for c in cases}
    sim_s: dict[tuple, str] = {}
    with tempfile.TemporaryDirectory() as out:
        for _ in range(args.repeats):
            for case in cases:  # interleaved: a load change hits every install alike
                t = time.perf_counter()
                proc = subprocess.run(
                    command(case[0], out, *case[1]), capture_output=True, text=True, check=True, cwd=out
                )
                times[case].append(time.perf_counter() - t)
                sim_s[case] = proc.stdout.strip().splitlines()[-1].split(";")[0]
    print(f"owcsim run {SCENE.name} --paths 20000 (whole command, {args.repeats} runs each)")
    for case in cases:
        label = case[0] + "".join(f" {a}" for a in case[1])
        print(
            f"  {label}: best {min(times[case]):.2f} s, median {statistics.median(times[case]):.2f} s  ({sim_s[case]})"
        )
    base = statistics.median(times[cases[0]])
    for case in cases[1:]:
        label = case[0] + "".join(f" {a}" for a in case[1])
        print(f"  median ratio {label} / {cases[0][0]}: {statistics.median(times[case]) / base:.2f}")
    print("import time [s] in one run, by package (self times of its modules; 0: not imported)")
    rows = {p: import_times(p) for p in pythons}
    print(f"  {'package':26s}" + "".join(f"{i:>10d}" for i in range(len(pythons))))
    for pkg in (*PACKAGES, "total"):
        print(f"  {pkg:26s}" + "".join(f"{rows[p][pkg]:10.3f}" for p in pythons))
    for i, p in enumerate(pythons):
        print(f"  [{i}] {p}")


if __name__ == "__main__":
    main()
