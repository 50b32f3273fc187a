"""Model only what the scene requires: the algorithm, K, S and the time window from the accuracy asked.

`resolve(spec)` turns "auto" settings into explicit ones and says why (the `modeled`
section of the result). Rules (explicit settings always win):
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
  `truncation_tolerance` x H0 (default 0.1 x target_rel_error, or 1e-4).
The geometric tail is an estimate, not a proof: it assumes that past the last measured
order each reflection (scattering) keeps at most rho_max (albedo_max) of the power,
which holds for the diffuse field of a closed room; the result says so.
"""
from __future__ import annotations

import math

import numpy as np

from pydantic import ValidationError

from owcsim.schemas import SceneSpec
from owcsim.schemas.errors import located
from owcsim.schemas.simulation import check_bin_budget

from .constants import SPEED_OF_LIGHT
from .errors import SceneError
from .media import medium_from_spec

#: Highest orders the truncation pilot measures.
PILOT_CAP = 40
#: Most receivers the truncation pilot traces (evenly chosen; every link runs in the main job).
PILOT_RECEIVERS = 8
#: Bins of the pilot's time window.
PILOT_BINS = 400


def choose_algorithm(spec: SceneSpec, scene_bounds=None) -> tuple[int, str, bool]:
    """(algorithm, reason, drop_medium) for spec.simulation.algorithm = "auto"."""
    med = spec.medium
    if med is None:
        return 1, "no medium: vacuum paths only (algorithm 1)", True
    engine_medium = medium_from_spec(med)
    if engine_medium is None:
        return 1, "sigma_t = 0: vacuum paths only (algorithm 1)", True
    bounds = getattr(engine_medium, "bounds", None)
    if bounds is not None and scene_bounds is not None and spec.room is not None:
        lo, hi = (np.asarray(b, float) for b in bounds)
        if np.any(hi <= scene_bounds[0]) or np.any(lo >= scene_bounds[1]):
            return 1, "the medium's region lies outside the room: no path can enter it; vacuum paths only", True
    if not _scatters(med):
        return 1, "sigma_s = 0: no scattering; algorithm 1 (extinction only) is exact", False
    return 5, ("scattering medium: algorithm 5 covers every family and was measured faster per accuracy than "
               "algorithms 2-4 (benchmarks/smoke_accuracy.py)"), False


def _scatters(medium) -> bool:
    """True when the medium document scatters anywhere (sigma_s > 0)."""
    if medium is None:
        return False
    if medium.type == "homogeneous":
        return medium.coefficients[1] > 0
    return bool(np.max(np.atleast_1d(medium.sigma_s)) > 0)


def _max_reflectance(spec: SceneSpec, scene) -> float:
    rho = scene.geometry.reflectance
    return float(rho.max()) if len(rho) else 0.0


def _max_albedo(spec: SceneSpec) -> float:
    med = spec.medium
    if med.type == "homogeneous":
        sa, ss = med.coefficients
        return ss / (sa + ss) if sa + ss > 0 else 0.0
    sa = np.broadcast_to(np.atleast_1d(med.sigma_a), np.atleast_1d(med.sigma_s).shape)
    ss = np.atleast_1d(med.sigma_s)
    st = sa + ss
    return float(np.max(np.where(st > 0, ss / np.where(st > 0, st, 1.0), 0.0)))


def _tail_order(gains, errors, ratio: float, allowed: float, cap: int):
    """Smallest order n whose estimated tail is <= allowed (else the cap), and that tail.

    tail(n) = max(sum of the pilot's gains above n, gain(n) ratio / (1 - ratio)) + 2 sigma:
    the measured orders, or the geometric tail from order n when the pilot's paths died out
    before the higher orders could be measured.
    """
    gains = np.asarray(gains, float)
    errors = np.asarray([e or 0.0 for e in errors], float)
    factor = ratio / (1.0 - ratio) if ratio < 1.0 else math.inf
    tail, last = math.inf, None
    for n in range(0, len(gains)):
        if gains[n] > 0:
            last = n
        # an order the pilot's paths did not reach continues the decay of the last one measured
        decayed = gains[last] * ratio ** (n - last) if last is not None else 0.0
        geometric = decayed * factor if decayed > 0 else 0.0
        tail = max(gains[n + 1:].sum(), geometric) + 2.0 * math.sqrt(float((errors[n + 1:] ** 2).sum()))
        if tail <= allowed:
            return n, tail
    return cap, tail


def validated(doc: dict, what: str) -> SceneSpec:
    """The SceneSpec of a document the engine derived (`what` names it); its problems as one SceneError."""
    try:
        return SceneSpec.model_validate(doc)
    except ValidationError as err:
        problems = "; ".join(f"{loc or '(document)'}: {msg}" for loc, msg in located(err.errors()))
        raise SceneError(f"{what}: {problems}") from None


def resolve(spec: SceneSpec, scene_builder, simulate_fn) -> tuple[SceneSpec, dict]:
    """Explicit settings for every "auto" one, and the `modeled` section explaining them."""
    sim = spec.simulation
    modeled: dict = {"rules": "engine/auto.py", "left_out": []}
    update: dict = {}
    doc_update: dict = {}
    if sim.algorithm == "auto":
        room_bounds = (np.asarray(spec.room.lo), np.asarray(spec.room.hi)) if spec.room is not None else None
        algorithm, why, drop_medium = choose_algorithm(spec, room_bounds)
        update["algorithm"] = algorithm
        modeled["algorithm_reason"] = why
        if drop_medium and spec.medium is not None:
            doc_update["medium"] = None
    else:
        algorithm = sim.algorithm
        modeled["algorithm_reason"] = f"algorithm {algorithm} requested"
    if algorithm != 5:
        update["max_scattering"] = {1: 1, 2: 1, 3: 1, 4: 2}[algorithm]  # S is fixed by the algorithm (4: s <= 2)
    need_k = sim.max_reflections is None
    need_s = algorithm == 5 and sim.max_scattering is None
    need_t = sim.t_max_s is None
    resolved = spec.model_copy(update={**doc_update, "simulation": sim.model_copy(update=update)})
    if not (need_k or need_s or need_t):
        modeled["pilot"] = None
        return resolved, modeled
    # --- the truncation pilot ---------------------------------------------------------------
    scene = scene_builder(resolved)
    extent = float(np.ptp(np.concatenate([scene.geometry.vertices, scene.transmitters.positions,
                                          scene.receivers.positions]), axis=0).max()) if len(
        scene.geometry.vertices) else 10.0
    cap_k = PILOT_CAP if need_k else resolved.simulation.max_reflections
    cap_s = PILOT_CAP if need_s else resolved.simulation.max_scattering
    t_long = resolved.simulation.t_max_s or (sim.t_min_s + (cap_k + cap_s + 3) * 1.8 * extent / SPEED_OF_LIGHT)
    receivers = resolved.all_receivers()
    pick = sorted(set(np.linspace(0, len(receivers) - 1, min(len(receivers), PILOT_RECEIVERS)).round().astype(int)))
    pilot_doc = resolved.model_dump(mode="python")
    pilot_doc["receivers"] = [receivers[i].model_dump(mode="python") for i in pick]
    pilot_doc["receiver_grids"] = []
    pilot_doc["simulation"].update(
        max_reflections=cap_k, max_scattering=cap_s, t_max_s=t_long, time_bin_s=(t_long - sim.t_min_s) / PILOT_BINS,
        paths=sim.pilot_paths, target_rel_error=None, seed=sim.seed + 1, batch_size=min(sim.batch_size, 4096))
    pilot = simulate_fn(validated(pilot_doc, "the pilot run that chooses the automatic settings"))
    links = pilot["links"]
    h0 = max(max(link["dc_gain"] for link in links), 1e-300)
    allowed = sim.tolerance * min(link["dc_gain"] for link in links if link["dc_gain"] > 0) \
        if any(link["dc_gain"] > 0 for link in links) else sim.tolerance * h0
    rho_max = _max_reflectance(resolved, scene)
    k_tail = s_tail = 0.0
    if need_k:
        ks, k_tails = zip(*(_tail_order(lk["dc_gain_by_reflection_order"], lk["dc_gain_by_reflection_order_stderr"],
                                        rho_max, allowed / 2, cap_k) for lk in links))
        update["max_reflections"] = max(ks)
        k_tail = max(k_tails)
        modeled["max_reflections_reason"] = (
            f"reflection order capped at {max(ks)}: estimated power of higher orders {k_tail:.2e} per watt "
            f"< {allowed / 2:.2e} (half the allowed truncation)")
    if need_s:
        a_max = _max_albedo(resolved)
        ss, s_tails = zip(*(_tail_order(lk["dc_gain_by_scattering_order"], lk["dc_gain_by_scattering_order_stderr"],
                                        a_max, allowed / 2, cap_s) for lk in links))
        update["max_scattering"] = max(1, max(ss))
        s_tail = max(s_tails)
        modeled["max_scattering_reason"] = (
            f"scattering order capped at {max(1, max(ss))}: estimated power of higher orders {s_tail:.2e} per watt "
            f"< {allowed / 2:.2e}")
    if need_t:
        dt = sim.time_bin_s
        edges = pilot["time_bins"]["t_min_s"] + pilot["time_bins"]["time_bin_s"] * np.arange(PILOT_BINS + 1)
        t_end = max(_window_end(edges, lk, allowed / 2) for lk in links)
        t_end = max(t_end, sim.t_min_s + dt)
        try:
            check_bin_budget(sim.t_min_s, t_end, dt, automatic=True)
        except ValueError as exc:
            raise SceneError(f"simulation: {exc}") from None
        n_bins = max(1, math.ceil((t_end - sim.t_min_s) / dt - 1e-9))
        update["t_max_s"] = sim.t_min_s + n_bins * dt
        modeled["time_window_reason"] = (
            f"window ends at {update['t_max_s'] * 1e9:.1f} ns: the power arriving later, extrapolated from the "
            f"pilot's exponential decay, is < {allowed / 2:.2e} per watt (late power is counted in late_gain, "
            "not dropped)")
    modeled["pilot"] = {"paths": sim.pilot_paths, "receivers": [receivers[i].id or f"rx{i}" for i in pick],
                        "max_reflections": cap_k, "max_scattering": cap_s, "t_max_s": t_long,
                        "allowed_truncation_per_watt": float(allowed), "rho_max": rho_max}
    modeled["truncation_estimate_per_watt"] = float(k_tail + s_tail)
    modeled["truncation_note"] = ("estimated: the tail past the pilot's last order assumes each further reflection "
                                  "(scattering) keeps at most rho_max (albedo_max) of the power")
    resolved = spec.model_copy(update={**doc_update, "simulation": sim.model_copy(update=update)})
    return resolved, modeled


def unreachable_receivers(scene, seen: np.ndarray | None = None, n_rays: int = 64) -> list[int]:
    """Receivers that no light can reach: their whole field of view is blocked at their position.

    A receiver whose front (its position plus one ray offset along its normal) lies inside
    a furniture box or outside the room looks into a solid. Otherwise `n_rays` stratified
    directions over its FOV cone are cast from just off the receiver along each ray (a
    surface it sits on is not an obstacle); if every one hits a surface within 10 ray
    offsets (~1e-5 of the scene's extent), it is flush against that surface. Either way it
    is reported, not simulated. Receivers in `seen` (a transmitter sees them directly: they
    are reachable) are not tested. Receivers enclosed by a user mesh are not detected (its
    orientation is unknown).
    """
    from .sampling import sample_cosine_cone, to_world

    isect, rx = scene.intersector, scene.receivers
    if isect.empty:
        return []
    side = int(math.ceil(math.sqrt(n_rays)))
    u = (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2) + 0.5) / side
    front = rx.positions + isect.offset * rx.normals
    spec = scene.spec
    in_solid = np.zeros(len(rx), bool)
    for box in spec.furniture:  # a loop over boxes, each test vectorized over receivers
        in_solid |= np.all((front > box.min) & (front < box.max), axis=1)
    if spec.room is not None:
        in_solid |= ~np.all((front >= spec.room.lo) & (front <= spec.room.hi), axis=1)
    out = []
    for j in range(len(rx)):  # a loop over devices, each one vectorized call
        if seen is not None and seen[j]:
            continue
        if in_solid[j]:
            out.append(j)
            continue
        dirs = to_world(sample_cosine_cone(rx.cos_fov[j], u[:, 0], u[:, 1]), rx.normals[j])
        prim, t = isect.intersect(front[j] + 2.0 * isect.offset * dirs, dirs)
        if np.all((prim >= 0) & (t <= 10.0 * isect.offset)):
            out.append(j)
    return out


def _window_end(edges, link, allowed: float) -> float:
    """Time after which less than `allowed` power arrives, for one pilot link.

    The pilot measures the power arriving after each time well while it is a sizeable
    fraction of H0, but too few of its paths live long enough to measure the far tail.
    A room's late response decays exponentially (diffuse field), so the tail is
    extrapolated from a fit of log(power after t) over the well-measured range
    (3e-2 .. 1e-3 of H0), aiming at a third of `allowed`.
    """
    after = np.cumsum(np.asarray(link["cir"]["total"])[::-1])[::-1] + link["late_gain"]  # after each left edge
    h0 = link["dc_gain"]
    if h0 <= 0:
        return float(edges[0])
    direct = np.flatnonzero(after <= allowed)
    fit = np.flatnonzero((after <= 0.03 * h0) & (after >= 1e-3 * h0))
    if len(fit) >= 3:
        slope, icept = np.polyfit(edges[fit], np.log(after[fit]), 1)
        if slope < 0:  # aim at a third of the allowance: the decay slows down as the slowest mode takes over
            return float(max(edges[fit[-1]], (np.log(allowed / 3.0) - icept) / slope))
    return float(edges[direct[0]] if len(direct) else edges[-1])
