"""owcsim command line: `owcsim run SCENE --out DIR`, `owcsim validate SCENE`, and the HTTP service:
`owcsim serve` (run the server) and `owcsim submit SCENE --server URL` (run a scene on one)."""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from .docs import InputError, load_scene

if TYPE_CHECKING:
    from owcsim.engine.run.simulate import Progress
    from owcsim.schemas.results import SimulationResultPublic


def _progress_bar(stream=None):
    """(update, close) of a one-line progress bar of the run (clients.progress.ProgressBar) on a terminal;
    silent when stderr is not one."""
    stream = stream if stream is not None else sys.stderr  # the stream of now, not of import time
    if not stream.isatty():
        return (lambda p: None), (lambda: None)
    from owcsim.clients.progress import ProgressBar

    bar = ProgressBar(stream)

    def update(p: Progress) -> None:
        bar.show(p.fraction, p.paths, p.dc_gain_rel_stderr, f"{p.elapsed_s:6.1f} s")

    return update, bar.close


def _cmd_validate(args) -> int:
    spec, _ = load_scene(args.scene, assignments=args.set or [])
    from owcsim.engine.scene.scene import build_scene  # builds the geometry: catches unreadable meshes too

    scene = build_scene(spec, Path(args.scene).resolve().parent)
    sim = spec.simulation
    window = f"{sim.n_bins} time bins" if sim.t_max_s is not None else "time window chosen when it runs"
    points = len(spec.receivers) + sum(g.count for g in spec.receiver_grids)  # not their orientation samples
    masked = int((scene.masked[:points] != "").sum())
    from owcsim.engine.results.result import surface_extent
    from owcsim.schemas.units import unit_warnings

    for note in unit_warnings(spec, surface_extent(scene)):  # values plausible only in another unit
        print(f"owcsim: warning: {note}", file=sys.stderr)
    print(
        f"{args.scene}: valid — {len(scene.geometry.faces)} triangles, {len(scene.transmitters)} transmitters, "
        f"{len(scene.receivers)} receivers{f' ({masked} grid points masked)' if masked else ''}, "
        f"algorithm {sim.algorithm}, {window}"
    )
    return 0


#: Links above which the command line prints a summary per map instead of one line per link.
MAX_LINES = 20


def _print_links(result: SimulationResultPublic) -> None:
    from owcsim.schemas.results import StopReason

    for note in result.warnings:
        print(f"owcsim: warning: {note}", file=sys.stderr)
    if result.maps or len(result.links) > MAX_LINES:
        from owcsim.formats.maps import format_summary, maps_of_result

        maps, _ = maps_of_result(result)
        if maps:
            print(format_summary(maps))
        worst = result.run.max_dc_gain_rel_stderr
        error = (
            "exact (line of sight in closed form)"
            if result.run.stop_reason == StopReason.EXACT
            else f"largest relative standard error of H0: {worst:.2e}"
            if worst is not None
            else "no error estimate"
        )
        print(
            f"{len(result.links):,d} links"
            + (f", {len(result.channels):,d} group channels" if result.channels else "")
            + f"; {error}; all in result.json, links.csv"
        )
        return
    nan = float("nan")  # a missing figure (None in the JSON), never a 0 taken for missing
    for link in result.links:
        err, rms, loss = link.dc_gain_stderr, link.rms_delay_spread_s, link.path_loss_db
        print(
            f"{link.transmitter} -> {link.receiver} ({link.direction}): "
            f"H0 = {nan if link.dc_gain is None else link.dc_gain:.6e} ± {nan if err is None else err:.1e}, "
            f"path loss {nan if loss is None else loss:.2f} dB, "
            f"tau_rms = {(nan if rms is None else rms) * 1e9:.3f} ns"
        )
    for ch in result.channels:  # transmitter groups: their summed channel
        err, rms, loss = ch.dc_gain_stderr, ch.rms_delay_spread_s, ch.path_loss_db
        print(
            f"group {ch.group} -> {ch.receiver}: H0 = {nan if ch.dc_gain is None else ch.dc_gain:.6e} "
            f"± {nan if err is None else err:.1e}, path loss {nan if loss is None else loss:.2f} dB, "
            f"tau_rms = {(nan if rms is None else rms) * 1e9:.3f} ns"
        )


def _print_timeline(result: SimulationResultPublic, took_s: float | None = None) -> None:
    """A timeline's times and every link's outages (timeline.csv holds every figure); nothing without one."""
    tl = result.timeline
    if tl is None:
        return
    took = f", {took_s:.2f} s" if took_s is not None else ""
    print(f"timeline: {len(tl.times_s)} times from {tl.times_s[0]:g} to {tl.times_s[-1]:g} s ({tl.method}{took})")
    for k in tl.links:
        if k.time_to_first_outage_s is not None:
            print(f"  {k.tx} -> {k.rx}: {len(k.outages)} outage(s), the first at {k.outages[0].start_s:.4g} s")


def _scene_overrides(args) -> list[tuple[str, object]]:
    """The simulation flags of `run` and `submit` as (dotted path, value) overrides."""
    flags = {
        "paths": args.paths,
        "seed": args.seed,
        "max_reflections": args.max_reflections,
        "algorithm": args.algorithm,
        "target_rel_error": args.target_rel_error,
        "direction": args.direction,
        "target_scope": args.target_scope,
    }
    overrides: list[tuple[str, object]] = [(f"simulation.{k}", v) for k, v in flags.items() if v is not None]
    if isinstance(args.algorithm, int):  # the document's S may be another algorithm's: kept only if N honours it
        overrides.append(("simulation.max_scattering", _scattering_kept_by(args.algorithm)))
    if args.paths is not None:  # the two stopping rules exclude each other: the flag given wins
        overrides.append(("simulation.target_rel_error", None))
    if args.target_rel_error is not None:
        overrides.append(("simulation.paths", None))
    return overrides


def _scattering_kept_by(number: int):
    """The document's `max_scattering` under `--algorithm number`: kept if that algorithm honours it, else
    left out (the algorithm counts its own orders: 1: s = 0, 2-3: s <= 1, 4: s <= 2), as `--paths` clears
    `target_rel_error`; a `--set simulation.max_scattering=...` still wins (applied after)."""
    from owcsim.schemas.algorithms import ALGORITHMS

    def value(doc: dict):
        sim = doc.get("simulation")
        given = sim.get("max_scattering") if isinstance(sim, dict) else None
        alg = ALGORITHMS.get(number)
        if alg is None or not isinstance(given, int) or alg.scattering_refusal(given) is None:
            return given
        return None

    return value


def _output_folder(path: str) -> Path:
    """The --out folder, created if needed; a path that cannot be one is an InputError (before any work)."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out {path}: cannot use it as the output folder ({exc.strerror or exc})") from None
    return out


def _cmd_run(args) -> int:
    assignments = args.set or []
    spec, _ = load_scene(args.scene, _scene_overrides(args), assignments)
    from owcsim.engine.run.simulate import simulate
    from owcsim.formats.result_files import write_outputs

    out = _output_folder(args.out)
    executor = None
    if args.scheduler:
        from owcsim.engine.run.execution_dask import executor_from_scheduler

        executor = executor_from_scheduler(args.scheduler)
    update, close = _progress_bar()
    try:
        started = time.perf_counter()
        if spec.timeline is not None:  # the channel over time: one run per time (engine/run/timeline.py)
            from owcsim.engine.run.timeline import run_timeline

            result = run_timeline(
                spec, base_dir=Path(args.scene).resolve().parent, workers=args.workers, progress=update
            )
        else:
            result = simulate(
                spec,
                base_dir=Path(args.scene).resolve().parent,
                workers=args.workers,
                progress=update,
                executor=executor,
            )
    finally:
        close()
        if executor is not None:
            executor.close()
    paths = write_outputs(result, out, plot=not args.no_plot, plot_format=args.plot_format)
    if args.channel_matrix:  # transmitters x receivers for MIMO studies (formats/channel_matrix.py)
        from owcsim.formats.channel_matrix import channel_matrix, write_channel_matrix

        paths.append(write_channel_matrix(channel_matrix(result), out / "channel_matrix.npz"))
    _print_links(result)
    _print_timeline(result, time.perf_counter() - started)
    run = result.run
    wrote = (
        ", ".join(str(p) for p in paths)
        if len(paths) <= 4
        else f"{len(paths)} files in {out} ({', '.join(p.name for p in paths[:3])}, ...)"
    )
    print(f"{run.paths_total:,d} paths in {run.wall_time_s:.2f} s ({run.stop_reason}); wrote {wrote}")
    return 0


def _cmd_serve(args) -> int:
    try:
        from owcsim.server.serve import serve
        from owcsim.server.settings import Settings
    except ImportError as exc:
        raise InputError(
            f"`owcsim serve` needs the server extra ({exc.name} is missing): pip install 'owcsim[server]'"
        ) from None
    from pydantic import ValidationError

    given = {
        "db": args.db,
        "max_concurrent_jobs": args.max_concurrent_jobs,
        "workers_per_job": args.workers_per_job,
        "api_keys_file": args.api_keys_file,
        "scheduler": args.scheduler,
    }
    try:
        settings = Settings(**{k: v for k, v in given.items() if v is not None})
        settings.key_owners()  # an unreadable key file is an error now, not at the first request
    except ValidationError as err:
        raise InputError(
            "invalid setting: " + "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in err.errors())
        ) from None
    except ValueError as exc:
        raise InputError(str(exc)) from None
    from owcsim.server.store import StoreError

    try:
        serve(settings, host=args.host, port=args.port)
    except StoreError as exc:  # damaged, or held by another server: a clear message, no traceback
        raise InputError(str(exc)) from None
    return 0


def _cmd_submit(args) -> int:
    try:
        from owcsim.clients.client import Client
        from owcsim.clients.errors import ApiError, ConnectionFailed, InvalidRequest, JobFailed
        from owcsim.clients.scene import InputFileError
    except ImportError as exc:
        raise InputError(
            f"`owcsim submit` needs the client extra ({exc.name} is missing): pip install 'owcsim[client]'"
        ) from None
    _, doc = load_scene(args.scene, _scene_overrides(args), args.set or [])
    if args.out:
        _output_folder(args.out)  # a bad --out is said now, not after the job ran
    api_key = args.api_key or os.environ.get("OWCSIM_API_KEY")
    try:
        with Client(args.server, api_key) as owc:
            job = owc.submit(doc, base_dir=Path(args.scene).resolve().parent)
            print(f"submitted job {job.id} to {args.server.rstrip('/')}{job.url}", file=sys.stderr)
            if args.no_wait:
                print(job.id)
                return 0
            try:
                job.wait(progress=sys.stderr.isatty())
            except KeyboardInterrupt:
                job.cancel()
                print(f"owcsim: interrupted; job {job.id} cancelled", file=sys.stderr)
                return 130
            result = job.result(wait=False)
    except (FileNotFoundError, InputFileError) as exc:  # a mesh or photometric file the client will not read
        raise InputError(str(exc)) from None
    except InvalidRequest as exc:
        raise InputError(f"the server refused the scene: {exc}") from None
    except (ApiError, ConnectionFailed, JobFailed) as exc:
        print(f"owcsim: error: {exc}", file=sys.stderr)
        return 1
    _print_links(result)
    _print_timeline(result)
    run = result.run
    wrote = f"; wrote {', '.join(str(p) for p in result.save(args.out))}" if args.out else ""
    print(f"{run.paths_total:,d} paths in {run.wall_time_s:.2f} s ({run.stop_reason}); job {job.id}{wrote}")
    return 0


def _algorithm(text: str) -> int | str:
    """The --algorithm value: a number or auto (the scene document's check names a number out of range)."""
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number or auto") from None


def _add_simulation_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--paths", type=int, help="paths per source device (replaces target_rel_error)")
    p.add_argument("--seed", type=int)
    p.add_argument("--max-reflections", type=int)
    p.add_argument(
        "--algorithm",
        type=_algorithm,
        metavar="{1,2,3,4,5,auto}",
        help="estimator (schemas/algorithms.py); auto: chosen from the scene. Drops a document max_scattering "
        "the algorithm cannot honour (it then counts its own orders)",
    )
    p.add_argument("--direction", choices=("auto", "forward", "backward"))
    p.add_argument("--target-rel-error", type=float, help="stop when stderr(H0)/H0 reaches this, every link")
    p.add_argument(
        "--target-scope",
        choices=("channels", "links", "both"),
        help="what --target-rel-error holds on: group channels, links, or both (docs/scene.md)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="override any field, e.g. --set receivers.0.fov_deg=60 (VALUE is JSON)",
    )


def build_parser() -> argparse.ArgumentParser:
    from .version import __version__

    p = argparse.ArgumentParser(prog="owcsim", description="Optical wireless channel simulator.")
    p.add_argument("--version", action="version", version=f"owcsim {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="simulate a scene; write result.json, links.csv, cir.csv and cir.svg")
    run.add_argument("scene", help="scene document (JSON)")
    run.add_argument("--out", required=True, help="output folder (created if needed)")
    run.add_argument(
        "--plot-format",
        choices=("svg", "png"),
        default="svg",
        help="figures (cir, map heatmaps) as SVG written directly (default, a few ms) or as PNG drawn by "
        "matplotlib (its start-up and drawing: ~0.5-0.8 s)",
    )
    run.add_argument("--no-plot", action="store_true", help="draw no figure (cir, map heatmaps): for sweeps")
    run.add_argument(
        "--channel-matrix",
        action="store_true",
        help="also write channel_matrix.npz: DC gain of every transmitter x receiver (and CIR when tallied)",
    )
    _add_simulation_options(run)
    where = run.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=1, help="worker processes on this machine (default 1)")
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the batches on the Dask cluster of this scheduler, e.g. tcp://host:8786 (needs owcsim[cluster])",
    )
    run.set_defaults(func=_cmd_run)
    val = sub.add_parser("validate", help="check a scene without running it")
    val.add_argument("scene")
    val.add_argument("--set", action="append", metavar="PATH=VALUE")
    val.set_defaults(func=_cmd_validate)
    srv = sub.add_parser("serve", help="run the HTTP service (settings: OWCSIM_* environment variables)")
    srv.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    srv.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    srv.add_argument("--db", help="job store file (default $OWCSIM_DB or ./owcsim-jobs.sqlite)")
    srv.add_argument("--max-concurrent-jobs", type=int, help="jobs running at once (default 2)")
    srv.add_argument("--workers-per-job", type=int, help="engine worker processes per job (default 1)")
    srv.add_argument(
        "--api-keys-file",
        help="file of bearer tokens, one per line (# comments): turns API keys on; a file with no token is an error",
    )
    srv.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run every job's batches on this Dask scheduler's cluster (default $OWCSIM_SCHEDULER)",
    )
    srv.set_defaults(func=_cmd_serve)
    sbm = sub.add_parser("submit", help="run a scene on an owcsim server; write its results like `run`")
    sbm.add_argument("scene", help="scene document (JSON); mesh files are sent inline")
    sbm.add_argument(
        "--server",
        default=os.environ.get("OWCSIM_SERVER", "http://127.0.0.1:8000"),
        help="server URL (default $OWCSIM_SERVER or http://127.0.0.1:8000)",
    )
    sbm.add_argument("--api-key", help="bearer token (default $OWCSIM_API_KEY)")
    sbm.add_argument("--out", help="output folder for result.json, cir.csv, cir.png (optional)")
    sbm.add_argument("--no-wait", action="store_true", help="print the job id and return at once")
    _add_simulation_options(sbm)
    sbm.set_defaults(func=_cmd_submit)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from owcsim.engine.core.errors import EngineError

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
