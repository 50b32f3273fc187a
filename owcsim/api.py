"""The in-process Python API: `owcsim.simulate(scene) -> Result`.

`scene` is a scene document as a dict, a path to a JSON file, or a `SceneSpec`; the result is
the same `Result` type the HTTP client returns (owcsim.clients.result): the engine's typed
result (schemas.results.SimulationResultPublic) with numpy arrays, tables, maps and plots.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from owcsim.clients.result import Result
from owcsim.schemas import SceneSpec

from .docs import InputError, format_validation_error, load_scene

if TYPE_CHECKING:
    from owcsim.engine.run.simulate import Progress


def load(scene: dict | str | Path | SceneSpec) -> tuple[SceneSpec, Path | None]:
    """(validated scene, folder that relative mesh paths are read from)."""
    if isinstance(scene, SceneSpec):
        return scene, None
    if isinstance(scene, (str, Path)):
        spec, _ = load_scene(scene)
        return spec, Path(scene).resolve().parent
    if isinstance(scene, dict):
        from pydantic import ValidationError

        try:
            return SceneSpec.model_validate(scene), None
        except ValidationError as err:
            raise InputError(format_validation_error(err)) from None
    raise TypeError(f"a scene is a dict, a JSON file path or a SceneSpec, not {type(scene).__name__}")


def simulate(
    scene: dict | str | Path | SceneSpec,
    *,
    workers: int = 1,
    base_dir: str | Path | None = None,
    progress: Callable[[Progress], None] | None = None,
) -> Result:
    """Simulate a scene in this process and return its Result (see the module docstring).

    `workers` > 1 runs batches in that many processes (same result bits); `progress(p)` is called
    after batches with an `owcsim.engine.run.simulate.Progress` (p.fraction, p.paths, p.batches,
    p.dc_gain_rel_stderr, p.elapsed_s); `base_dir` resolves relative mesh paths (default: the scene
    file's folder). Raises InputError for an invalid scene and owcsim.engine.core.errors.EngineError for
    one the engine refuses.
    """
    from owcsim.engine.run.simulate import simulate as run

    spec, folder = load(scene)
    where = base_dir if base_dir is not None else folder
    if spec.timeline is not None:  # the channel over time (engine/run/timeline.py): `result.timeline`
        from owcsim.engine.run.timeline import run_timeline

        return Result.of(run_timeline(spec, base_dir=where, workers=workers, progress=progress))
    result = run(spec, base_dir=where, workers=workers, progress=progress)
    return Result.of(result)
