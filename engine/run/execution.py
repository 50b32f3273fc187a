"""Executors: where batches run. Results always come back in submission order.

`SerialExecutor` traces in the calling process. `ProcessExecutor` keeps a pool of
worker processes that outlives jobs: each worker builds a job's Embree scene the
first time it sees the job (from the scene document written once to a file) and
caches it, so a warm pool pays no start-up per job; a job whose surfaces, transmitters and
medium a cached scene has already (an automatic job's truncation pilot and its run) only gets
its receivers set on that scene. The document travels pickled, not as
JSON: validating JSON again would re-normalise direction vectors and could change their
last bit, and with it the result. Work items are independent
(their random streams are fixed by the job), so the merged result does not depend
on the executor or the number of workers. `map(job, items, settings)` yields batch
tallies; `items` may be an endless generator (accuracy mode): only a bounded window
is in flight, and closing the iterator cancels what has not started.
"""

from __future__ import annotations

import hashlib
import multiprocessing as mp
import os
import pickle
import tempfile
import time
from collections import OrderedDict, deque
from collections.abc import Generator, Iterable
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from typing import Protocol

from owcsim.engine.integrator.kernel import trace_batch
from owcsim.engine.integrator.path import KernelSettings, WorkItem
from owcsim.engine.run.receivers import with_receivers
from owcsim.engine.scene.scene import Scene, build_scene
from owcsim.engine.tally.tally import BatchTally
from owcsim.schemas import SceneSpec

#: Scenes a worker keeps built (least recently used are dropped).
SCENE_CACHE_SIZE = 4


@dataclass
class JobRef:
    """What executors need to find a job's scene: the built scene (in this process), or its document."""

    scene: Scene
    key: str
    spec_path: str
    base_dir: str | None


def job_ref(scene: Scene, base_dir: str | None, folder: str | None = None) -> JobRef:
    """Write the validated scene document once (pickled, content-addressed) so workers can build it."""
    data = pickle.dumps(scene.spec, protocol=pickle.HIGHEST_PROTOCOL)
    key = hashlib.sha256(scene.spec.model_dump_json().encode() + b"\0" + data + str(base_dir).encode()).hexdigest()[:24]
    folder = folder or _private_folder()
    path = os.path.join(folder, f"{key}.pickle")
    if os.path.exists(path):
        os.utime(path)  # in use again: not stale
    else:
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
        _prune(folder)
    return JobRef(scene, key, path, base_dir)


#: Scene documents not used for this long are deleted when a new one is written [s].
STALE_SCENE_S = 7 * 24 * 3600.0


def _prune(folder: str, now: float | None = None) -> int:
    """Delete the scene pickles (and stray temporaries) of `folder` unused for STALE_SCENE_S; their count."""
    now = time.time() if now is None else now
    removed = 0
    for entry in os.scandir(folder):
        try:
            if entry.name.endswith((".pickle", ".tmp")) and now - entry.stat().st_mtime > STALE_SCENE_S:
                os.remove(entry.path)
                removed += 1
        except FileNotFoundError:  # another process pruned it first
            continue
    return removed


def _private_folder() -> str:
    """This user's scene folder under the temporary directory, readable by nobody else (it holds pickles)."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    folder = os.path.join(tempfile.gettempdir(), f"owcsim-scenes-{uid}")
    os.makedirs(folder, mode=0o700, exist_ok=True)
    st = os.stat(folder)
    if hasattr(os, "getuid") and (st.st_uid != uid or st.st_mode & 0o077):
        raise PermissionError(f"{folder} must belong to this user and be private (mode 700); remove it")
    return folder


class Executor(Protocol):
    workers: int

    def map(self, job: JobRef, items: Iterable[WorkItem], settings: KernelSettings) -> Generator[BatchTally]: ...

    def close(self) -> None: ...


class SerialExecutor:
    """Trace every batch in this process."""

    workers = 1

    def map(self, job: JobRef, items: Iterable[WorkItem], settings: KernelSettings) -> Generator[BatchTally]:
        for item in items:
            yield trace_batch(job.scene, item, settings)

    def close(self) -> None:
        pass


_SCENES: OrderedDict[str, Scene] = OrderedDict()
#: The fields of a scene document that decide what build_scene builds besides the receivers (surfaces, the
#: transmitters, the medium): documents that agree on them, as a job and its truncation pilot do, share one
#: built geometry in a worker (the receivers are set on it: receivers.with_receivers).
BUILT_FIELDS = {"room", "furniture", "meshes", "transmitters", "medium"}


def built_key(spec: SceneSpec, base_dir: str | None) -> str:
    """Key of what build_scene(spec, base_dir) builds besides the receivers."""
    text = spec.model_dump_json(include=BUILT_FIELDS) + "\0" + str(base_dir)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _worker_scene(key: str, spec_path: str, base_dir: str | None) -> Scene:
    """The job's scene in this worker: cached; built once per geometry (a job's pilot and its run share it)."""
    scene = _SCENES.get(key)
    if scene is None:
        with open(spec_path, "rb") as fh:
            spec = pickle.load(fh)
        assert isinstance(spec, SceneSpec), spec_path
        shared = built_key(spec, base_dir)
        same = next((_SCENES[k] for k, b in reversed(_BUILT.items()) if b == shared and k in _SCENES), None)
        if same is not None:
            scene = with_receivers(same, spec)
        else:
            scene = build_scene(spec, base_dir)
        _SCENES[key], _BUILT[key] = scene, shared
        while len(_SCENES) > SCENE_CACHE_SIZE:
            _BUILT.pop(_SCENES.popitem(last=False)[0], None)
    _SCENES.move_to_end(key)
    return scene


#: built_key of each cached scene (by its job key)
_BUILT: dict[str, str] = {}


def _run_item(
    key: str,
    spec_path: str,
    base_dir: str | None,
    item: WorkItem,
    settings: KernelSettings,
) -> BatchTally:
    """A batch in a worker: the JobRef's fields without its scene (the scene travels as its document's path)."""
    return trace_batch(_worker_scene(key, spec_path, base_dir), item, settings)


class ProcessExecutor:
    """A pool of `workers` processes (forkserver start: no Embree/TBB state is ever forked)."""

    def __init__(self, workers: int):
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(["owcsim.engine.integrator.kernel"])
        self.workers = workers
        self._pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx)

    def map(self, job: JobRef, items: Iterable[WorkItem], settings: KernelSettings) -> Generator[BatchTally]:
        window: deque[Future[BatchTally]] = deque()
        try:
            for item in items:
                task = (job.key, job.spec_path, job.base_dir, item, settings)
                window.append(self._pool.submit(_run_item, *task))
                if len(window) >= 2 * self.workers:
                    yield window.popleft().result()
            while window:
                yield window.popleft().result()
        finally:
            for f in window:
                f.cancel()

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
