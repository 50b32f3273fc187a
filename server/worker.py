"""One job's run, in its own worker process: load the scene, simulate, write progress and outcome.

The worker talks to the job store with its own connection. After every batch it
writes progress (at most every `progress_interval_s`) and learns whether to stop:
the job was cancelled, its run was taken back (server restart), the server process
is gone (its end of the worker's lifeline pipe closed), or the wall-time limit is reached. A
cancelled run stores its partial result. An engine error fails the job with the engine's message.

Memory: before anything else the worker caps its own address space (RLIMIT_AS) at what it
has mapped already + the job's memory estimate (engine.run.budget, made at submission) + a
headroom for the thread stacks and allocator arenas Embree/TBB and numpy reserve but do not
use; an allocation past it raises MemoryError, reported as "ran out of its memory budget".
At the end it renders the result once (server.formats.render_all: JSON, CSV, NPZ,
compressed) and stores the renders with the outcome: serving a result never re-renders it
(plots are drawn from the stored NPZ at their first request, so no job pays matplotlib's time).
"""

from __future__ import annotations

import ctypes
import logging
import resource
import signal
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .formats import render_all

if TYPE_CHECKING:
    from owcsim.engine.run.simulate import Progress

log = logging.getLogger("owcsim.server.worker")


@dataclass(frozen=True)
class WorkerLimits:
    workers: int
    max_wall_time_s: float
    progress_interval_s: float
    scheduler: str | None = None  # Dask scheduler address: batches run on its cluster
    memory_headroom_bytes: int = 1 << 30  # address space allowed beyond mapped-at-start + estimate [B]


#: glibc mallopt parameter: most malloc arenas (each thread's arena reserves 64 MB of address space).
_M_ARENA_MAX = -8


def mapped_bytes() -> int:
    """Address space this process has mapped now [B] (VmSize)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * resource.getpagesize()


def cap_address_space(budget_bytes: int, headroom_bytes: int) -> int:
    """Limit this process's address space to what it maps now + budget + headroom; returns the limit [B]."""
    try:  # fewer per-thread malloc arenas: their reservations would count against the limit
        ctypes.CDLL("libc.so.6").mallopt(_M_ARENA_MAX, 2)
    except (OSError, AttributeError):
        pass
    limit = mapped_bytes() + budget_bytes + headroom_bytes
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    return limit


def out_of_memory_reason(budget_bytes: int) -> str:
    return (
        f"the job ran out of its memory budget of {budget_bytes / 2**30:.3g} GB (estimated from its settings: "
        "links x reflection and scattering orders x time bins, receivers, batch_size, triangles): ask for "
        "fewer receivers, orders or time bins, or a smaller batch_size"
    )


class _Watch:
    """Progress writer and stop rule of one run (called by the engine after each batch)."""

    def __init__(self, store, job_id: str, token: int, limits: WorkerLimits, lifeline):
        self.store, self.job_id, self.token, self.limits = store, job_id, token, limits
        self.lifeline = lifeline
        self.t0 = time.monotonic()
        self.last_write = 0.0
        self.last_check = 0.0
        self.pending: tuple | None = None
        self.reason: str | None = None  # why the run stops early: cancelled, abandoned, time limit

    def progress(self, p: Progress) -> None:
        self.pending = (p.fraction, p.paths, p.batches, p.dc_gain_rel_stderr, p.elapsed_s)
        now = time.monotonic()
        if now - self.last_write >= self.limits.progress_interval_s:
            self.flush()

    def flush(self) -> None:
        self.last_write = time.monotonic()
        if self.pending is not None and not self.store.progress(self.job_id, self.token, *self.pending):
            self.reason = self.reason or "abandoned"

    def should_stop(self) -> bool:
        now = time.monotonic()
        if self.reason is None and self.lifeline.poll():
            self.reason = "abandoned"  # the server closed the pipe: it stopped, or it is gone
        if self.reason is None and now - self.last_check >= 0.2:
            self.last_check = now
            mine, cancel = self.store.run_state(self.job_id, self.token)
            self.reason = "abandoned" if not mine else "cancelled" if cancel else None
            if self.reason is None and now - self.t0 > self.limits.max_wall_time_s:
                self.reason = "time_limit"
        return self.reason is not None


def run_job(db_path: str, job_id: str, token: int, limits: WorkerLimits, lifeline, memory_bytes: int = 0) -> None:
    """Entry point of the worker process. `lifeline`: read end of a pipe only the server writes to;
    `memory_bytes`: the job's memory estimate [B] (0: no cap)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the server decides
    from owcsim.engine.core.errors import EngineError
    from owcsim.engine.run.simulate import simulate
    from owcsim.schemas import SceneSpec

    from .store import JobStore

    store = JobStore(db_path)
    watch = _Watch(store, job_id, token, limits, lifeline)
    executor = None
    if memory_bytes > 0:  # after the imports (the forkserver has them already) and the store's connection
        cap_address_space(memory_bytes, limits.memory_headroom_bytes)
    try:
        spec = SceneSpec.model_validate_json(store.scene_json(job_id))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if limits.scheduler:
                from owcsim.engine.run.execution_dask import executor_from_scheduler

                executor = executor_from_scheduler(limits.scheduler)
            if spec.timeline is not None:  # one run per time, progress per time (engine/run/timeline.py)
                from owcsim.engine.run.timeline import run_timeline

                result = run_timeline(
                    spec, workers=limits.workers, progress=watch.progress, should_stop=watch.should_stop
                )
            else:
                result = simulate(
                    spec,
                    base_dir=None,
                    workers=limits.workers,
                    progress=watch.progress,
                    should_stop=watch.should_stop,
                    executor=executor,
                )
        notes = list(dict.fromkeys(str(w.message) for w in caught))
    except EngineError as exc:
        store.finish(job_id, token, "failed", error=str(exc))
        return
    except MemoryError:
        result = None  # free what can be freed before writing
        store.finish(job_id, token, "failed", error=out_of_memory_reason(memory_bytes))
        return
    except Exception as exc:  # a bug, not the user's input: keep the trace in the server log
        log.exception("job %s: the engine failed", job_id)
        store.finish(job_id, token, "failed", error=f"internal error in the engine ({type(exc).__name__}: {exc})")
        return
    finally:
        if executor is not None:
            try:
                executor.close()
            except Exception:  # the job's outcome is decided; a cluster that went away must not change it
                log.warning("job %s: closing the Dask client failed", job_id, exc_info=True)
        sys.stderr.flush()
    assert result is not None  # set by simulate: the branches that clear it return
    if watch.reason == "abandoned":
        return
    if watch.reason == "time_limit":
        store.finish(
            job_id,
            token,
            "failed",
            warnings=notes,
            error=f"stopped at the server's wall-time limit of {limits.max_wall_time_s:g} s after "
            f"{result.run.paths_total:,d} paths: ask for fewer paths or a larger "
            "target_rel_error",
        )
        return
    watch.flush()
    status = "cancelled" if watch.reason == "cancelled" else "succeeded"
    try:
        text = result.model_dump_json()  # JSON has no NaN/inf: the model writes them as null
        with tempfile.TemporaryDirectory(prefix=f"owcsim-{job_id[:8]}-", dir=Path(db_path).parent) as tmp:
            renders = render_all(result, text, Path(tmp))
            store.finish(job_id, token, status, result_json=text, warnings=notes, renders=renders)
    except MemoryError:
        result = text = None
        store.finish(
            job_id,
            token,
            "failed",
            warnings=notes,
            error=out_of_memory_reason(memory_bytes) + " (while storing the result)",
        )
