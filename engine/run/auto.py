"""Model only what the scene requires: the algorithm, K, S and the time window from the accuracy asked.

`plan(spec, scene)` and `finish(step, pilot_result)` (this module) turn "auto" settings into explicit ones
and say why (the `modeled` section of the result); the job runner (engine/run/simulate.py) runs
the pilot `plan` asks for between the two, on the job's built scene. Rules (explicit settings always win):
- algorithm: no medium or sigma_t = 0 everywhere -> vacuum paths (algorithm 1, no
  medium); sigma_s = 0 -> algorithm 1 (exact for a purely absorbing medium);
  scattering -> algorithm 5, the only one that covers every family. In
  benchmarks/smoke_accuracy.py it also reaches a given error of H0 faster than the
  single-scattering algorithms 2-4, which miss the multiply scattered light (half of H0
  in the smoke room there), so no scene needs them to be cheapest.
- K, S, window: a pilot (`pilot_paths` paths, K and S up to PILOT_CAP, a long window)
  measures the gain of every reflection and scattering order and the arrival times.
  K is the smallest order whose tail (pilot orders beyond it, plus a geometric tail
  past the pilot with ratio rho_max, plus two pilot standard errors) stays under half
  the allowed truncated power; S likewise with ratio albedo_max; the window ends where
  the power arriving later is under the other half. Allowed truncated power:
  `truncation_tolerance` x H0 (default 0.1 x target_rel_error, or 1e-4). When the power past
  the pilot's cap is over that, K (S) goes on past the pilot along the geometric tail, up to
  MAX_ORDER (bright rooms; roulette keeps the cost per path), the CIR is then not split by
  order, and the window holds those orders within the pilot's window; a tail that stays over
  the allowance sets `truncation_within_allowance` false and the result warns.
The pilot itself is built in engine/run/pilot.py, the order and window mathematics are in
engine/run/tail.py and the geometric tail in engine/results/truncation.py (the result reports it
too). Whether the medium scatters and its largest albedo are decided once, when the scene is built
(scene.medium_model, engine/media/model.py), from the document's medium.
The geometric tail is an estimate, not a proof: it assumes that past the last measured
order each reflection (scattering) keeps at most rho_max (albedo_max) of the power,
which holds for the diffuse field of a closed room; the result says so.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.core.errors import SceneError
from owcsim.engine.run.pilot import PILOT_BINS, PILOT_CAP, PilotRun, pilot_run
from owcsim.engine.run.receivers import extreme_receivers
from owcsim.engine.run.tail import OrderChoice, OrderKind, choose_order, window_end
from owcsim.engine.scene.scene import Scene
from owcsim.schemas import SceneSpec
from owcsim.schemas.algorithms import Algorithm, algorithm
from owcsim.schemas.results import ModeledPublic, PilotPublic, SimulationResultPublic
from owcsim.schemas.simulation import check_bin_budget


def choose_algorithm(spec: SceneSpec, scene: Scene) -> tuple[int, str, bool]:
    """(algorithm, reason, drop_medium) for spec.simulation.algorithm = "auto" on the scene built from `spec`
    (its medium is None when sigma_t = 0; whether it scatters: scene.medium_model)."""
    if spec.medium is None:
        return 1, "no medium: vacuum paths only (algorithm 1)", True
    medium = scene.medium
    if medium is None:
        return 1, "sigma_t = 0: vacuum paths only (algorithm 1)", True
    if medium.bounds is not None and spec.room is not None:
        room_lo, room_hi = np.asarray(spec.room.lo), np.asarray(spec.room.hi)
        lo, hi = (np.asarray(b, float) for b in medium.bounds)
        if np.any(hi <= room_lo) or np.any(lo >= room_hi):
            return 1, "the medium's region lies outside the room: no path can enter it; vacuum paths only", True
    if not scene.scatters:
        return 1, "sigma_s = 0: no scattering; algorithm 1 (extinction only) is exact", False
    return (
        5,
        (
            "scattering medium: algorithm 5 covers every family and was measured faster per accuracy than "
            "algorithms 2-4 (benchmarks/smoke_accuracy.py)"
        ),
        False,
    )


@dataclass(frozen=True)
class Resolution:
    """The job's settings so far: `spec` (explicit where decided), the `scene` it runs on, the `modeled`
    section explaining them, the `update`s still to apply after the `pilot` (None: no pilot needed)."""

    original: SceneSpec
    spec: SceneSpec
    scene: Scene
    modeled: ModeledPublic
    pilot: PilotRun | None = None
    update: dict[str, Any] = field(default_factory=dict)
    doc_update: dict[str, Any] = field(default_factory=dict)


def _apply(
    spec: SceneSpec, scene: Scene, update: dict[str, Any], doc_update: dict[str, Any]
) -> tuple[SceneSpec, Scene]:
    """The scene document with the chosen settings, and its scene (the built one, its medium dropped when the
    algorithm runs without it); the budgets that need K, S and the window are checked here."""
    resolved = spec.model_copy(update={**doc_update, "simulation": spec.simulation.model_copy(update=update)})
    sim = resolved.simulation
    if sim.is_resolved:  # what validating the document would check of the chosen settings (not re-validated:
        try:  # a large inline mesh would be parsed again)
            if sim.t_max_s is not None and "t_max_s" in update:
                check_bin_budget(sim.t_min_s, sim.t_max_s, sim.time_bin_s, automatic=True)
            resolved.check_tally_budget()
        except ValueError as exc:
            raise SceneError(f"the scene with its automatic settings: {exc}") from None
    if "medium" in doc_update and scene.medium is not None:
        return resolved, dataclasses.replace(
            scene, spec=resolved, medium=None, phase=None, medium_far_distance=math.inf, medium_model=None
        )
    if "medium" in doc_update:  # sigma_t = 0: no medium was built; the document's is dropped too
        return resolved, dataclasses.replace(scene, spec=resolved, medium_model=None)
    return resolved, dataclasses.replace(scene, spec=resolved)


def _choose_algorithm(spec: SceneSpec, scene: Scene, modeled: ModeledPublic, update: dict, doc_update: dict) -> int:
    """The algorithm's number: the requested one, or the automatic choice (recorded in `update`, the medium
    dropped through `doc_update` when it cannot touch any path); its reason in `modeled`."""
    sim = spec.simulation
    if sim.algorithm != "auto":
        modeled.algorithm_reason = f"algorithm {sim.algorithm} requested"
        return sim.algorithm
    number, why, drop_medium = choose_algorithm(spec, scene)
    update["algorithm"] = number
    modeled.algorithm_reason = why
    if drop_medium and spec.medium is not None:
        doc_update["medium"] = None
    return number


def _line_of_sight_window(spec: SceneSpec) -> float:
    """End of the window of a line-of-sight-only job [s]: after the longest direct path, whole bins from t_min."""
    sim = spec.simulation
    longest = max(math.dist(t.position, r.position) for t in spec.transmitters for r in extreme_receivers(spec))
    n_bins = max(1, math.ceil((longest / SPEED_OF_LIGHT - sim.t_min_s) / sim.time_bin_s + 1e-9) + 1)
    return sim.t_min_s + n_bins * sim.time_bin_s


def plan(spec: SceneSpec, scene: Scene) -> Resolution:
    """First step of the resolution: the algorithm, and the settings known without a pilot; the pilot to run if
    K, S or the window are automatic (`finish` reads its result)."""
    sim = spec.simulation
    modeled = ModeledPublic(rules="engine/run/auto.py")
    update: dict[str, Any] = {}
    doc_update: dict[str, Any] = {}
    alg = algorithm(_choose_algorithm(spec, scene, modeled, update, doc_update))
    if alg.scattering_orders is not None:  # S fixed by the algorithm, or 4's 1 or 2 (schemas/algorithms.py)
        update["max_scattering"] = alg.S(sim.max_scattering)
    need_k = sim.max_reflections is None
    need_s = alg.scattering_orders is None and sim.max_scattering is None
    if need_s and scene.medium is None:  # algorithm 5 in clear air (or sigma_t = 0): a surface path tracer
        update["max_scattering"] = 1  # the field's least; no path scatters, so S changes nothing
        modeled.max_scattering_reason = "no medium (or sigma_t = 0): no path scatters; S has no effect"
        need_s = False
    need_t = sim.t_max_s is None
    if need_t and not need_k and not alg.counts_scattering and sim.max_reflections == 0:
        # Line of sight only: every arrival is a direct path, known without a pilot.
        update["t_max_s"] = _line_of_sight_window(spec)
        modeled.time_window_reason = "line of sight only: the window ends after the longest direct path"
        need_t = False
    resolved, job_scene = _apply(spec, scene, update, doc_update)
    if not (need_k or need_s or need_t):
        return Resolution(spec, resolved, job_scene, modeled)
    pilot = pilot_run(resolved, scene, job_scene, need_k, need_s)
    return Resolution(spec, resolved, job_scene, modeled, pilot, update, doc_update)


def _time_window(
    spec: SceneSpec, pilot: SimulationResultPublic, run: PilotRun, allowed: float, ends: list[float]
) -> tuple[float, str]:
    """(t_max_s [s], its reason): where the power arriving later is under half the allowance, and holding the
    orders chosen past the pilot (`ends`) within the pilot's window."""
    sim = spec.simulation
    dt = sim.time_bin_s
    bins = pilot.time_bins
    edges = np.asarray(bins.t_min_s + bins.time_bin_s * np.arange(PILOT_BINS + 1), np.float64)  # [s]
    t_end = max(window_end(edges, lk, allowed / 2) for lk in pilot.links)
    # the orders chosen past the pilot, within the pilot's window: the memory estimate of a job with an
    # automatic window (engine/run/budget.py) takes that window as its bound; later power is in late_gain
    past_pilot = max(ends, default=0.0)
    held = min(past_pilot, run.t_long)
    t_end = max(t_end, held, sim.t_min_s + dt)
    try:
        check_bin_budget(sim.t_min_s, t_end, dt, automatic=True)
    except ValueError as exc:
        raise SceneError(f"simulation: {exc}") from None
    n_bins = max(1, math.ceil((t_end - sim.t_min_s) / dt - 1e-9))
    t_max = sim.t_min_s + n_bins * dt
    reason = (
        f"window ends at {t_max * 1e9:.1f} ns: the power arriving later, extrapolated from the "
        f"pilot's exponential decay, is < {allowed / 2:.2e} per watt (late power is counted in late_gain, "
        "not dropped)"
        + (
            "; it holds the orders chosen past the pilot (their mean delays, extrapolated per order, plus 4 "
            "standard deviations)"
            if 0 < past_pilot <= t_end and past_pilot == held
            else (
                f"; the orders chosen past the pilot arrive until about {past_pilot * 1e9:.1f} ns, but the "
                "window stops at the pilot's (the bound of the job's memory estimate, engine/run/budget.py): "
                "their later power is in late_gain and dc_gain, not in the binned CIR; give t_max_s to bin it"
                if past_pilot > t_end
                else ""
            )
        )
    )
    return t_max, reason


def _choose_orders(
    step: Resolution, pilot: SimulationResultPublic, alg: Algorithm, allowed: float, update: dict[str, Any]
) -> tuple[OrderChoice | None, OrderChoice | None]:
    """K and S where automatic (recorded in `update`), from the pilot's order split: (K's choice, S's choice)."""
    spec, scene, run = step.original, step.scene, step.pilot
    assert run is not None
    sim = spec.simulation
    bins = pilot.time_bins
    allowance = allowed / 2  # half the allowance to K, half to S (like the power and the delay shifts)
    rel = sim.tolerance / 2
    t_mid = np.asarray(bins.t_min_s + bins.time_bin_s * (np.arange(PILOT_BINS) + 0.5), np.float64)  # [s]
    enclosed = len(scene.geometry.faces) > 0
    k = s = None
    if sim.max_reflections is None:
        rho_max = scene.max_reflectance
        k = choose_order(
            OrderKind.REFLECTION,
            pilot.links,
            rho_max,
            run.cap_k,
            allowed=allowance,
            rel=rel,
            t_mid=t_mid,
            enclosed=enclosed,
        )
        update["max_reflections"] = k.order
    if alg.scattering_orders is None and sim.max_scattering is None and "max_scattering" not in update:
        s = choose_order(
            OrderKind.SCATTERING,
            pilot.links,
            scene.max_albedo,
            run.cap_s,
            allowed=allowance,
            rel=rel,
            t_mid=t_mid,
            enclosed=enclosed,
            extra=1,
        )
        update["max_scattering"] = s.order
    return k, s


def finish(step: Resolution, pilot: SimulationResultPublic) -> Resolution:
    """Second step of the resolution: K, S and the window from the truncation pilot's result."""
    spec, scene, run = step.original, step.scene, step.pilot
    assert run is not None
    sim = spec.simulation
    modeled, update = step.modeled.model_copy(), dict(step.update)
    alg = algorithm(update.get("algorithm", sim.algorithm))
    need_t = "t_max_s" not in update and sim.t_max_s is None
    h0 = max(max(link.dc_gain or 0.0 for link in pilot.links), 1e-300)
    gains = [link.dc_gain for link in pilot.links if link.dc_gain]
    allowed = sim.tolerance * min(gains) if gains else sim.tolerance * h0
    k, s = _choose_orders(step, pilot, alg, allowed, update)
    chosen = [c for c in (k, s) if c is not None]
    if k is not None:
        modeled.max_reflections_reason = k.reason
    if s is not None:
        modeled.max_scattering_reason = s.reason
    doc_update = dict(step.doc_update)
    if max(update.get("max_reflections", 0), update.get("max_scattering", 0)) > PILOT_CAP and (
        spec.outputs.cir_by_order is None
    ):  # hundreds of orders x a long window: the CIR split by order would hold 1e7+ numbers per link
        doc_update["outputs"] = spec.outputs.model_copy(update={"cir_by_order": False})
        modeled.outputs_reason = (
            "the CIR is not split by order (outputs.cir_by_order false): the orders chosen past the pilot's "
            f"{PILOT_CAP} would make it orders x bins numbers per link; H0 is still split by order"
        )
    if need_t:
        ends = [end for c in chosen for end in c.window_ends]
        update["t_max_s"], modeled.time_window_reason = _time_window(spec, pilot, run, allowed, ends)
    modeled.pilot = PilotPublic(
        paths=sim.pilot_paths,
        receivers=[scene.receivers.ids[i] for i in run.receivers],
        max_reflections=run.cap_k,
        max_scattering=run.cap_s,
        t_max_s=run.t_long,
        allowed_truncation_per_watt=float(allowed),
        rho_max=scene.max_reflectance,
    )
    total_tail = float((k.tail if k is not None else 0.0) + (s.tail if s is not None else 0.0))
    modeled.truncation_estimate_per_watt = total_tail if math.isfinite(total_tail) else None
    modeled.truncation_within_allowance = all(c.within for c in chosen) if chosen else None
    modeled.truncation_note = (
        "estimated from the pilot: the orders it measured plus a geometric tail past its "
        "last order (" + "; ".join(c.note for c in chosen) + "), plus two of its standard errors"
        if chosen
        else "no order was chosen automatically"
    )
    resolved, job_scene = _apply(spec, scene, update, doc_update)
    return Resolution(spec, resolved, job_scene, modeled)
