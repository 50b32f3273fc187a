"""Maps in accuracy mode: each point's paths follow its own error, many points' paths to one kernel batch.

A map (a scene with receiver grids, every link run from its receiver) with a `target_rel_error` runs in rounds:

- round 0 gives every point `FIRST_PATHS` paths;
- after each round every point's quantities in `simulation.target_scope` are checked (tally/estimates.py
  `ready_points`: relative standard error of H0 at or below the target on a trusted error bar, the same rule
  as the whole job's, engine/tally/reliability.py, with its heavy-tail guard in a medium); a point that meets
  it gets no more paths, a point at relative error r with n paths gets n ((r / target)^2 - 1) x MARGIN more
  (the error falls as 1 / sqrt(paths)), at least QUANTUM and at most GROWTH_CAP x n;
- the run stops when every point is ready, or when the time budget is spent.

Why FIRST_PATHS = 256 replaces the blanket 2 048-path minimum of stopping.py. The minimum exists so that the
error bar a point stops on is itself trusted. A map's paths are pseudo-random (every path an independent
sample), so 256 paths give a sample variance with 255 degrees of freedom: the standard error is itself known
to about 1 / sqrt(2 x 255) = 4.4 % (Cramer 1946 section 27.4), the z-score of a point is a Student t with 255
degrees of freedom (95.4 % within 2 sigma, E[z^2] = 1.008), and the optional-stopping effect of stopping on
that error bar is bounded by the same 4 % (tests/engine/test_map_allocation.py measures the coverage of a
6 x 6 map at 1 % against a long reference run; benchmarks/map_scale.py --only f prints it over 12 seeds:
95.8 % within 2 sigma, mean z^2 0.97). Quasi-random blocks of 256 paths (engine/core/qmc.py) would make
256 paths one sample: 2 048 paths gave 8 samples, the fewest the reliability rule accepts.

Packed batches (`WorkItem.sources`, `counts`; engine/tally/packed.py): the points of one round that share
their targets, field of view and gain (normals may differ) are traced together, up to the job's batch
size per batch (simulate.batch_size), so a map's kernel batch reaches the sizes where the per-step fixed
cost is paid over many paths (benchmarks/path_cost.py). The plan of round r depends on the tallies merged up to its end
(merged in submission order), so the same document and seed give the same bits with any number of workers.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.arrays import IntArray
from owcsim.engine.integrator.path import KernelSettings, WorkItem
from owcsim.engine.run.job import Job, Progress
from owcsim.engine.scene.scene import Scene
from owcsim.engine.tally.estimates import ready_points
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas.algorithms import Direction
from owcsim.schemas.results import StopReason

#: Paths of every point in the first round (module docstring: why 256 samples suffice for a trusted error bar).
FIRST_PATHS = 256
#: Path counts are whole multiples of this.
QUANTUM = 64
#: A point's next round asks this much more than the 1 / sqrt(paths) law needs (its error is an estimate).
MARGIN = 1.1
#: A point gets at most this multiple of its paths so far in one round (a noisy first error cannot run away).
GROWTH_CAP = 8
#: Per-link Direction.code of links not simulated, and of links run from their receiver.
SKIP, BACKWARD = Direction.NONE.code, Direction.BACKWARD.code

#: (direction, source, targets) as simulate.Run
Run = tuple[Direction, int, tuple[int, ...]]
#: simulate._merge: feed items, merge tallies in order; the callback may stop the run
Merge = Callable[[Job, dict[Direction, Accumulator], Iterable[WorkItem], Callable[[WorkItem], bool]], None]


def packable(scene: Scene, settings: KernelSettings) -> bool:
    """True when the kernel may trace several sources in one batch: algorithm 1 (reflections, extinction
    only), no mirror, no spectral bands, one side (the emission and the tally of other algorithms read
    the one source of a batch)."""
    one_source_parts = (
        settings.segment_scatter or settings.free_flight or settings.mis or settings.both_sides or settings.phase_lobe
    )
    return not one_source_parts and not scene.mirror_planes and scene.spectra is None


def is_map(job: Job, directions: IntArray) -> bool:
    """A map whose batches pack several points: a scene with receiver grids, every link from its receiver (or
    skipped), in a kernel that packs, no receiver keeping a CIR or an order split, and pseudo-random paths (an
    accuracy run, or a fixed budget below the quasi-random blocks' floor: KernelSettings.qmc_block 1)."""
    spec, scene, plan = job.spec, job.scene, job.settings.tally
    return (
        bool(spec.receiver_grids)
        and (spec.simulation.n_paths is None or job.settings.qmc_block <= 1)
        and bool(np.all((directions == BACKWARD) | (directions == SKIP)))
        and packable(scene, job.settings)
        and not bool((plan.cir_rank >= 0).any() or (plan.order_rank >= 0).any())
    )


def extra_paths(n: IntArray, rel: np.ndarray, ready: np.ndarray, target: float) -> IntArray:
    """Paths each point gets next round: 0 when ready, else n ((rel / target)^2 - 1) MARGIN (half its paths when
    its error meets the target but the error bar is not yet trusted), in QUANTUM steps, within
    [QUANTUM, GROWTH_CAP n]."""
    n = np.asarray(n, np.int64)
    with np.errstate(invalid="ignore", over="ignore"):
        ratio = np.where(np.isfinite(rel), (np.asarray(rel, float) / target) ** 2, GROWTH_CAP + 1.0)
    want = np.where(ratio > 1.0, n * (ratio - 1.0) * MARGIN, 0.5 * n)
    want = np.clip(want, QUANTUM, GROWTH_CAP * np.maximum(n, QUANTUM))
    want = (np.ceil(want / QUANTUM) * QUANTUM).astype(np.int64)
    return np.where(ready, 0, want)


def pack(
    runs: list[Run], need: IntArray, scene: Scene, cap: int, round_index: int, seed: int, phase: int
) -> list[WorkItem]:
    """The round's packed batches: the points with need > 0, grouped by targets, field of view and gain (one
    weight per path; normals may differ: kernel._packed_directions), in receiver order, at most `cap` paths
    per batch (a point needing more gets batches of its own)."""
    rx = scene.receivers
    groups: dict[tuple[tuple[int, ...], float, float], list[tuple[int, int]]] = {}
    for _, source, targets in runs:  # one entry per point: the grouping keys, no per-path work
        if need[source] > 0:
            key = (targets, float(rx.cos_fov[source]), float(rx.gain[source]))
            groups.setdefault(key, []).append((source, int(need[source])))
    items: list[WorkItem] = []
    for (targets, *_), members in groups.items():
        batch: list[tuple[int, int]] = []  # (source, paths) of the batch being filled
        filled = 0  # its paths
        for source, count in members:
            while count > 0:
                take = min(count, cap - filled)
                batch.append((source, take))
                count -= take
                filled += take
                if filled >= cap:
                    items.append(_packed_item(targets, batch, round_index, seed, phase, len(items)))
                    batch, filled = [], 0
        if batch:
            items.append(_packed_item(targets, batch, round_index, seed, phase, len(items)))
    return items


def _packed_item(
    targets: tuple[int, ...], batch: list[tuple[int, int]], round_index: int, seed: int, phase: int, part: int
) -> WorkItem:
    """A packed batch of receivers' paths: (source, paths) in order."""
    sources, counts = tuple(s for s, _ in batch), tuple(c for _, c in batch)
    return WorkItem(
        Direction.BACKWARD, sources[0], targets, round_index, sum(counts), seed, phase, sources, counts, part
    )


@dataclass
class MapWatch:
    """Called with each merged batch of a map run: counts it, reports progress, honours a cancel."""

    job: Job
    accs: dict[Direction, Accumulator]
    points_done: float = 0.0  # fraction of points ready after the latest round
    worst: float | None = None  # the worst point's relative standard error after the latest round
    done: int = 0
    progress_at: float = -1.0

    def __call__(self, item: WorkItem) -> bool:
        self.done += 1
        job = self.job
        job.info.batches = self.done
        elapsed = time.perf_counter() - job.watch.t_start
        if job.watch.progress is not None and elapsed - self.progress_at >= 0.25:
            self.progress_at = elapsed
            budget = job.spec.simulation.time_budget_s
            job.watch.progress(
                Progress(
                    fraction=min(1.0, max(elapsed / budget, self.points_done)),
                    paths=int(max(a.n_paths.max() for a in self.accs.values())),
                    batches=self.done,
                    dc_gain_rel_stderr=self.worst,
                    elapsed_s=elapsed,
                )
            )
        if job.watch.should_stop is not None and job.watch.should_stop():
            job.info.stop_reason = StopReason.CANCELLED
            return True
        return False


def run_map(
    job: Job, runs: list[Run], directions: IntArray, accs: dict[Direction, Accumulator], merge: Merge, cap: int
) -> None:
    """Run a map in packed batches: a fixed budget in one round of `paths` per point; an accuracy run in rounds,
    each point's paths by its own error (module docstring). Sets the stop reason."""
    sim, scene = job.spec.simulation, job.scene
    n_rx = len(scene.receivers)
    need = np.zeros(n_rx, np.int64)
    watch = MapWatch(job, accs)
    target = sim.target_rel_error
    if target is None:  # a fixed budget: every point's paths at once
        assert sim.n_paths is not None
        need[[source for _, source, _ in runs]] = sim.n_paths
        merge(job, accs, pack(runs, need, scene, cap, 0, sim.seed, 0), watch)
        return
    served = directions != SKIP
    need[[source for _, source, _ in runs]] = FIRST_PATHS
    acc = accs[Direction.BACKWARD]
    for round_index in range(1 << 20):
        items = pack(runs, need, scene, cap, round_index, sim.seed, 0)
        merge(job, accs, items, watch)
        if job.info.stop_reason is StopReason.CANCELLED:
            return
        ready, rel = ready_points(
            accs,
            job.los.gain,
            scene,
            job.settings.tally,
            target,
            served,
            sim.target_scope,
            heavy_tails=scene.medium is not None,
        )
        ready |= ~np.isin(np.arange(n_rx), [source for _, source, _ in runs])  # points not run
        watch.points_done = float(ready.mean()) if n_rx else 1.0
        watch.worst = float(rel.max()) if n_rx and np.isfinite(rel.max()) else None
        if ready.all():
            job.info.stop_reason = StopReason.TARGET_REACHED
            return
        if time.perf_counter() - job.watch.t_start >= sim.time_budget_s:
            job.info.stop_reason = StopReason.TIME_BUDGET
            return
        paths = acc.n_paths.reshape(-1, n_rx).max(axis=0)
        need = extra_paths(paths, rel, ready, target)
