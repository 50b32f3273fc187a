"""Executors: where batches run. Results always come back in submission order.

`SerialExecutor` traces in the calling process; `ProcessExecutor` keeps a pool of
worker processes, each building the Embree scene once (in its initializer) and then
tracing the work items it is sent. Items are independent (their random streams are
fixed by the job), so the merged result does not depend on the executor or the
number of workers. The interface is `map(items) -> iterator of BatchTally`; items
may be an endless generator (accuracy mode): only a bounded window is in flight.
"""
from __future__ import annotations

import multiprocessing as mp
from collections import deque
from concurrent.futures import ProcessPoolExecutor
from typing import Iterable, Iterator, Protocol

from schemas import SceneSpec

from .kernel import KernelSettings, WorkItem, trace_batch
from .scene import Scene, build_scene


class Executor(Protocol):
    def map(self, items: Iterable[WorkItem], settings: KernelSettings) -> Iterator: ...

    def close(self) -> None: ...


class SerialExecutor:
    """Trace every batch in this process, on `scene`."""

    def __init__(self, scene: Scene):
        self.scene = scene

    def map(self, items, settings):
        for item in items:
            yield trace_batch(self.scene, item, settings)

    def close(self) -> None:
        pass


_WORKER_SCENE: Scene | None = None


def _init_worker(spec_json: str, base_dir: str | None) -> None:
    global _WORKER_SCENE
    _WORKER_SCENE = build_scene(SceneSpec.model_validate_json(spec_json), base_dir)


def _run_item(item: WorkItem, settings: KernelSettings):
    return trace_batch(_WORKER_SCENE, item, settings)


class ProcessExecutor:
    """A pool of `workers` processes (forkserver start: no Embree/TBB state is forked)."""

    def __init__(self, spec: SceneSpec, base_dir: str | None, workers: int):
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(["engine.kernel"])
        self.workers = workers
        self._pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                                         initargs=(spec.model_dump_json(), base_dir))

    def map(self, items, settings):
        window = deque()
        it = iter(items)
        try:
            for item in it:
                window.append(self._pool.submit(_run_item, item, settings))
                if len(window) >= 2 * self.workers:
                    yield window.popleft().result()
            while window:
                yield window.popleft().result()
        finally:
            for f in window:
                f.cancel()

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
