"""Engine pre-flight of a submitted scene, so that what the engine cannot run is refused at once.

The scene is built (geometry on Embree: an unreadable base64 mesh fails here) and the
engine runs its own entry point on it with the smallest possible settings (one path,
line of sight only, one time bin, stopped after the first batch). Whatever the engine
refuses (SceneError, UnsupportedError, an algorithm it lacks) becomes a 422 problem
with the engine's message, instead of a job that fails after waiting in the queue.
"""
from __future__ import annotations

from owcsim.schemas import SceneSpec
from owcsim.schemas.errors import ProblemField

from .problems import ProblemError


def preflight(spec: SceneSpec) -> int:
    """Build and dry-run the scene; returns its number of triangles. Raises ProblemError (422)."""
    from owcsim.engine.errors import EngineError
    from owcsim.engine.scene import build_scene
    from owcsim.engine.simulate import simulate

    sim = spec.simulation
    tiny = sim.model_copy(update={
        "max_reflections": 0, "t_min_s": 0.0, "t_max_s": sim.time_bin_s, "paths": 1, "target_rel_error": None,
        "batch_size": 64, "direction": "forward", "pilot_paths": 256})
    try:
        scene = build_scene(spec, None)
        simulate(spec.model_copy(update={"simulation": tiny}), scene=scene, should_stop=lambda: True)
    except EngineError as exc:
        raise ProblemError(422, "scene-not-runnable", f"the engine cannot run this scene: {exc}",
                           errors=[ProblemField(loc="body", msg=str(exc), type="engine_error")]) from None
    except ArithmeticError as exc:  # e.g. a half-power angle so small that cos() rounds to 1
        msg = f"a number is out of the range the simulator can compute with ({type(exc).__name__}: {exc})"
        raise ProblemError(422, "scene-not-runnable", f"the engine cannot run this scene: {msg}",
                           errors=[ProblemField(loc="body", msg=msg, type="value_error")]) from None
    return len(scene.geometry.faces)
