"""The job as the planner runs it: one value passed to every step instead of long parameter lists.

`Job` holds a resolved job on its built scene (document, scene, kernel settings, executor, the line of
sight, the run's record and who watches it); `simulate.py` builds it once per run and its steps
(direction choice, batches, stopping rule) read it. The result builder gets a `FinishedJob`
(engine/results/job.py), below this layer.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from owcsim.engine.integrator.path import KernelSettings
from owcsim.engine.results.job import LineOfSight, RunInfo
from owcsim.engine.run.execution import Executor, JobRef
from owcsim.engine.scene.scene import Scene
from owcsim.schemas import SceneSpec


@dataclass(frozen=True, slots=True)
class Progress:
    """How far a run is, after its latest batch (the server stores it as schemas.jobs.JobProgress)."""

    fraction: float  # estimated fraction done, 0..1
    paths: int  # paths traced so far by the busiest link
    batches: int  # batches merged so far
    dc_gain_rel_stderr: float | None  # current worst relative standard error of H0 (None: not known yet)
    elapsed_s: float  # since the job started [s]


ProgressFn = Callable[[Progress], None]


@dataclass(frozen=True, slots=True)
class Watch:
    """Who watches a run: a progress callback, a cancel question asked after every batch, and its start."""

    progress: ProgressFn | None = None
    should_stop: Callable[[], bool] | None = None
    t_start: float = 0.0  # time.perf_counter() when the job started [s]


@dataclass(frozen=True, slots=True)
class Job:
    """A resolved job on its built scene, ready to run: what every step of the planner reads."""

    spec: SceneSpec  # resolved: no "auto" setting left
    scene: Scene
    settings: KernelSettings
    executor: Executor
    ref: JobRef  # where the executor's workers find the scene
    los: LineOfSight
    info: RunInfo  # filled in as the run goes
    watch: Watch
