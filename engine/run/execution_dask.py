"""Dask distributed executor: a job's batches run as tasks on a Dask cluster.

Install with `pip install 'owcsim[cluster]'` (dask[distributed]); the engine imports
without it, and `DaskExecutor` raises `DaskUnavailableError` (with the pip command)
when it is missing. Every worker needs the same owcsim installation as the client.

How a job runs (`DaskExecutor.map`, the executor interface of engine.run.execution):

- The scene goes to the cluster once per job, as the result of one small task
  (`owcsim-scene-<key>`) holding the validated scene document. Each worker fetches it
  once, builds the Embree scene on its first batch of the job and keeps it in a
  worker-side cache keyed by the job's content key (per worker thread: the
  intersector's ray counters are per scene), so batches carry only their WorkItem.
  The document travels as the validated pydantic object (pickled), not as JSON text:
  re-validating JSON re-normalises direction vectors, which can change their last bit.
  Mesh `file`s are read by the client and sent as `data_base64` (workers need no
  shared file system). The worker checks a fingerprint of the geometry and devices it
  built against the client's, so a worker with another trimesh, another mesh file or
  another engine fails loudly instead of returning different numbers.
- Each WorkItem becomes one task (`owcsim-batch-...`), submitted in item order with at
  most `window` in flight; tallies are yielded in item order and the engine merges
  them in that order. A task's random stream is fixed by its WorkItem (seed, phase,
  direction, source, batch), never by the worker that runs it, so a retried task
  returns the identical tally and results are bit-identical to the local pool for
  any number of workers.
- Reduction: each task returns its batch tally (the batch's contributions already
  reduced on the worker to per-link arrays) and the client folds the tallies in
  batch order. Floating-point addition is not associative, so only the same
  sequential fold as the local pool gives the same bits; a tree reduction on the
  cluster would not, and a sequential chain on the cluster would serialise the job.
  The engine also needs every batch on the client: progress and the accuracy-mode
  stopping rule read the merged tallies after every batch.
- Lost workers: the scheduler reschedules their tasks (up to
  `distributed.scheduler.allowed-failures` deaths per task); a task that raises is
  retried `retries` times. Either way the job's result is exact and complete.
- Cancellation: closing the iterator returned by `map` (the engine does when
  `should_stop` answers True or on any error) cancels the job's pending tasks on
  the cluster.
"""

from __future__ import annotations

import base64
import concurrent.futures
import functools
import hashlib
import importlib.metadata
import platform
import threading
import time
import uuid
import warnings
import weakref
from collections import OrderedDict, deque
from collections.abc import Generator, Iterable
from pathlib import Path

import numpy as np

from owcsim.engine.core.errors import EngineError, SceneError
from owcsim.engine.integrator.kernel import trace_batch
from owcsim.engine.integrator.path import KernelSettings, WorkItem
from owcsim.engine.run.execution import SCENE_CACHE_SIZE, JobRef
from owcsim.engine.scene.scene import Scene, build_scene
from owcsim.engine.tally.tally import BatchTally
from owcsim.schemas import SceneSpec

PIP_INSTALL = "pip install 'owcsim[cluster]'"


class DaskUnavailableError(EngineError, ImportError):
    """Distributed execution was requested but dask[distributed] is not installed."""


class ClusterError(EngineError):
    """The Dask cluster cannot run the job: unreachable, without workers, or not the same installation."""


def _distributed():
    try:
        import distributed
    except ImportError as exc:
        raise DaskUnavailableError(
            f"distributed execution needs Dask, which is not installed ({exc}); install it with: {PIP_INSTALL}"
        ) from None
    return distributed


# --------------------------------------------------------------------------- what travels


def portable_spec(spec: SceneSpec, base_dir: str | Path | None) -> SceneSpec:
    """The scene with every mesh `file` read here and inlined as `data_base64` + `format`.

    Paths resolve as `build_scene` resolves them (relative to `base_dir`, else to the
    working directory), so the workers load the same bytes with the same format.
    """
    spec = _inline_photometry(spec, base_dir)
    if not any(m.file is not None for m in spec.meshes):
        return spec
    meshes = []
    for i, mesh in enumerate(spec.meshes):
        if mesh.file is None:
            meshes.append(mesh)
            continue
        path = Path(mesh.file)
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        try:
            data = path.read_bytes()
        except OSError as exc:
            where = "" if base_dir is not None or path.is_absolute() else " (relative to the working directory)"
            raise SceneError(
                f"{mesh.name or f'meshes[{i}]'}: cannot read mesh file {str(path)!r}{where} to send "
                f"it to the cluster ({exc.strerror or exc})"
            ) from None
        meshes.append(
            mesh.model_copy(
                update={
                    "file": None,
                    "data_base64": base64.b64encode(data).decode("ascii"),
                    "format": mesh.format or path.suffix[1:].lower(),
                }
            )
        )
    return spec.model_copy(update={"meshes": meshes})


def _inline_photometry(spec: SceneSpec, base_dir: str | Path | None) -> SceneSpec:
    """Transmitters' photometric `file`s read here and inlined (as `portable_spec` does for meshes)."""
    if not any(t.photometry is not None and t.photometry.file is not None for t in spec.transmitters):
        return spec
    txs = []
    for i, tx in enumerate(spec.transmitters):
        phot = tx.photometry
        if phot is None or phot.file is None:
            txs.append(tx)
            continue
        path = Path(phot.file)
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise SceneError(
                f"transmitters[{i}].photometry: cannot read {str(path)!r} to send it to the cluster "
                f"({exc.strerror or exc})"
            ) from None
        phot = phot.model_copy(
            update={"file": None, "data_base64": base64.b64encode(data).decode("ascii"), "format": phot.resolved_format}
        )
        txs.append(tx.model_copy(update={"photometry": phot}))
    return spec.model_copy(update={"transmitters": txs})


def scene_fingerprint(scene: Scene) -> str:
    """Digest of what the kernel reads from a built scene: geometry arrays and device arrays."""
    h = hashlib.sha256()
    g = scene.geometry
    parts = [g.vertices, g.faces, g.reflectance, g.group]
    if g.material is not None:
        parts += [g.material.rho_d, g.material.rho_s, g.material.exponent, g.material.rho_m]
    for dev in (scene.transmitters, scene.receivers):
        parts += [dev.positions, dev.normals, dev.order, dev.cos_fov, dev.gain, dev.power]
        parts += [a for p in dev.patterns if p is not None for a in (p.gamma, p.c, p.intensity)]
    for a in parts:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    h.update(repr(scene.medium_far_distance).encode())
    return h.hexdigest()[:32]


@functools.lru_cache(maxsize=1)
def _code_digest() -> str:
    """Digest of the engine's and the schemas' source: the code that defines the numbers."""
    h = hashlib.sha256()
    root = Path(__file__).resolve().parent.parent
    for package in ("engine", "schemas"):
        for path in sorted((root / package).glob("*.py")):
            h.update(path.name.encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:16]


def _version(dist: str) -> str | None:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return None


def worker_environment() -> dict:
    """What must match between client and workers for bit-identical results (run on each worker)."""
    import pydantic
    import trimesh

    return {
        "owcsim code": _code_digest(),
        "owcsim": _version("owcsim"),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "embreex": _version("embreex"),
        "trimesh": trimesh.__version__,
        "pydantic": pydantic.VERSION,
    }


# --------------------------------------------------------------------------- worker side

#: Scenes built on this worker, per worker thread (a scene's ray counters must not be shared):
#: {thread id: OrderedDict[job key, Scene]}, least recently used dropped beyond SCENE_CACHE_SIZE.
_SCENES: dict[int, OrderedDict[str, Scene]] = {}
_STATS = {"builds": 0}
_LOCK = threading.Lock()


#: glibc malloc on the workers: arrays below 32 MiB come from the heap, and up to 64 MiB of free heap is
#: kept. These are the bounds glibc's own dynamic thresholds reach in a process like the local pool's
#: workers; Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which freezes them at 128 KiB,
#: so every batch-sized temporary is mapped and faulted in afresh (batches of 32768 paths ran 2x slower).
MALLOC_MMAP_THRESHOLD = 32 << 20
MALLOC_TRIM_THRESHOLD = 64 << 20
_TUNED: list[bool] = []


def _tune_malloc() -> None:
    """Once per worker process: restore the heap thresholds a batch's large temporaries need (glibc only)."""
    with _LOCK:
        if _TUNED:
            return
        _TUNED.append(True)
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, MALLOC_MMAP_THRESHOLD)  # M_MMAP_THRESHOLD
        libc.mallopt(-1, MALLOC_TRIM_THRESHOLD)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass


def _scene_spec(spec: SceneSpec) -> SceneSpec:
    """The job's scene-document task: its result stays on the cluster while the job runs."""
    return spec


def _worker_scene(key: str, fingerprint: str, spec: SceneSpec) -> Scene:
    with _LOCK:
        cache = _SCENES.setdefault(threading.get_ident(), OrderedDict())
    scene = cache.get(key)
    if scene is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the client built the same scene and reported its warnings
            scene = build_scene(spec, None)
        got = scene_fingerprint(scene)
        if got != fingerprint:
            raise SceneError(
                f"the Dask worker built a different scene than the client (fingerprint {got} vs "
                f"{fingerprint}): install the same owcsim, numpy, embreex and trimesh on every worker"
            )
        cache[key] = scene
        while len(cache) > SCENE_CACHE_SIZE:
            cache.popitem(last=False)
        with _LOCK:
            _STATS["builds"] += 1
    cache.move_to_end(key)
    return scene


def _run_batch(key: str, fingerprint: str, spec: SceneSpec, item: WorkItem, settings: KernelSettings) -> BatchTally:
    """One task: trace one batch on this worker's cached scene of the job."""
    _tune_malloc()
    return trace_batch(_worker_scene(key, fingerprint, spec), item, settings)


def worker_cache_info() -> dict:
    """Scenes this worker process built since it started, and the job keys it caches (run on a worker)."""
    with _LOCK:
        return {"builds": _STATS["builds"], "cached": sorted({k for c in _SCENES.values() for k in c})}


# --------------------------------------------------------------------------- client side


class DaskExecutor:
    """Runs batches on a Dask cluster; same interface and results as engine.run.execution.ProcessExecutor.

    `client_or_address`: a `distributed.Client` (the caller keeps and closes it) or a
    scheduler address such as "tcp://host:8786" (a client is opened here and closed by
    `close()`). `window`: most tasks of one `map` in flight (default 4 per worker
    thread at start: a result takes ~20 ms to come back through the scheduler, so a
    thread needs more than one queued batch to stay busy). `retries`: extra attempts
    of a task that raised (a task whose worker died is rescheduled by the scheduler
    anyway). `timeout_s`: to connect, for the first worker to join, and the longest
    time a running job waits with no worker before failing.
    """

    #: seconds between checks that the cluster still has workers while waiting for a batch
    poll_s = 2.0

    def __init__(self, client_or_address, *, window: int | None = None, retries: int = 2, timeout_s: float = 30.0):
        distributed = _distributed()
        self._own = isinstance(client_or_address, str)
        if self._own:
            try:
                self._client = distributed.Client(client_or_address, timeout=timeout_s, set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ClusterError(f"cannot connect to the Dask scheduler at {client_or_address}: {exc}") from None
        else:
            self._client = client_or_address
        self.address = self._client.scheduler.address
        self.retries = int(retries)
        self.timeout_s = float(timeout_s)
        self._lock = threading.Lock()
        self._shipped: OrderedDict[int, tuple] = OrderedDict()  # id(scene) -> (weakref, key, fingerprint, future)
        try:
            try:
                self._client.wait_for_workers(1, timeout=timeout_s)
            except TimeoutError:
                raise ClusterError(
                    f"no Dask worker joined the scheduler at {self.address} within {timeout_s:g} s; "
                    f"start some with: dask worker {self.address} --nthreads 1"
                ) from None
            nthreads = self._client.nthreads()
            self._check_workers()
        except BaseException:
            self.close()
            raise
        #: Dask workers when the executor started (the cluster may grow or shrink later)
        self.workers = max(1, len(nthreads))
        #: worker threads when the executor started
        self.threads = max(1, sum(nthreads.values()))
        self.window = int(window) if window else max(4, 4 * self.threads)

    # -- set-up

    def _check_workers(self) -> None:
        """Every worker must run the same engine code; other library versions only warn."""
        try:
            envs = self._client.run(worker_environment)
        except Exception as exc:  # typically ModuleNotFoundError: owcsim is not installed on a worker
            raise ClusterError(
                f"the Dask workers cannot run owcsim ({type(exc).__name__}: {exc}); install the "
                f"same owcsim on every worker: {PIP_INSTALL}"
            ) from None
        mine = worker_environment()
        for worker, env in envs.items():
            diff = {k: (mine[k], env.get(k)) for k in mine if env.get(k) != mine[k]}
            if "owcsim code" in diff:
                raise ClusterError(
                    f"Dask worker {worker} runs different owcsim engine code than this client "
                    f"({diff}); install the same owcsim version on the workers"
                )
            if diff:
                warnings.warn(
                    f"Dask worker {worker} has other library versions than this client {diff}: "
                    "results may differ in the last digits from a local run",
                    RuntimeWarning,
                    stacklevel=3,
                )

    def _ship(self, job: JobRef):
        """(key, fingerprint, future of the scene document) of a job, sent to the cluster once."""
        scene = job.scene
        with self._lock:
            entry = self._shipped.pop(id(scene), None)
            if entry is not None and entry[0]() is scene and entry[3].status in ("pending", "finished"):
                self._shipped[id(scene)] = entry
                return entry[1:]
        if entry is not None:  # failed, cancelled (scheduler restart) or another scene: submit it afresh
            entry[3].release()
        spec = portable_spec(scene.spec, job.base_dir)
        fingerprint = scene_fingerprint(scene)
        key = hashlib.sha256((spec.model_dump_json() + "\0" + fingerprint).encode()).hexdigest()[:24]
        future = self._client.submit(_scene_spec, spec, key=f"owcsim-scene-{key}", retries=self.retries)
        with self._lock:
            self._shipped[id(scene)] = (weakref.ref(scene), key, fingerprint, future)
            while len(self._shipped) > SCENE_CACHE_SIZE:
                self._shipped.popitem(last=False)
        return key, fingerprint, future

    # -- the executor interface

    def map(self, job: JobRef, items: Iterable[WorkItem], settings: KernelSettings) -> Generator[BatchTally]:
        """Tallies of `items`, in item order; at most `window` tasks in flight; closing cancels the rest."""
        key, fingerprint, spec_future = self._ship(job)
        token = uuid.uuid4().hex[:12]
        window: deque = deque()
        try:
            for i, item in enumerate(items):
                window.append(
                    self._client.submit(
                        _run_batch,
                        key,
                        fingerprint,
                        spec_future,
                        item,
                        settings,
                        key=f"owcsim-batch-{token}-{i}",
                        retries=self.retries,
                        fifo_timeout=0,
                    )
                )
                if len(window) >= self.window:
                    yield self._result(window.popleft())
            while window:
                yield self._result(window.popleft())
        finally:
            if window:
                self._cancel(window)

    def _result(self, future):
        """The task's tally; on any error the future is released (tracebacks must not pin it on the cluster)."""
        distributed = _distributed()
        try:
            return self._wait(future)
        except distributed.KilledWorker as exc:
            raise ClusterError(
                f"a batch was running on every worker that died in turn ({exc}); the cluster gave "
                "up on it (distributed.scheduler.allowed-failures)"
            ) from None
        except concurrent.futures.CancelledError as exc:
            raise ClusterError(
                f"the Dask cluster dropped a batch of the job ({exc}); was the scheduler restarted?"
            ) from None
        finally:
            if future.status != "finished":
                self._cancel([future])

    def _wait(self, future):
        alone_since = None
        while True:
            try:
                return future.result(timeout=self.poll_s)
            except TimeoutError:
                if future.done():  # the task itself raised TimeoutError
                    raise
            if self._n_workers() > 0:
                alone_since = None
                continue
            alone_since = alone_since or time.monotonic()
            if time.monotonic() - alone_since > self.timeout_s:
                raise ClusterError(
                    f"the Dask cluster at {self.address} has had no worker for {self.timeout_s:g} s; the job stops"
                ) from None

    def _n_workers(self) -> int:
        try:
            return len(self._client.nthreads())
        except Exception:
            return 0

    def _cancel(self, futures) -> None:
        try:
            self._client.cancel(list(futures))
        except Exception:  # the client may be closing; the scheduler forgets released tasks anyway
            pass

    def close(self) -> None:
        """Release the scenes held on the cluster; close the client if this executor opened it."""
        with self._lock:
            futures = [entry[3] for entry in self._shipped.values()]
            self._shipped.clear()
        for future in futures:  # dropped, not cancelled: another client may hold the same job's scene
            future.release()
        if self._own:
            self._client.close()

    def __enter__(self) -> "DaskExecutor":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def executor_from_scheduler(address: str, **kwargs) -> DaskExecutor:
    """A DaskExecutor on the scheduler at `address` (e.g. "tcp://host:8786"); close it when done."""
    return DaskExecutor(address, **kwargs)
