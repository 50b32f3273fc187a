"""Scene and medium builds per job, and whole-command time, with explicit against automatic settings.

The smoky room (examples/smoky_room.json) with a large mesh as furniture: an icosphere of
radius 0.4 m subdivided `--subdivisions` times (8: 1 310 720 triangles, the size of the
issue 10 measurement), written as a PLY file next to the scene. Two settings:
- explicit: algorithm 5, K = 6, S = 20, t_max_s given (no pilot);
- automatic: algorithm, K, S and the window chosen by engine/run/auto.py (a truncation pilot runs).
For each it prints the geometry builds (engine.scene.geometry.build_geometry, one per scene build)
and medium builds (engine.media.registry.medium_from_spec) counted in one job (in-process `simulate`),
the same counts for the service pre-flight of the automatic scene, and the wall time of the
whole command `owcsim run SCENE --out DIR` (best of `--repeats`, in a fresh process: imports,
scene build, pilot, run, files).

The counters wrap the builders in every engine module that imported them, so the same child
runs on any version of the code: `--before-python /work/main/.venv/bin/python` measures another
install (e.g. a worktree of the code before this change) in the same run, for before/after
ratios. Without it the before figures are the ones issue 10 recorded (1.3 M triangles): an
automatic job built the scene 3 times and the medium 4 times and called `simulate` twice, the
pre-flight built the scene 4 times, and the command took 8.2 s against 2.2 s with explicit
settings.
Run: .venv/bin/python benchmarks/build_once.py [--subdivisions 8] [--paths 2048] [--repeats 2]
     [--before-python /path/to/other/.venv/bin/python]
Timings are noisy on a shared machine: compare ratios measured in the same run.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: What issue 10 measured before the job runner built each scene once (1.3 M-triangle mesh).
ISSUE_BEFORE = {
    "automatic": {"geometry": 3, "medium": 4, "command_s": 8.2},
    "explicit": {"command_s": 2.2},
    "preflight": {"geometry": 4},
}


def scene_files(folder: Path, subdivisions: int, paths: int) -> dict[str, Path]:
    """The mesh (PLY) and the two scene documents (explicit, automatic) in `folder`."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.4)
    sphere.apply_translation([3.5, 3.5, 0.8])
    sphere.export(folder / "sphere.ply")
    doc = json.loads((ROOT / "examples" / "smoky_room.json").read_text())
    doc["meshes"] = [{"name": "sphere", "file": "sphere.ply", "reflectance": 0.5}]
    out = {}
    explicit = dict(doc["simulation"], paths=paths)
    automatic = {"paths": paths, "seed": 1, "pilot_paths": 1024}
    for name, sim in (("explicit", explicit), ("automatic", automatic)):
        out[name] = folder / f"{name}.json"
        out[name].write_text(json.dumps(dict(doc, simulation=sim)))
    return out


CHILD = r"""
import json, sys
from pathlib import Path
import owcsim.engine.run.simulate, owcsim.server.preflight  # every engine module these import, loaded
from owcsim.docs import load_scene

counts = {"geometry": 0, "medium": 0}
def counted(key, real):
    def wrapper(*a, **k):
        counts[key] += 1
        return real(*a, **k)
    return wrapper
for mod_name, attr, key in (("owcsim.engine.scene.geometry", "build_geometry", "geometry"),
                            ("owcsim.engine.media.registry", "medium_from_spec", "medium")):
    real = getattr(sys.modules[mod_name], attr)
    wrap = counted(key, real)
    for name, mod in list(sys.modules.items()):  # every module that imported the builder by name
        if name.startswith("owcsim.") and getattr(mod, attr, None) is real:
            setattr(mod, attr, wrap)
out = {}
for case in sys.argv[1:3]:
    counts.update(geometry=0, medium=0)
    spec, _ = load_scene(case)
    owcsim.engine.run.simulate.simulate(spec, base_dir=Path(case).parent)
    out[Path(case).stem] = dict(counts)
counts.update(geometry=0, medium=0)
spec, _ = load_scene(sys.argv[2])  # the pre-flight of the automatic scene (mesh path made absolute)
spec = spec.model_copy(update={"meshes": [m.model_copy(update={"file": str(Path(sys.argv[2]).parent / m.file)})
                                          for m in spec.meshes]})
owcsim.server.preflight.preflight(spec)
out["preflight"] = dict(counts)
print(json.dumps(out))
"""


def counts(python: str, files: dict[str, Path]) -> dict:
    proc = subprocess.run(
        [python, "-c", CHILD, str(files["explicit"]), str(files["automatic"])],
        capture_output=True,
        text=True,
        check=True,
        cwd=files["explicit"].parent,
    )  # not a source tree
    return json.loads(proc.stdout.strip().splitlines()[-1])


def command_time(python: str, scene: Path, repeats: int) -> float:
    """Best wall time [s] of `owcsim run SCENE --out DIR` in a fresh process."""
    best = float("inf")
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as out:
            t = time.perf_counter()
            subprocess.run(
                [python, "-m", "owcsim", "run", str(scene), "--out", out],
                check=True,
                capture_output=True,
                cwd=scene.parent,
            )  # not a source tree: the install's own code
            best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--subdivisions", type=int, default=8, help="icosphere subdivisions (8: 1 310 720 triangles)")
    ap.add_argument("--paths", type=int, default=2048)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--before-python", help="interpreter of another install to measure in the same run")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="owcsim-build-once-") as tmp:
        files = scene_files(Path(tmp), args.subdivisions, args.paths)
        print(f"smoky room + icosphere of {20 * 4**args.subdivisions:,d} triangles, {args.paths:,d} paths")
        versions = {"this code": sys.executable}
        if args.before_python:
            versions["before (--before-python)"] = args.before_python
        rows = {}
        for label, python in versions.items():
            c = counts(python, files)
            t = {name: command_time(python, files[name], args.repeats) for name in ("explicit", "automatic")}
            rows[label] = (c, t)
        if not args.before_python:
            b = ISSUE_BEFORE
            rows["before (issue 10, 1.3 M triangles)"] = (
                {
                    "explicit": {"geometry": None, "medium": None},
                    "automatic": b["automatic"],
                    "preflight": {"geometry": b["preflight"]["geometry"], "medium": None},
                },
                {"explicit": b["explicit"]["command_s"], "automatic": b["automatic"]["command_s"]},
            )
        print(f"{'version':38s} {'job':10s} {'scene builds':>12s} {'medium builds':>13s} {'command [s]':>11s}")
        for label, (c, t) in rows.items():
            for job in ("explicit", "automatic", "preflight"):
                n = c[job]
                cell = lambda v: "-" if v is None else f"{v}"  # noqa: E731
                tt = f"{t[job]:11.2f}" if job in t else f"{'-':>11s}"
                print(f"{label:38s} {job:10s} {cell(n.get('geometry')):>12s} {cell(n.get('medium')):>13s} {tt}")
        for label, (_, t) in rows.items():
            print(f"{label}: automatic / explicit command time = {t['automatic'] / t['explicit']:.2f}")


if __name__ == "__main__":
    main()
