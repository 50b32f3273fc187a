"""Run a job: build the scene once, choose the automatic settings, plan the batches, execute, merge, stop.

`simulate(spec)` is the engine's entry point and its job runner: it builds the engine
`Scene` once (or takes a built one), resolves "auto" settings on that scene (engine/run/auto.py
says what to run; a truncation pilot, when one is needed, runs here on a receiver subset of
the same scene), then runs the job and returns the typed result (schemas.results
.SimulationResultPublic). The plan is a function of the scene document only (batches, their
sizes and their random streams), so the same seed gives bit-identical results with any
number of workers. In accuracy mode batches are issued in rounds (one batch per source) and
the run stops after the first round at which every link's relative standard error of H0 is
at or below the target, or when the time budget is spent (the result says which;
engine/run/stopping.py).

`simulate_two_sided(spec)` runs a resolved job with every link from both devices (studies and
tests: engine/integrator/weights.py's partition of unity) through the same steps. Each run
is one `Job` value (engine/run/job.py) read by every step; the result is built from one
`FinishedJob` (engine/results/job.py).
"""

from __future__ import annotations

import itertools
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from owcsim.engine.core import qmc
from owcsim.engine.core.arrays import BoolArray, FloatArray, IntArray
from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.integrator.lobe import phase_lobe_wanted
from owcsim.engine.integrator.path import KernelSettings, WorkItem
from owcsim.engine.results.job import FinishedJob, LineOfSight, RunInfo
from owcsim.engine.results.result import build_result
from owcsim.engine.run import allocation, auto
from owcsim.engine.run.execution import Executor, JobRef, ProcessExecutor, SerialExecutor, job_ref
from owcsim.engine.run.job import Job, Progress, ProgressFn, Watch
from owcsim.engine.run.receivers import unreachable_receivers
from owcsim.engine.run.stopping import MIN_PATHS_FOR_STOP, BatchWatch
from owcsim.engine.scene.los import line_of_sight, los_geometry
from owcsim.engine.scene.scene import Scene, build_scene, check_spectral
from owcsim.engine.tally import reliability
from owcsim.engine.tally.plan import N_GROUPS, TallyPlan, TimeBins
from owcsim.engine.tally.tally import CIR_GROUPS_MAX, Accumulator
from owcsim.schemas import SceneSpec, SimulationSpec
from owcsim.schemas.algorithms import Direction, TwoSided, algorithm
from owcsim.schemas.results import DirectionChoicePublic, ModeledPublic, SimulationResultPublic, StopReason

#: The names other packages import from here (the job's progress report, the run's record).
__all__ = ["Progress", "ProgressFn", "RunInfo", "simulate", "simulate_two_sided", "kernel_settings", "batch_size"]

#: Heuristic of the auto direction: with this many times more receivers than
#: transmitters (or the reverse), one side amortizes its paths over so many links
#: that no pilot is run.
AMORTIZATION_RATIO = 8
#: Accuracy runs double their batches every this many rounds, up to the job's batch_size: small first
#: batches check the target early, later ones pay the per-step fixed cost over more paths (a 4 096-path batch
#: spends ~half its time in it: benchmarks/path_cost.py). A round is then at most ~1/8 of the paths so far.
GROWTH_ROUNDS = 4
#: Per-link direction codes (Direction.code): paths from the transmitter, from the receiver, both, or none.
FORWARD, BACKWARD, BOTH, SKIP = (d.code for d in Direction)
#: Most (path, target) pairs, times the estimates per segment, that one batch holds in its dense per-path
#: tallies and its step's estimate lists (~150 B each): batches shrink as receivers grow, so a batch of a
#: 100 000-point map needs about as much memory as one of a single link.
PATH_TARGET_BUDGET = 1 << 20
#: Most next-event estimates one kernel step of a batch may hold (points along segments multiply them).
ESTIMATE_BUDGET = 1 << 22


def tally_plan(spec: SceneSpec, scene: Scene) -> TallyPlan:
    """What the job tallies (schemas/outputs.py): CIR and order split per receiver, group weights."""
    sim = spec.simulation
    cir_flags, order_flags = spec.outputs.per_receiver(len(spec.receivers), spec.grid_receiver_count())
    cir, orders = np.asarray(cir_flags, bool), np.asarray(order_flags, bool)
    K, S = _resolved(sim.max_reflections), sim.scattering_orders

    def rank(flags: BoolArray) -> IntArray:
        return np.where(flags, np.cumsum(flags) - 1, -1).astype(np.int64)

    n_cir = len(scene.transmitters) * int(cir.sum())
    # a run that may be one batch per source (paths <= batch_size, or an accuracy run that stops after its first
    # round) bins its first batches per path group too: per-bin errors without a second batch (tally.py)
    one_batch = sim.n_paths is None or sim.n_paths <= sim.batch_size
    return TallyPlan(
        bins=TimeBins(sim.t_min_s, sim.time_bin_s, sim.n_bins),
        n_orders=K + 1,
        n_scatter=S + 1,
        n_rx=len(scene.receivers),
        cir_rank=rank(cir),
        order_rank=rank(orders),
        group_weights=group_weights(spec, scene),
        split_cir=spec.outputs.cir_by_order is not False,
        first_batch_groups=one_batch and 0 < N_GROUPS * n_cir * sim.n_bins <= CIR_GROUPS_MAX,
    )


def _resolved(value: int | None) -> int:
    """A setting a resolved document gives (engine/run/auto.py resolves "auto" before the run)."""
    assert value is not None, "the job's document is resolved"
    return value


def group_weights(spec: SceneSpec, scene: Scene) -> FloatArray:
    """(G, n_tx): weight P_i / sum_group P of each member transmitter in its group's channel."""
    ids = {t: i for i, t in enumerate(scene.transmitters.ids)}
    w = np.zeros((len(spec.transmitter_groups), len(scene.transmitters)))
    for g, group in enumerate(spec.transmitter_groups):
        members = [ids[t] for t in group.transmitters]
        power = scene.transmitters.power[members]
        w[g, members] = power / power.sum()
    return w


def two_sided(spec: SceneSpec, scene: Scene) -> bool:
    """True when every link runs from both devices under the partition of unity of integrator/weights.py: in a
    medium, algorithms 2-4 always, algorithm 5 unless a direction is requested (bounded weights near point
    devices); the registry's `two_sided` says which (schemas/algorithms.py)."""
    rule = algorithm(spec.simulation.algorithm).two_sided
    return scene.medium is not None and (
        rule is TwoSided.ALWAYS or (rule is TwoSided.AUTO_DIRECTION and spec.simulation.direction == "auto")
    )


def kernel_settings(spec: SceneSpec, scene: Scene, both_devices: bool | None = None) -> KernelSettings:
    """The kernel configuration of the job's algorithm (physics.md section 4; its flags from the registry,
    schemas/algorithms.py); `both_devices` (default: the planner's rule, `two_sided`) gives the settings of
    links run from both devices (the registry's `both_devices` flags; integrator/weights.py)."""
    sim = spec.simulation
    alg = algorithm(sim.algorithm)
    step = sim.segment_time_step_s if sim.segment_time_step_s is not None else sim.time_bin_s
    settings = KernelSettings(
        max_reflections=_resolved(sim.max_reflections),
        russian_roulette=sim.russian_roulette,
        rr_start_depth=sim.rr_start_depth,
        tally=tally_plan(spec, scene),
        max_scattering=sim.scattering_orders,
        strata_length=step * SPEED_OF_LIGHT,
        max_strata=sim.max_strata,
        equiangular_points=sim.equiangular_points,
        tally_channels=1 + (scene.spectra.n_channels if scene.spectra is not None else 0),
        qmc_block=qmc.job_block(sim.quasi_random, sim.n_paths),
        **_flags(alg.kernel),
    )
    both = two_sided(spec, scene) if both_devices is None else both_devices
    if both:  # a run whose partner run is missing would count about half: the planner runs both sides
        settings = replace(settings, **_flags(alg.both_devices_kernel(scene.medium is not None)))
    # the phase lobe (integrator/lobe.py): algorithm 5 from either side or both, algorithms 2-4 from both
    lobe = settings.free_flight or (settings.mis and settings.segment_scatter)
    if lobe and scene.medium is not None and scene.spectra is None and phase_lobe_wanted(scene.phase):
        settings = replace(settings, phase_lobe=True)  # a peaked phase function
    return settings


def _flags(flags: Mapping[str, object]) -> dict[str, Any]:
    """The registry's KernelSettings flags (field name -> value, schemas/algorithms.py) as keyword arguments."""
    return dict(flags)


@contextmanager
def _executor(executor: Executor | None, workers: int) -> Iterator[Executor]:
    """The given executor (left open: a long-lived pool serves many jobs), or one for this job only."""
    if executor is not None:
        yield executor
        return
    own: Executor = SerialExecutor() if workers <= 1 else ProcessExecutor(workers)
    try:
        yield own
    finally:
        own.close()


def simulate(
    spec: SceneSpec,
    *,
    base_dir: str | Path | None = None,
    workers: int = 1,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    scene: Scene | None = None,
    executor: Executor | None = None,
    on_finished: Callable[[FinishedJob], None] | None = None,
) -> SimulationResultPublic:
    """Simulate the scene document; return its typed result (schemas.results.SimulationResultPublic).

    The scene is built once (`scene`: one already built from `spec`, e.g. by a pre-flight) and every
    step of the job uses it: the automatic settings, their pilot (on a receiver subset of the same
    scene) and the run. `workers` > 1 starts a process pool for this call; pass a long-lived
    `executor` instead to reuse warm workers across jobs (it is not closed here). `progress` gets a
    `Progress` after batches; `should_stop` is asked after every batch of the run (True stops it:
    stop reason "cancelled"). `on_finished` sees the finished main run (its tallies: e.g. the path groups'
    estimates engine/run/frames.py compares across frames) before its result is built.
    """
    watch = Watch(progress, should_stop, time.perf_counter())
    scene = scene if scene is not None else build_scene(spec, base_dir)
    with _executor(executor, workers) as ex:
        resolved, scene, modeled = _resolve(spec, scene, ex, base_dir)
        return _run_job(resolved, scene, ex, base_dir, watch, original=spec, modeled=modeled, on_finished=on_finished)


def simulate_two_sided(
    spec: SceneSpec,
    *,
    base_dir: str | Path | None = None,
    executor: Executor | None = None,
    direction: Direction | str = Direction.BOTH,
    **overrides: object,
) -> SimulationResultPublic:
    """`simulate` with every link run from both devices under the partition of unity (integrator/weights.py), the
    settings of the registry's `both_devices` flags (schemas/algorithms.py), for studies and tests.

    The spec must be resolved (explicit algorithm, K, S and window). `direction` forward / backward runs one
    side only with the one-sided settings (as `simulate` does, for comparisons); `overrides` replace
    KernelSettings fields (e.g. rr_start_depth, rr_threshold)."""
    t_start = time.perf_counter()
    side = Direction(direction)
    sim = spec.simulation
    if not sim.is_resolved or side is Direction.NONE:
        raise ValueError("simulate_two_sided needs a resolved document and a direction")
    alg = algorithm(sim.algorithm)
    if side is Direction.BOTH and alg.both_devices is None:
        raise ValueError(f"algorithm {alg.number} runs one direction: give direction forward or backward")
    scene = build_scene(spec, base_dir)
    settings = replace(kernel_settings(spec, scene, both_devices=side is Direction.BOTH), **_flags(overrides))
    rule = (
        f"algorithm {alg.number} from both devices, partition of unity (engine/integrator/weights.py)"
        if side is Direction.BOTH
        else f"requested: {side}"
    )
    with _executor(executor, 1) as ex:
        job = _start(spec, scene, settings, ex, base_dir, Watch(t_start=t_start))
        job.info.direction_choice = DirectionChoicePublic(rule=rule)
        return _finish(job, np.full(scene.n_links, side.code))


def _resolve(
    spec: SceneSpec, scene: Scene, executor: Executor, base_dir: str | Path | None
) -> tuple[SceneSpec, Scene, ModeledPublic | None]:
    """Explicit settings for the "auto" ones (engine/run/auto.py), on the built scene: (spec, scene, modeled)."""
    if spec.simulation.is_resolved:
        return spec, scene, None
    step = auto.plan(spec, scene)
    if step.pilot is not None:  # the truncation pilot: a short run of K, S, window up to their caps
        pilot = _run_job(step.pilot.spec, step.pilot.scene, executor, base_dir, Watch(t_start=time.perf_counter()))
        step = auto.finish(step, pilot)
    return step.spec, step.scene, step.modeled


def _start(
    spec: SceneSpec,
    scene: Scene,
    settings: KernelSettings,
    executor: Executor,
    base_dir: str | Path | None,
    watch: Watch,
) -> Job:
    """The job value every step reads: its scene where the executor finds it, and the line of sight."""
    geometry = los_geometry(scene)
    gain, delay = line_of_sight(scene, geometry)
    ref = (
        JobRef(scene, "", "", None)
        if isinstance(executor, SerialExecutor)
        else job_ref(scene, str(base_dir) if base_dir is not None else None)
    )
    los = LineOfSight(gain, delay, geometry)
    return Job(spec, scene, settings, executor, ref, los, RunInfo(workers=executor.workers), watch)


def _run_job(
    spec: SceneSpec,
    scene: Scene,
    executor: Executor,
    base_dir: str | Path | None,
    watch: Watch,
    original: SceneSpec | None = None,
    modeled: ModeledPublic | None = None,
    on_finished: Callable[[FinishedJob], None] | None = None,
) -> SimulationResultPublic:
    """Run a resolved job on its built scene: its settings, its directions, its batches, its result."""
    job = _start(spec, scene, kernel_settings(spec, scene), executor, base_dir, watch)
    return _finish(job, _choose_directions(job), original, modeled, on_finished)


def _finish(
    job: Job,
    directions: IntArray,
    original: SceneSpec | None = None,
    modeled: ModeledPublic | None = None,
    on_finished: Callable[[FinishedJob], None] | None = None,
) -> SimulationResultPublic:
    """Run the job in its chosen directions (links not simulated skipped) and build its result."""
    scene = job.scene
    blocked = skip_unsimulated(job, directions)
    accs = _run(job, directions)
    job.info.wall_time_s = time.perf_counter() - job.watch.t_start
    finished = FinishedJob(
        spec=job.spec,
        scene=scene,
        settings=job.settings,
        los=job.los,
        directions=directions,
        accs=accs,
        info=job.info,
        original=original,
        modeled=modeled,
        unreachable=blocked,
    )
    if on_finished is not None:
        on_finished(finished)
    return build_result(finished)


def skip_unsimulated(job: Job, directions: IntArray) -> list[int]:
    """Mark SKIP in `directions` (per link) the links no path needs: receivers masked or unreachable (a direct
    view proves reachability), and every link when the job is line of sight only (then stop reason EXACT).
    Returns the unreachable receivers."""
    scene = job.scene
    seen = job.los.gain.reshape(len(scene.transmitters), len(scene.receivers)).any(axis=0)
    masked = np.flatnonzero(scene.masked != "")
    blocked = unreachable_receivers(scene, seen | (scene.masked != ""))
    rx_of_link = np.arange(scene.n_links) % len(scene.receivers)
    directions[np.isin(rx_of_link, np.concatenate([blocked, masked]).astype(np.int64))] = SKIP
    if exact_los_only(scene, job.settings):
        directions[:] = SKIP
        job.info.stop_reason = StopReason.EXACT
        job.info.direction_choice = DirectionChoicePublic(
            rule="max_reflections = 0 without scattering: line of sight only, in closed form"
        )
    return blocked


def exact_los_only(scene: Scene, settings: KernelSettings) -> bool:
    """True when every path the job asks for is a line of sight (computed exactly): no Monte Carlo at all."""
    scatters = scene.medium is not None and (settings.free_flight or settings.segment_scatter)
    return settings.max_reflections == 0 and not scatters


def batch_size(sim: SimulationSpec, settings: KernelSettings, n_targets: int) -> int:
    """Paths per batch: the job's batch_size, capped so that paths x targets stay under PATH_TARGET_BUDGET
    (the dense per-path tallies) and paths x targets x estimates per segment under ESTIMATE_BUDGET (one
    step's next-event estimates, ~60 B each)."""
    per_segment = 1
    if settings.segment_scatter:
        per_segment += settings.max_strata + settings.equiangular_points
    if settings.free_flight:
        per_segment += settings.equiangular_points
    n_targets = max(1, n_targets)
    n_targets *= settings.tally_channels  # spectral scenes tally 1 + V channels per target (engine/spectral/spectra.py)
    size = max(1, min(sim.batch_size, PATH_TARGET_BUDGET // n_targets, ESTIMATE_BUDGET // (n_targets * per_segment)))
    return qmc.whole_blocks(size, settings.qmc_block)


#: A run of batches: (direction, source device, target devices).
Run = tuple[Direction, int, tuple[int, ...]]


def _sources(scene: Scene, directions: IntArray) -> list[Run]:
    """(direction, source, targets) runs that cover every link in its chosen direction(s)."""
    n_rx = len(scene.receivers)
    codes = directions.reshape(len(scene.transmitters), n_rx)
    fwd, bwd = (codes == FORWARD) | (codes == BOTH), (codes == BACKWARD) | (codes == BOTH)
    runs = [(Direction.FORWARD, i, tuple(np.flatnonzero(fwd[i]).tolist())) for i in range(fwd.shape[0]) if fwd[i].any()]
    runs += [(Direction.BACKWARD, j, tuple(np.flatnonzero(bwd[:, j]).tolist())) for j in range(n_rx) if bwd[:, j].any()]
    return runs


#: The random-stream phase of WorkItem.rng: the main run's batches and the direction pilot's are independent.
MAIN_PHASE, PILOT_PHASE = 0, 1


def _items(
    runs: list[Run], sim: SimulationSpec, settings: KernelSettings, phase: int, n_paths: int | None
) -> Iterator[WorkItem]:
    """Batches in rounds (one per run per round); endless when n_paths is None.

    Every run of a direction has the same batch size (capped by its largest target count), so the
    plan, and with it the random streams, depends on the scene document only."""
    sizes = {
        d: batch_size(sim, settings, max((len(t) for dd, _, t in runs if dd == d), default=1))
        for d in (Direction.FORWARD, Direction.BACKWARD)
    }
    bs = min(sizes[d] for d in {r[0] for r in runs}) if runs else sim.batch_size
    grown = bs
    if n_paths is None:  # accuracy mode: a round of many sources checks the target sooner: first batches of a
        # quarter (or 1 / sources) of batch_size, growing to the largest batch the memory caps allow
        bs = qmc.whole_blocks(min(bs, max(MIN_PATHS_FOR_STOP, sim.batch_size // max(len(runs), 4))), settings.qmc_block)
    rounds: Iterable[int] = itertools.count() if n_paths is None else range(-(-n_paths // bs))
    for b in rounds:
        if n_paths is None:  # accuracy mode: batches double every GROWTH_ROUNDS rounds up to the memory cap
            size = min(grown, bs << min(b // GROWTH_ROUNDS, 16))
        else:
            size = min(bs, n_paths - b * bs)
        for direction, source, targets in runs:
            yield WorkItem(direction, source, targets, b, size, sim.seed, phase)


def _new_accumulators(scene: Scene, settings: KernelSettings) -> dict[Direction, Accumulator]:
    check_spectral(scene, settings.free_flight or settings.segment_scatter)  # the kernel the job chose
    n_bands = scene.spectra.n_bands if scene.spectra is not None else 0  # spectral scenes: channel tallies too
    accs = {
        d: Accumulator(scene.n_links, settings.tally, backward=d is Direction.BACKWARD, n_bands=n_bands)
        for d in (Direction.FORWARD, Direction.BACKWARD)
    }
    return accs


def _merge(
    job: Job,
    accs: dict[Direction, Accumulator],
    items: Iterable[WorkItem],
    on_batch: Callable[[WorkItem], bool] | None = None,
) -> None:
    """Feed items to the executor and merge their tallies in order; `on_batch` may stop the run."""
    pulled: deque[WorkItem] = deque()

    def recording() -> Iterator[WorkItem]:
        for it in items:
            pulled.append(it)
            yield it

    results = job.executor.map(job.ref, recording(), job.settings)
    try:
        for tally in results:
            item = pulled.popleft()
            accs[item.direction].add(tally, item.batch, item.source)
            if on_batch is not None and on_batch(item):
                break
    finally:
        results.close()


def _choose_directions(job: Job) -> IntArray:
    """Per link: the Direction.code its paths run in (SKIP is set later for links not simulated): by a rule
    (two-sided, the algorithm's, requested, line of sight only, amortized over many devices) or a pilot."""
    ruled = _direction_rule(job)
    if ruled is not None:
        choice, direction = ruled
        job.info.direction_choice = choice
        return np.full(job.scene.n_links, direction.code)
    choice, directions = _direction_pilot(job)
    job.info.direction_choice = choice
    return directions


def _direction_rule(job: Job) -> tuple[DirectionChoicePublic, Direction] | None:
    """The direction of every link when a rule decides it (and why); None: a pilot must choose."""
    spec, scene = job.spec, job.scene
    sim = spec.simulation
    alg = algorithm(sim.algorithm)
    n_tx, n_rx = len(scene.transmitters), len(scene.receivers)
    if two_sided(spec, scene):
        rule = (
            f"algorithm {sim.algorithm} in a medium: every link from both devices, each path weighted by its "
            "share (integrator/weights.py: bounded weights near point devices)"
        )
        return DirectionChoicePublic(rule=rule), Direction.BOTH
    if alg.direction is not None:
        return DirectionChoicePublic(rule=alg.direction_reason), alg.direction
    if sim.direction != "auto":
        return DirectionChoicePublic(rule=f"requested: {sim.direction}"), Direction(sim.direction)
    if sim.max_reflections == 0:
        rule = "max_reflections = 0: line of sight only, computed exactly"
        return DirectionChoicePublic(rule=rule), Direction.FORWARD
    if n_rx >= AMORTIZATION_RATIO * n_tx:
        # A map: forward paths serve every receiver at once, but their next-event estimates from wall points
        # a few cm from a receiver are heavy-tailed, so the map's worst points converge slowly; paths from each
        # receiver to the few luminaires do not (benchmarks/map_scale.py measures both).
        rule = (
            f"{n_tx} transmitters x {n_rx} receivers (a map): paths from each receiver to the few transmitters; "
            "no pilot"
        )
        return DirectionChoicePublic(rule=rule), Direction.BACKWARD
    if n_tx >= AMORTIZATION_RATIO * n_rx:
        rule = (
            f"{n_tx} transmitters x {n_rx} receivers: the receiver side amortizes its paths over the "
            "transmitters, no pilot"
        )
        return DirectionChoicePublic(rule=rule), Direction.BACKWARD
    return None


def _direction_pilot(job: Job) -> tuple[DirectionChoicePublic, IntArray]:
    """A short run each way; per link the side of higher efficiency = 1 / (relative variance per path x rays
    per path), rays shared by the links a source serves. Ray counts (not times) keep the choice deterministic.

    Its paths are not merged into the result: the choice depends on their sample variance (and mean), so
    the chosen side's pilot paths are a selected sample, not an unbiased one (CHANGELOG, pilot reuse)."""
    scene, sim = job.scene, job.spec.simulation
    n_tx, n_rx = len(scene.transmitters), len(scene.receivers)
    cost_eff, sound = [], []
    for direction in (Direction.FORWARD, Direction.BACKWARD):
        runs = _sources(scene, np.full(scene.n_links, direction.code))
        accs = _new_accumulators(scene, job.settings)
        _merge(job, accs, _items(runs, sim, job.settings, PILOT_PHASE, sim.pilot_paths))
        acc = accs[direction]
        n = acc.n_paths.astype(float)
        mean = acc.s1[:, 0] / n
        var = np.maximum(acc.s2[:, 0, 0] / n - mean**2, 0.0)
        h0 = mean + job.los.gain
        rays_per_path = (acc.rays_intersect + acc.rays_occluded) / max(n.sum(), 1)
        links_per_source = n_rx if direction is Direction.FORWARD else n_tx
        with np.errstate(divide="ignore", invalid="ignore"):
            rel_var = np.where(h0 > 0, var / h0**2, np.inf)
            cost_eff.append((rel_var * rays_per_path / links_per_source, np.sqrt(rel_var), rays_per_path))
        # Its variance is only a measure when its paths reached the receiver's surroundings: a side whose
        # sampled part (LOS left out) is 0 or held by a few path groups has not seen its own tail
        sampled = reliability.from_accumulators([acc])
        sound.append(sampled.trusted() & (sampled.estimate > 0))
    by_variance = np.where(cost_eff[1][0] < cost_eff[0][0], BACKWARD, FORWARD)
    choice = np.where(sound[1] & ~sound[0], BACKWARD, np.where(sound[0] & ~sound[1], FORWARD, by_variance))
    overruled = int((choice != by_variance).sum())
    why = (
        f"; {overruled} link(s) from the only side whose pilot saw a sampled part not held by a few path groups"
        if overruled
        else ""
    )
    report = DirectionChoicePublic(
        rule="pilot: lower relative variance x rays per path, per link" + why,
        paths_per_direction=sim.pilot_paths,
        rel_std_per_path_forward=_finite_list(cost_eff[0][1]),
        rel_std_per_path_backward=_finite_list(cost_eff[1][1]),
        rays_per_path_forward=float(cost_eff[0][2]),
        rays_per_path_backward=float(cost_eff[1][2]),
    )
    return report, choice


def _finite_list(x: FloatArray) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in x]


def _run(job: Job, directions: IntArray) -> dict[Direction, Accumulator]:
    """Run the batches of every link in its direction(s), merging as they come; stop by the job's rule
    (engine/run/stopping.py)."""
    sim = job.spec.simulation
    runs = _sources(job.scene, directions)
    accs = _new_accumulators(job.scene, job.settings)
    n_paths = sim.n_paths
    total_batches = None
    if n_paths is not None and runs:
        first = next(_items(runs, sim, job.settings, MAIN_PHASE, n_paths))
        total_batches = len(runs) * -(-n_paths // first.n_paths)
    if not runs:  # every link exact or skipped (unreachable receivers): nothing to run, not an endless loop
        if job.info.stop_reason is not StopReason.EXACT:
            job.info.stop_reason = StopReason.NOTHING_TO_SIMULATE
        return accs
    if allocation.is_map(job, directions):  # a map: packed batches; to a target, each point's paths by its own error
        cap = batch_size(sim, job.settings, len(job.scene.transmitters))
        allocation.run_map(job, runs, directions, accs, _merge, cap)
        return accs
    watch = BatchWatch(job, accs, directions, len(runs), total_batches)
    _merge(job, accs, _items(runs, sim, job.settings, MAIN_PHASE, n_paths), watch)
    return accs
