"""Engine pre-flight of a submitted scene, so that what the engine cannot run is refused at once.

The pre-flight of a scene that can be large (meshes given as file content, more than
SMALL_RECEIVERS receivers or SMALL_TRIANGLES inline triangles) runs in its own short-lived
process (from the forkserver the dispatcher uses, engine imported already), never in the
server: its address space is capped (`preflight_memory_bytes`), it is killed past
`preflight_timeout_s`, and at most `preflight_concurrency` run at once. A small scene (a
room, boxes, a few devices: milliseconds and kilobytes) is pre-flighted in the calling
thread, which saves the process start. The steps:

1. meshes given as file content are decoded and their triangles counted from the file's
   structure (triangles of each geometry x the nodes instancing it) before anything is
   flattened: a small file that instances a large mesh thousands of times is refused
   against `max_triangles` in milliseconds;
2. the scene is built, once (geometry on Embree: an unreadable base64 mesh fails here) and the
   engine runs its own entry point on that scene with the smallest possible settings (one path,
   line of sight only, one time bin, explicit orders so no pilot runs, stopped after the first
   batch). Whatever the engine
   refuses (a SceneError: an input it cannot simulate) becomes a 422 problem
   with the engine's message, instead of a job that fails after waiting in the queue;
3. the job's memory estimate (engine.run.budget) is made with the scene's triangles and extent.
"""

from __future__ import annotations

import multiprocessing as mp
import threading
from dataclasses import dataclass

from owcsim.schemas import SceneSpec, SimulationSpec
from owcsim.schemas.algorithms import algorithm
from owcsim.schemas.errors import ProblemField

from .prescan import child_keys, number_lists, required_keys, vocabulary
from .problems import ProblemError

vocabulary()  # the pre-scan's field names, made once: the forkserver imports this module, its children inherit them
child_keys(), number_lists(), required_keys()

#: A scene with at most this many receivers (grids expanded), no file-content meshes and at most
#: SMALL_TRIANGLES inline triangles is pre-flighted in the server's thread, not in a process.
SMALL_RECEIVERS = 1000
SMALL_TRIANGLES = 10_000


def is_small(spec: SceneSpec) -> bool:
    receivers = len(spec.receivers) + spec.grid_receiver_count()  # with orientation samples and photodiodes
    triangles = sum(len(m.faces or ()) for m in spec.meshes)
    return (
        receivers <= SMALL_RECEIVERS
        and len(spec.transmitters) <= SMALL_RECEIVERS
        and triangles <= SMALL_TRIANGLES
        and all(m.vertices is not None for m in spec.meshes)
        and spec.medium is None
    )  # (a grid medium may be large)


@dataclass(frozen=True)
class Preflight:
    triangles: int
    memory_bytes: int  # the job's memory estimate [B]


def _problem(kind: str, loc: str, msg: str, type_: str, status: int = 422) -> tuple:
    return ("problem", status, kind, msg, [(loc, msg, type_)])


def _run(spec: SceneSpec, max_triangles: int, workers: int) -> tuple:
    """The pre-flight itself (in the pre-flight process): ("ok", triangles, memory) or ("problem", ...)."""
    import numpy as np

    from owcsim.engine.core.errors import EngineError
    from owcsim.engine.run.budget import job_memory_bytes
    from owcsim.engine.run.simulate import simulate
    from owcsim.engine.scene.geometry import _load_mesh
    from owcsim.engine.scene.scene import build_scene

    try:
        counted = (12 if spec.room else 0) + 12 * len(spec.furniture)
        for i, mesh in enumerate(spec.meshes):
            counted += _load_mesh(i, mesh, None, count_only=True)
            if counted > max_triangles:
                return _problem(
                    "limit-exceeded",
                    f"body.meshes.{i}",
                    f"the scene has at least {counted:,d} triangles (meshes counted with every instance "
                    f"of their nodes); this server accepts at most {max_triangles:,d} (setting "
                    "max_triangles)",
                    "limit_exceeded",
                )
        sim = spec.simulation
        tiny = sim.model_copy(
            update={
                "max_reflections": 0,
                "t_min_s": 0.0,
                "t_max_s": sim.time_bin_s,
                "paths": 1,
                "target_rel_error": None,
                "batch_size": 64,
                "direction": "forward",
                "pilot_paths": 256,
                # an algorithm whose default S is above 1 (4: the double-scattering family) keeps it: that runs too
                "max_scattering": sim.max_scattering if sim.max_scattering is not None or _s_above_1(sim) else 1,
            }
        )  # every setting explicit but the algorithm: no pilot
        scene = build_scene(spec, None)
        simulate(spec.model_copy(update={"simulation": tiny}), scene=scene, should_stop=lambda: True)
    except EngineError as exc:  # located at a field when the engine knows it (a photometric file's `loc`)
        field = getattr(exc, "loc", None)
        loc = f"body.{field}" if field else "body"
        return _problem("scene-not-runnable", loc, f"the engine cannot run this scene: {exc}", "engine_error")
    except ArithmeticError as exc:  # e.g. a half-power angle so small that cos() rounds to 1
        msg = f"a number is out of the range the simulator can compute with ({type(exc).__name__}: {exc})"
        return _problem("scene-not-runnable", "body", f"the engine cannot run this scene: {msg}", "value_error")
    triangles = len(scene.geometry.faces)
    points = [scene.geometry.vertices, scene.transmitters.positions, scene.receivers.positions]
    extent = float(np.ptp(np.concatenate(points), axis=0).max())
    cells = sum(p.intensity.size for p in scene.transmitters.patterns if p is not None)
    memory = job_memory_bytes(spec, triangles=triangles, extent_m=extent, workers=workers, photometry_cells=cells)
    return ("ok", triangles, memory)


def _child(conn, memory_bytes: int, what: str, fn, *args) -> None:
    """Entry point of the pre-flight process: cap the address space, run `fn(*args)` (a tuple), send it."""
    import warnings

    from .worker import cap_address_space

    cap_address_space(memory_bytes, 0)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the job's run records them
            out = fn(*args)
    except MemoryError:
        out = _problem(
            "limit-exceeded",
            "body",
            f"{what} needs more than this server's {memory_bytes / 2**30:.3g} GB (setting "
            "preflight_memory_bytes): a smaller mesh, photometric table or medium grid, or fewer receivers",
            "limit_exceeded",
        )
    conn.send(out)
    conn.close()


def _preflight_json(scene_json: str, max_triangles: int, workers: int) -> tuple:
    return _run(SceneSpec.model_validate_json(scene_json), max_triangles, workers)


class Preflighter:
    """Runs pre-flights in their own processes, at most `concurrency` at once."""

    def __init__(self, *, concurrency: int, timeout_s: float, memory_bytes: int, max_triangles: int, workers: int):
        self._slots = threading.BoundedSemaphore(concurrency)
        self.timeout_s, self.memory_bytes = timeout_s, memory_bytes
        self.max_triangles, self.workers = max_triangles, workers
        self._ctx = mp.get_context("forkserver")

    def __call__(self, spec: SceneSpec, scene_json: str) -> Preflight:
        """Blocking (call it from a worker thread); raises ProblemError with the refusal."""
        if is_small(spec):
            return self.inline(spec, scene_json)
        out = self.in_process(
            "the pre-flight of this scene", _preflight_json, scene_json, self.max_triangles, self.workers
        )
        return Preflight(triangles=out[1], memory_bytes=out[2])

    def inline(self, spec: SceneSpec, scene_json: str = "") -> Preflight:
        """The pre-flight in the calling process (small scenes; and inside the pre-flight process itself)."""
        out = _run(spec, self.max_triangles, self.workers)
        if out[0] != "ok":
            raise _error(out)
        return Preflight(triangles=out[1], memory_bytes=out[2])

    def in_process(self, what: str, fn, *args) -> tuple:
        """`fn(*args)` (a module-level function returning ("ok", ...) or a problem tuple) in a pre-flight
        process: capped memory, killed past the timeout, at most `concurrency` at once. Blocking; returns
        the "ok" tuple, raises ProblemError with the refusal."""
        out: tuple | None
        with self._slots:
            receive, send = self._ctx.Pipe(duplex=False)
            proc = self._ctx.Process(
                target=_child,
                name="owcsim-preflight",
                daemon=True,
                args=(send, self.memory_bytes, what, fn, *args),
            )
            proc.start()
            send.close()
            try:
                out = receive.recv() if receive.poll(self.timeout_s) else None
            except EOFError:  # it died without an answer (e.g. killed at its memory limit by the kernel)
                out = ()
            finally:
                receive.close()
                if proc.is_alive():
                    proc.kill()
                proc.join()
                proc.close()
        if out is None:
            raise _error(
                _problem(
                    "limit-exceeded",
                    "body",
                    f"{what} took longer than this server's {self.timeout_s:g} s (setting preflight_timeout_s)",
                    "limit_exceeded",
                )
            )
        if not out:
            raise _error(
                _problem(
                    "limit-exceeded",
                    "body",
                    f"{what} ended without an answer "
                    f"(more memory than this server's {self.memory_bytes / 2**30:.3g} GB for it?)",
                    "limit_exceeded",
                )
            )
        if out[0] != "ok":
            raise _error(out)
        return out


def _error(out: tuple) -> ProblemError:
    """A problem tuple ("problem", status, kind, detail, [(loc, msg, type)], {extensions}?) as a ProblemError."""
    _, status, kind, detail, errors, *extensions = out
    fields = [ProblemField(loc=loc, msg=msg, type=t) for loc, msg, t in errors]
    return ProblemError(status, kind, detail, errors=fields, **(extensions[0] if extensions else {}))


def as_tuple(exc: ProblemError) -> tuple:
    """A ProblemError as the picklable tuple a pre-flight process sends back (`_error` undoes it)."""
    return ("problem", exc.status, exc.kind, exc.detail, [(e.loc, e.msg, e.type) for e in exc.errors], exc.extensions)


def preflight(spec: SceneSpec) -> int:
    """In-process pre-flight (tools and tests); returns the scene's triangles. Raises ProblemError (422)."""
    out = _run(spec, 2**62, 1)
    if out[0] != "ok":
        raise _error(out)
    return out[1]


def _s_above_1(sim: SimulationSpec) -> bool:
    """The requested algorithm fixes a scattering order above 1 by default (the registry's `scattering_orders`)."""
    return sim.algorithm != "auto" and (algorithm(sim.algorithm).scattering_orders or 0) > 1
