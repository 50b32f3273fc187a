"""owcsim command line: `owcsim run SCENE --out DIR`, `owcsim validate SCENE`."""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

from .docs import InputError, load_scene


def _progress_bar(stream=sys.stderr):
    """A one-line progress bar on a terminal; silent when not a terminal."""
    state = {"last": 0.0}
    tty = stream.isatty()

    def update(fraction: float, info: dict) -> None:
        now = time.monotonic()
        if not tty or (now - state["last"] < 0.1 and fraction < 1.0):
            return
        state["last"] = now
        width = 30
        full = int(round(width * min(max(fraction, 0.0), 1.0)))
        err = info.get("dc_gain_rel_stderr")
        err_txt = f"  rel.err(H0) {err:.2e}" if err is not None else ""
        stream.write(f"\r[{'#' * full}{'.' * (width - full)}] {100 * fraction:5.1f}%  "
                     f"{info['paths']:>12,d} paths{err_txt}  {info['elapsed_s']:6.1f} s")
        stream.flush()

    def close() -> None:
        if tty and state["last"]:
            stream.write("\n")

    return update, close


def _cmd_validate(args) -> int:
    spec, _ = load_scene(args.scene, assignments=args.set or [])
    from engine.scene import build_scene  # builds the geometry: catches unreadable meshes too

    scene = build_scene(spec, Path(args.scene).resolve().parent)
    print(f"{args.scene}: valid — {len(scene.geometry.faces)} triangles, {len(scene.transmitters)} transmitters, "
          f"{len(scene.receivers)} receivers, algorithm {spec.simulation.algorithm}, "
          f"{spec.simulation.n_bins} time bins")
    return 0


def _cmd_run(args) -> int:
    flags = {"paths": args.paths, "seed": args.seed, "max_reflections": args.max_reflections,
             "algorithm": args.algorithm, "target_rel_error": args.target_rel_error, "direction": args.direction}
    overrides = [(f"simulation.{k}", v) for k, v in flags.items() if v is not None]
    if args.paths is not None:  # the two stopping rules exclude each other: the flag given wins
        overrides.append(("simulation.target_rel_error", None))
    if args.target_rel_error is not None:
        overrides.append(("simulation.paths", None))
    assignments = args.set or []
    spec, _ = load_scene(args.scene, overrides, assignments)
    from engine.simulate import simulate
    from clients.output import write_outputs

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    update, close = _progress_bar()
    try:
        result = simulate(spec, base_dir=Path(args.scene).resolve().parent, workers=args.workers, progress=update)
    finally:
        close()
    paths = write_outputs(result, out)
    for link in result["links"]:
        err = link["dc_gain_stderr"]
        rms = link["rms_delay_spread_s"]
        print(f"{link['transmitter']} -> {link['receiver']} ({link['direction']}): "
              f"H0 = {link['dc_gain']:.6e} ± {err if err is not None else float('nan'):.1e}, "
              f"path loss {link['path_loss_db'] or float('nan'):.2f} dB, "
              f"tau_rms = {(rms or float('nan')) * 1e9:.3f} ns")
    run = result["run"]
    print(f"{run['paths_total']:,d} paths in {run['wall_time_s']:.2f} s ({run['stop_reason']}); "
          f"wrote {', '.join(str(p) for p in paths)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="owcsim", description="Optical wireless channel simulator.")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="simulate a scene; write result.json, cir.csv and cir.png")
    run.add_argument("scene", help="scene document (JSON)")
    run.add_argument("--out", required=True, help="output folder (created if needed)")
    run.add_argument("--paths", type=int, help="paths per source device (replaces target_rel_error)")
    run.add_argument("--seed", type=int)
    run.add_argument("--max-reflections", type=int)
    run.add_argument("--algorithm", type=int)
    run.add_argument("--direction", choices=("auto", "forward", "backward"))
    run.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    run.add_argument("--target-rel-error", type=float, help="stop when stderr(H0)/H0 reaches this, every link")
    run.add_argument("--set", action="append", metavar="PATH=VALUE",
                     help="override any field, e.g. --set receivers.0.fov_deg=60 (VALUE is JSON)")
    run.set_defaults(func=_cmd_run)
    val = sub.add_parser("validate", help="check a scene without running it")
    val.add_argument("scene")
    val.add_argument("--set", action="append", metavar="PATH=VALUE")
    val.set_defaults(func=_cmd_validate)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from engine.errors import EngineError

    with warnings.catch_warnings():
        warnings.simplefilter("default")
        try:
            return args.func(args)
        except (InputError, EngineError) as exc:
            print(f"owcsim: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("owcsim: interrupted", file=sys.stderr)
            return 130
