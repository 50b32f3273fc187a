"""Frames of a time-varying medium from one set of paths: per-frame ratio rows (issue 26, item 4).

`simulate_reweighted(spec, frames)` traces each path once in a carrier grid medium (the cell-wise
mean of a window of frames, engine/media/frame_ratios.py `carrier_grid`) and tallies every frame
from the same paths, each estimate times the frame's ratio row (`FrameRatios`: T_f / T_c along
every segment, sigma_s,f / sigma_s,c at every scattering point; the derivation and its references
are in that module's docstring). The kernel, its settings, batches, random streams and stopping rule
are those of `simulate` (engine/run/simulate.py): a frame's tally is an ordinary tally
(engine/integrator/context.py keeps one per frame), so every frame's result is built as if the scene
held that frame's medium, with the reweighted estimator's own error bars (per-path and per-group
spreads of w r_f), and the line of sight computed exactly through that frame's grid. In accuracy
mode the run stops at the end of the first round at which every frame meets the target
(engine/run/stopping.py's rule, asked per frame).

Windows. Where frames differ much from the carrier, ratio rows spread (heavy tails): a path's ratio
is exp(-(tau_f - tau_c)) over its segments. The rule, in two steps: (1) probe rays (PROBES from each
device with its angular density, to the first surface) give every frame's optical depth along them;
consecutive frames form a window while every frame's depths stay within MAX_DEPTH_SPREAD of the
window's mean along every probe (no path tracing: a fraction of a second); (2) a pilot of PILOT_PATHS
paths per window measures each frame's effective sample size as a fraction of the carrier's
(frame_ratios.effective_fraction, the per-path relative second moments); while some frame falls below
MIN_EFFECTIVE_FRACTION the window is cut in two halves (each its own carrier and paths), down to
single frames. Frames of
one window share paths (their differences have small errors); frames of different windows are
independent.

Also returned: per path group the H0 of every frame, (F, n_links, N_GROUPS), the groups shared by the
frames of a window (the spread over groups of H0_f+1 - H0_f gives the error of a difference).
Runs serially (`workers` is accepted for the caller's interface; the frames' tables live in the
process that built them).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.core.errors import SceneError
from owcsim.engine.integrator.path import KernelSettings, WorkItem
from owcsim.engine.media.frame_ratios import (
    MIN_EFFECTIVE_FRACTION,
    FramedGrid,
    FrameRatios,
    carrier_grid,
    effective_fraction,
)
from owcsim.engine.media.frames import MediumFrames
from owcsim.engine.media.grid import GridMedium
from owcsim.engine.media.model import medium_model
from owcsim.engine.results.job import FinishedJob, LineOfSight, RunInfo
from owcsim.engine.results.result import build_result
from owcsim.engine.run.execution import SerialExecutor
from owcsim.engine.run.job import Job, Progress, ProgressFn, Watch
from owcsim.engine.run.simulate import (
    _choose_directions,
    _items,
    _new_accumulators,
    _resolve,
    _sources,
    _start,
    kernel_settings,
    skip_unsimulated,
)
from owcsim.engine.run.stopping import BatchWatch
from owcsim.engine.scene.los import line_of_sight, los_geometry
from owcsim.engine.scene.scene import Scene, build_scene
from owcsim.engine.tally import reliability
from owcsim.engine.tally.plan import N_GROUPS
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas import SceneSpec
from owcsim.schemas.algorithms import Direction
from owcsim.schemas.results import SimulationResultPublic, StopReason

#: Paths of the window pilot (per frame window; 0: no pilot); its random streams are their own (WorkItem phase
#: WINDOW_PHASE).
PILOT_PATHS = 2048
#: Largest difference of optical depth [-] between a frame and its window's mean along any probe ray.
MAX_DEPTH_SPREAD = 0.5
#: Probe rays per device.
PROBES = 256
WINDOW_PHASE = 2


def simulate_reweighted(
    spec: SceneSpec,
    frames: MediumFrames,
    *,
    frame_of_receiver: IntArray | None = None,
    base_dir: str | Path | None = None,
    workers: int = 1,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[list[SimulationResultPublic], FloatArray | None, FloatArray | None]:
    """One result per frame (as if the scene held frame f's medium; spec.medium is replaced), per path group
    the H0 of every frame and link, (F, n_links, G), and each group's weight (its paths; 0 = empty), the same
    shape (engine/tally/reliability.py `group_means`; see the module docstring).

    `frame_of_receiver[r]`: the frame receiver r belongs to (a moving receiver is one receiver per frame: its
    estimate is tallied in that frame only, and the other frames' results report its line of sight alone);
    -1: every frame."""
    t_start = time.perf_counter()
    rx_frames = _check(spec, frames, frame_of_receiver)
    watch = Watch(progress, should_stop, t_start)
    base = _with_medium(spec, frames, None)
    ex = SerialExecutor()
    resolved, _, modeled = _resolve(base, _carrier_scene(base, base_dir), ex, base_dir)
    windows = _windows(resolved, frames, rx_frames, base_dir)
    F = frames.n_frames
    results: list[SimulationResultPublic | None] = [None] * F
    groups: FloatArray | None = None
    paths: FloatArray | None = None
    for w, idx in enumerate(windows):
        run = _Window(resolved, frames, idx, rx_frames, base_dir, watch)
        run.run(None)
        ess = run.efficiency_per_frame()
        for local, f in enumerate(idx):
            res = run.result(local, modeled, spec)
            res.warnings.append(
                f"frames: frame {f} reweighted from the carrier of frames {idx[0]}..{idx[-1]} (window {w + 1} of "
                f"{len(windows)}; frames of one window share paths, of different windows are independent); its "
                f"effective sample size is {ess[local]:.2f} of the carrier's (engine/media/frame_ratios.py)"
            )
            results[f] = res
        g, n = run.group_h0()
        if groups is None or paths is None:
            groups, paths = np.zeros((F,) + g.shape[1:]), np.zeros((F,) + g.shape[1:])
        groups[idx], paths[idx] = g, n
    return [r for r in results if r is not None], groups, paths


def _check(spec: SceneSpec, frames: MediumFrames, frame_of_receiver: IntArray | None) -> IntArray | None:
    """Refusals with clear messages; the per-receiver frames as an array (None: every receiver in every frame)."""
    if spec.spectral is not None:
        raise SceneError(
            "frames: a spectral scene with a time-varying medium is not supported (run one band per job, or "
            "frames of the grey scene)"
        )
    if frame_of_receiver is None:
        return None
    rx = np.asarray(frame_of_receiver, np.int64).reshape(-1)
    if rx.size and (rx.min() < -1 or rx.max() >= frames.n_frames):
        raise SceneError(f"frame_of_receiver: entries must be -1 (every frame) or 0..{frames.n_frames - 1}")
    return rx


def _with_medium(spec: SceneSpec, frames: MediumFrames, f: int | None) -> SceneSpec:
    """The document with frame f's grid as its medium (f None: the frames' carrier, their cell-wise mean)."""
    return spec.model_copy(update={"medium": frames.grid_spec(f)})


def _carrier_scene(spec: SceneSpec, base_dir: str | Path | None) -> Scene:
    scene = build_scene(spec, base_dir)
    if scene.mirror_planes:
        raise SceneError(
            "frames: perfect-mirror surfaces are not supported with reweighted frames yet (use a Phong "
            "material with a large exponent)"
        )
    return scene


@dataclass
class _Window:
    """The reweighted run of the frames `idx` (one carrier, one set of paths)."""

    spec: SceneSpec  # resolved, any medium (replaced by the window's carrier)
    frames: MediumFrames
    idx: IntArray
    rx_frames: IntArray | None
    base_dir: str | Path | None
    watch: Watch

    def __post_init__(self) -> None:
        self.sub = self.frames.select(self.idx)
        # the carrier: the frames' cell-wise mean (one frame: that frame, bit for bit)
        self.spec_c = _with_medium(self.spec, self.sub, None if len(self.idx) > 1 else 0)
        scene = _carrier_scene(self.spec_c, self.base_dir)
        grid = scene.medium if isinstance(scene.medium, GridMedium) else carrier_grid(self.sub)
        local = None
        if self.rx_frames is not None:  # the receivers' frames as indices in this window (-2: none of them)
            lookup = np.full(self.frames.n_frames, -2, np.int64)
            lookup[self.idx] = np.arange(len(self.idx))
            local = np.where(self.rx_frames < 0, -1, lookup[np.maximum(self.rx_frames, 0)])
        self.ratios = FrameRatios(self.sub, grid, local)
        medium = FramedGrid(grid, self.ratios) if scene.medium is not None else None  # one walk: carrier and frames
        self.scene = replace(scene, medium=medium, path_ratios=self.ratios)
        self.settings: KernelSettings = replace(kernel_settings(self.spec_c, self.scene), phase_lobe=False)

    # --- the run ------------------------------------------------------------------------------------------------
    def run(self, n_paths: int | None, phase: int = 0) -> None:
        """Run the window's batches (n_paths None: the document's paths or target); fills the accumulators."""
        ex = SerialExecutor()
        self.job = job = _start(self.spec_c, self.scene, self.settings, ex, self.base_dir, self.watch)
        self.directions = directions = self._directions(job)
        F = len(self.idx)
        self.frame_scenes = [self._frame_scene(f) for f in range(F)]
        self.frame_los = [_los(s) for s in self.frame_scenes]  # exact, through each frame's grid
        self.accs = _new_accumulators(self.scene, self.settings)
        self.frame_accs = [_new_accumulators(self.scene, self.settings) for _ in range(F)]
        self.infos = [
            RunInfo(stop_reason=job.info.stop_reason, direction_choice=job.info.direction_choice) for _ in range(F)
        ]
        runs = _sources(self.scene, directions)
        sim = self.spec_c.simulation
        count = n_paths if n_paths is not None else sim.n_paths
        total = None
        if count is not None and runs:
            first = next(_items(runs, sim, self.settings, phase, count))
            total = len(runs) * -(-count // first.n_paths)
        watches = [
            BatchWatch(
                replace(
                    job,
                    scene=self.frame_scenes[f],
                    los=self.frame_los[f],
                    info=self.infos[f],
                    watch=Watch(t_start=self.watch.t_start),
                ),
                self.frame_accs[f],
                directions,
                len(runs),
                total,
            )
            for f in range(F)
        ]
        if runs:
            self._merge(ex, _items(runs, sim, self.settings, phase, count), watches)
        wall = time.perf_counter() - self.watch.t_start
        for info in self.infos:
            info.wall_time_s = wall

    def _directions(self, job: Job) -> IntArray:
        """Per link its direction, the links no path needs skipped (simulate.skip_unsimulated)."""
        directions = _choose_directions(job)
        self.blocked = skip_unsimulated(job, directions)
        return directions

    def _merge(self, ex: SerialExecutor, items: Iterator[WorkItem], watches: list[BatchWatch]) -> None:
        pulled: deque[WorkItem] = deque()

        def recording() -> Iterator[WorkItem]:
            for it in items:
                pulled.append(it)
                yield it

        done = 0
        results = ex.map(self.job.ref, recording(), self.settings)
        try:
            for tally in results:
                item = pulled.popleft()
                done += 1
                self.accs[item.direction].add(tally, item.batch, item.source)
                assert tally.frames is not None  # the scene carries frame ratios
                for f, acc in enumerate(self.frame_accs):
                    acc[item.direction].add(tally.frames[f], item.batch, item.source)
                stops = [w(item) for w in watches]
                if self._report(watches, done):
                    break
                if all(stops):
                    break
        finally:
            results.close()

    def _report(self, watches: list[BatchWatch], done: int) -> bool:
        """Progress (the worst frame) and the caller's cancel; True: cancelled."""
        w = self.watch
        elapsed = time.perf_counter() - w.t_start
        if w.progress is not None:
            worst = [x.worst for x in watches if np.isfinite(x.worst)]
            w.progress(
                Progress(
                    fraction=min(x._fraction(elapsed) for x in watches),
                    paths=int(max(a.n_paths.max() for a in self.accs.values())),
                    batches=done,
                    dc_gain_rel_stderr=max(worst) if worst else None,
                    elapsed_s=elapsed,
                )
            )
        if w.should_stop is not None and w.should_stop():
            for info in self.infos:
                info.stop_reason = StopReason.CANCELLED
            return True
        return False

    # --- what it gives ----------------------------------------------------------------------------------------------
    def _frame_scene(self, f: int) -> Scene:
        """The scene with frame f's medium (its line of sight, its result)."""
        medium = self.sub.frame(f)
        spec_f = _with_medium(self.spec, self.sub, f)
        keep = medium if medium.sigma_t_max > 0 else None
        return replace(
            self.scene,
            spec=spec_f,
            medium=keep,
            phase=keep.phase if keep is not None else None,
            path_ratios=None,
            medium_model=medium_model(spec_f.medium, keep),
        )

    def result(self, f: int, modeled, original: SceneSpec) -> SimulationResultPublic:
        """Frame f's result (local index in the window)."""
        scene = self.frame_scenes[f]
        self.infos[f].batches = self.job.info.batches
        finished = FinishedJob(
            spec=scene.spec,
            scene=scene,
            settings=self.settings,
            los=self.frame_los[f],
            directions=self.directions,
            accs=self.frame_accs[f],
            info=self.infos[f],
            original=original.model_copy(update={"medium": scene.spec.medium}),
            modeled=modeled,
            unreachable=self.blocked,
        )
        return build_result(finished)

    def group_h0(self) -> tuple[FloatArray, FloatArray]:
        """(F, n_links, N_GROUPS) per path group the H0 of each frame (the groups' mean per-path estimates, summed
        over the directions, plus the exact line of sight) and each group's weight (reliability.group_means)."""
        out = np.zeros((len(self.idx), self.scene.n_links, N_GROUPS))
        paths = np.zeros_like(out)
        for f, accs in enumerate(self.frame_accs):
            out[f], paths[f] = reliability.group_dc_gain(accs.values(), self.frame_los[f].gain)
        return out, paths

    def efficiency_per_frame(self) -> FloatArray:
        """(F,) the worst link's ESS_f / ESS_c, 1 before any path."""
        return self.efficiency()

    def efficiency(self) -> FloatArray:
        """(F,) the worst link's ESS_f / ESS_c (frame_ratios.effective_fraction) of the run so far."""
        rel_c = _rel2(self.accs)
        rel_f = np.stack([_rel2(a) for a in self.frame_accs])
        eff = effective_fraction(rel_c[None, :], rel_f)
        return eff.min(axis=1) if eff.shape[1] else np.ones(len(self.idx))


def _los(scene: Scene) -> LineOfSight:
    """The exact line of sight of every link through the scene's medium (a frame's grid)."""
    geometry = los_geometry(scene)
    return LineOfSight(*line_of_sight(scene, geometry), geometry)


def _rel2(accs: dict[Direction, Accumulator]) -> FloatArray:
    """(n_links,) per-path relative variance of H0's Monte Carlo part, over the directions that ran (NaN: none)."""
    rel = np.full(next(iter(accs.values())).n_links, np.nan)
    for acc in accs.values():
        mean, cov = acc.moments()
        n = acc.n_paths
        with np.errstate(invalid="ignore", divide="ignore"):
            r = cov[:, 0, 0] * n / (mean[:, 0] ** 2)
        ok = (n > 0) & np.isfinite(r)
        rel = np.where(ok, np.where(np.isnan(rel), 0.0, rel) + r, rel)
    return rel


def probe_depths(scene: Scene, frames: MediumFrames, n: int = PROBES) -> FloatArray:
    """(P, F) optical depth of every frame along probe rays: `n` rays from each device with its own angular
    density (emission pattern, receiver field of view) to the first surface, fixed random numbers."""
    rng = np.random.default_rng(26)
    isect = scene.intersector
    segs = []
    for devices in (scene.transmitters, scene.receivers):
        for i in range(len(devices.positions)):  # a loop over devices (one link: two)
            u = rng.random((2, n))
            d = np.asarray(devices.sample_directions(i, u[0], u[1]), np.float64).reshape(n, 3)
            o = np.repeat((devices.positions[i] + isect.offset * devices.normals[i])[None, :], n, axis=0)
            _, t = isect.intersect(o, d)
            segs.append((o, d, np.where(np.isfinite(t), t, 0.0)))
    o, d, L = (np.concatenate(x) for x in zip(*segs))
    return FrameRatios(frames, carrier_grid(frames)).depths((o, d, L))[:, :-1]


def depth_windows(tau: FloatArray, spread: float) -> list[IntArray]:
    """Consecutive frame windows, each as long as every frame's probe depths stay within `spread` of the window's
    mean frame's (tau (P, F); greedy from the first frame)."""
    F = tau.shape[1]
    out, start = [], 0
    while start < F:
        end = start + 1
        while end < F:
            block = tau[:, start : end + 1]
            if np.abs(block - block.mean(axis=1, keepdims=True)).max() > spread:
                break
            end += 1
        out.append(np.arange(start, end))
        start = end
    return out


def _windows(
    spec: SceneSpec, frames: MediumFrames, rx_frames: IntArray | None, base_dir: str | Path | None
) -> list[IntArray]:
    """The frame windows (module docstring): by the probe rays' depth spread, then halves while a pilot finds a
    frame below MIN_EFFECTIVE_FRACTION."""
    scene = _carrier_scene(spec, base_dir)
    todo = depth_windows(probe_depths(scene, frames), MAX_DEPTH_SPREAD)
    out: list[IntArray] = []
    while todo:
        idx = todo.pop(0)
        if len(idx) == 1 or PILOT_PATHS <= 0:
            out.append(idx)
            continue
        pilot = _Window(spec, frames, idx, rx_frames, base_dir, Watch(t_start=time.perf_counter()))
        pilot.run(PILOT_PATHS, phase=WINDOW_PHASE)
        if pilot.efficiency().min() >= MIN_EFFECTIVE_FRACTION:
            out.append(idx)
        else:
            half = len(idx) // 2
            todo = [idx[:half], idx[half:]] + todo
    return sorted(out, key=lambda w: int(w[0]))
