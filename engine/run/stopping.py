"""The job's stopping rule and progress reports, asked after every merged batch (simulate._merge).

A run of a given number of paths stops after its last batch. An accuracy run (paths = None) is
checked at the end of every round (one batch per source): it stops once every link has
MIN_PATHS_FOR_STOP paths and its relative standard error of H0 is at or below the target (and the
reliability rule agrees, engine/tally/estimates.may_stop), or when the time budget is spent. The
caller's `should_stop` cancels any run. A map whose points pack into shared batches runs per point
instead (engine/run/allocation.py: rounds, each point's paths by its own error, no blanket minimum).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.arrays import IntArray
from owcsim.engine.integrator.path import WorkItem
from owcsim.engine.run.job import Job, Progress
from owcsim.engine.tally.estimates import may_stop, reported_rel_stderr
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas.algorithms import Direction
from owcsim.schemas.results import StopReason

#: Least time between two evaluations of every link's error for progress reports [s].
PROGRESS_INTERVAL_S = 0.25
#: Accuracy mode checks the target only once each link has this many paths.
MIN_PATHS_FOR_STOP = 2048
#: Per-link code of links not simulated (Direction.code).
SKIP = Direction.NONE.code


@dataclass
class BatchWatch:
    """Called with each merged batch: counts it, reports progress, and says whether the run stops.

    `total_batches` is the run's batch count (None: accuracy mode, endless rounds of `n_runs` batches)."""

    job: Job
    accs: Mapping[Direction, Accumulator]
    directions: IntArray  # per link, Direction.code
    n_runs: int  # batches per round (one per source)
    total_batches: int | None
    done: int = 0  # batches merged so far
    worst: float = math.inf  # latest worst relative standard error of H0
    rel_at: float = -PROGRESS_INTERVAL_S  # elapsed time of that evaluation [s]

    def __call__(self, item: WorkItem) -> bool:
        self.done += 1
        self.job.info.batches = self.done
        end_of_round = self.done % max(self.n_runs, 1) == 0
        elapsed = time.perf_counter() - self.job.watch.t_start
        self._update_error(elapsed, end_of_round)
        progress = self.job.watch.progress
        if progress is not None:
            progress(
                Progress(
                    fraction=self._fraction(elapsed),
                    paths=int(max(a.n_paths.max() for a in self.accs.values())),
                    batches=self.done,
                    dc_gain_rel_stderr=self.worst if np.isfinite(self.worst) else None,
                    elapsed_s=elapsed,
                )
            )
        should_stop = self.job.watch.should_stop
        if should_stop is not None and should_stop():
            self.job.info.stop_reason = StopReason.CANCELLED
            return True
        if self.total_batches is None and end_of_round:
            return self._accuracy_stop(elapsed)
        return False

    def _update_error(self, elapsed: float, end_of_round: bool) -> None:
        """The error of every link costs O(links): computed where the stopping rule needs it (end of a round in
        accuracy mode) and for progress at most every PROGRESS_INTERVAL_S, not after each of a map's batches."""
        last = self.total_batches is not None and self.done == self.total_batches
        if (self.total_batches is None and end_of_round) or (
            self.job.watch.progress is not None and (last or elapsed - self.rel_at >= PROGRESS_INTERVAL_S)
        ):
            job = self.job
            scope = job.spec.simulation.target_scope
            rel = reported_rel_stderr(self.accs, job.los.gain, job.scene, job.settings.tally, scope)
            self.worst = float(np.max(rel)) if len(rel) else 0.0
            self.rel_at = elapsed

    def _fraction(self, elapsed: float) -> float:
        """Estimated fraction done: batches merged, or in accuracy mode the larger of the time budget spent
        and (target / worst error)^2 (the error falls as 1 / sqrt(paths))."""
        if self.total_batches is not None:
            return self.done / self.total_batches
        worst, target = self.worst, self._target()
        return min(
            1.0,
            max(
                elapsed / self.job.spec.simulation.time_budget_s,
                0.0 if not np.isfinite(worst) else (target / worst) ** 2 if worst > 0 else 1.0,
            ),
        )

    def _target(self) -> float:
        """The accuracy run's target relative standard error of H0 (given: no paths count)."""
        target = self.job.spec.simulation.target_rel_error
        assert target is not None, "an accuracy run has a target_rel_error"
        return target

    def _accuracy_stop(self, elapsed: float) -> bool:
        """End of a round in accuracy mode: the target reached on every simulated link, or the time spent."""
        job, sim, target = self.job, self.job.spec.simulation, self._target()
        simulated = self.directions != SKIP
        served = np.sum([a.n_paths for a in self.accs.values()], axis=0)[simulated]
        if (
            (served.min() if len(served) else MIN_PATHS_FOR_STOP) >= MIN_PATHS_FOR_STOP
            and self.worst <= target
            and may_stop(
                self.accs,
                job.los.gain,
                job.scene,
                job.settings.tally,
                target,
                simulated,
                sim.target_scope,
                heavy_tails=job.scene.medium is not None,  # reliability.py: optional stopping in smoke
            )
        ):
            job.info.stop_reason = StopReason.TARGET_REACHED
            return True
        if elapsed >= sim.time_budget_s:
            job.info.stop_reason = StopReason.TIME_BUDGET
            return True
        return False
