"""The truncation pilot: a short run that measures every reflection and scattering order and the arrivals.

When K, S or the time window are automatic, engine/run/auto.py asks the job runner for a pilot:
the job's document with up to PILOT_RECEIVERS of its receivers (evenly chosen among those that
run), K and S up to PILOT_CAP, a window long enough for those orders (PILOT_BINS bins), its own
paths (`simulation.pilot_paths`) and seed + 1, the CIR and the order split of every link. It
runs on the job's built scene with those receivers (receivers.with_receivers: nothing rebuilt).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import ValidationError

from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.core.errors import SceneError
from owcsim.engine.run.receivers import with_receivers
from owcsim.engine.scene.scene import Scene
from owcsim.schemas import OutputsSpec, SceneSpec
from owcsim.schemas.errors import located

#: Highest orders the truncation pilot measures.
PILOT_CAP = 40
#: Most receivers the truncation pilot traces (evenly chosen; every link runs in the main job).
PILOT_RECEIVERS = 8
#: Bins of the pilot's time window.
PILOT_BINS = 400


@dataclass(frozen=True)
class PilotRun:
    """The truncation pilot the job runner must run: its document and its scene (the job's scene with the
    chosen receivers: nothing rebuilt), the receivers it traces, the orders it measures up to and the end
    of its window `t_long` [s]."""

    spec: SceneSpec
    scene: Scene
    receivers: list[int]
    cap_k: int
    cap_s: int
    t_long: float


def validated(doc: dict, what: str) -> SceneSpec:
    """The SceneSpec of a document the engine derived (`what` names it); its problems as one SceneError."""
    try:
        return SceneSpec.model_validate(doc)
    except ValidationError as err:
        problems = "; ".join(f"{loc or '(document)'}: {msg}" for loc, msg in located([dict(e) for e in err.errors()]))
        raise SceneError(f"{what}: {problems}") from None


def _extent(scene: Scene) -> float:
    """Largest side [m] of the box around the surfaces and devices (10 m without surfaces)."""
    if not len(scene.geometry.vertices):
        return 10.0
    points = np.concatenate([scene.geometry.vertices, scene.transmitters.positions, scene.receivers.positions])
    return float(np.ptp(points, axis=0).max())


def _pilot_receivers(scene: Scene) -> list[int]:
    """Up to PILOT_RECEIVERS receivers evenly chosen among those that run (grid points in furniture or outside
    the room are not run; all of them when none runs: the document check then says why)."""
    usable = np.flatnonzero(scene.masked == "")
    if not len(usable):
        usable = np.arange(len(scene.receivers))
    return sorted(
        set(usable[np.linspace(0, len(usable) - 1, min(len(usable), PILOT_RECEIVERS)).round().astype(int)].tolist())
    )


def pilot_run(resolved: SceneSpec, scene: Scene, job_scene: Scene, need_k: bool, need_s: bool) -> PilotRun:
    """The pilot of a job whose settings so far are `resolved`: K (S) up to PILOT_CAP where automatic, else the
    job's; a window that holds those orders across the scene (`scene`: the job's built scene; `job_scene`:
    the one it runs on, the pilot's receivers set on it)."""
    sim = resolved.simulation
    cap_k = PILOT_CAP if need_k else sim.max_reflections
    cap_s = PILOT_CAP if need_s else sim.max_scattering
    assert cap_k is not None and cap_s is not None  # explicit where not automatic
    extent = _extent(scene)
    # (S counted as at least 1: algorithm 1's S = 0 keeps the window the rule always gave it)
    t_long = sim.t_max_s or (sim.t_min_s + (cap_k + max(cap_s, 1) + 3) * 1.8 * extent / SPEED_OF_LIGHT)
    pick = _pilot_receivers(scene)
    pilot_spec = resolved.model_copy(
        update={
            "receivers": [resolved.receiver_at(i) for i in pick],
            "receiver_grids": [],
            "transmitter_groups": [],
            "lighting": None,  # its task areas name the grids left out
            "outputs": OutputsSpec(cir=True, orders=True),  # the pilot reads the order split and the CIR
            "simulation": sim.model_copy(
                update=dict(
                    max_reflections=cap_k,
                    max_scattering=cap_s,
                    t_max_s=t_long,
                    time_bin_s=(t_long - sim.t_min_s) / PILOT_BINS,
                    paths=sim.pilot_paths,
                    target_rel_error=None,
                    seed=sim.seed + 1,
                    batch_size=min(sim.batch_size, 4096),
                )
            ),
        }
    )
    if not (scene.masked[pick] == "").all():  # every grid point masked: the document check says why
        pilot_spec = validated(
            pilot_spec.model_dump(mode="python"), "the pilot run that chooses the automatic settings"
        )
    return PilotRun(pilot_spec, with_receivers(job_scene, pilot_spec), pick, cap_k, cap_s, t_long)
