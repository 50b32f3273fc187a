"""Model only what the scene requires: the algorithm, K, S and the time window from the accuracy asked.

`plan(spec, scene)` and `finish(step, pilot_result)` turn "auto" settings into explicit ones
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
The geometric tail is an estimate, not a proof: it assumes that past the last measured
order each reflection (scattering) keeps at most rho_max (albedo_max) of the power,
which holds for the diffuse field of a closed room; the result says so.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from pydantic import ValidationError

from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.core.errors import SceneError
from owcsim.schemas import OutputsSpec, SceneSpec
from owcsim.schemas.algorithms import algorithm
from owcsim.schemas.errors import located
from owcsim.schemas.results import LinkPublic, ModeledPublic, PilotPublic, SimulationResultPublic
from owcsim.schemas.simulation import check_bin_budget

if TYPE_CHECKING:
    from owcsim.engine.scene.scene import Scene

#: Highest orders the truncation pilot measures.
PILOT_CAP = 40
#: Highest order K (S) the automatic choice may take: the schema's limit of `max_reflections` (`max_scattering`).
MAX_ORDER = 1000
#: Most receivers the truncation pilot traces (evenly chosen; every link runs in the main job).
PILOT_RECEIVERS = 8
#: Bins of the pilot's time window.
PILOT_BINS = 400


def choose_algorithm(spec: SceneSpec, engine_medium, scene_bounds=None) -> tuple[int, str, bool]:
    """(algorithm, reason, drop_medium) for spec.simulation.algorithm = "auto"; `engine_medium` is the built
    medium of the scene (media.medium_from_spec(spec.medium): None when sigma_t = 0)."""
    med = spec.medium
    if med is None:
        return 1, "no medium: vacuum paths only (algorithm 1)", True
    if engine_medium is None:
        return 1, "sigma_t = 0: vacuum paths only (algorithm 1)", True
    bounds = getattr(engine_medium, "bounds", None)
    if bounds is not None and scene_bounds is not None and spec.room is not None:
        lo, hi = (np.asarray(b, float) for b in bounds)
        if np.any(hi <= scene_bounds[0]) or np.any(lo >= scene_bounds[1]):
            return 1, "the medium's region lies outside the room: no path can enter it; vacuum paths only", True
    if not _scatters(med):
        return 1, "sigma_s = 0: no scattering; algorithm 1 (extinction only) is exact", False
    return (
        5,
        (
            "scattering medium: algorithm 5 covers every family and was measured faster per accuracy than "
            "algorithms 2-4 (benchmarks/smoke_accuracy.py)"
        ),
        False,
    )


def _scatters(medium) -> bool:
    """True when the medium document scatters anywhere (sigma_s > 0)."""
    if medium is None:
        return False
    if medium.type == "homogeneous":
        return medium.coefficients[1] > 0
    if medium.type == "particles":
        return _particle_coefficients(medium)[1] > 0
    return bool(np.max(np.atleast_1d(medium.sigma_s)) > 0)


def _particle_coefficients(medium) -> tuple[float, float]:
    from owcsim.engine.media.mie import medium_coefficients  # Mie sigma_a, sigma_s of particle smoke (cached)

    return medium_coefficients(medium)


def _max_reflectance(spec: SceneSpec, scene) -> float:
    rho = scene.geometry.reflectance
    return float(rho.max()) if len(rho) else 0.0


def _max_albedo(spec: SceneSpec) -> float:
    med = spec.medium
    if med.type in ("homogeneous", "particles"):
        sa, ss = med.coefficients if med.type == "homogeneous" else _particle_coefficients(med)
        return ss / (sa + ss) if sa + ss > 0 else 0.0
    sa = np.broadcast_to(np.atleast_1d(med.sigma_a), np.atleast_1d(med.sigma_s).shape)
    ss = np.atleast_1d(med.sigma_s)
    st = sa + ss
    return float(np.max(np.where(st > 0, ss / np.where(st > 0, st, 1.0), 0.0)))


def tail_ratio(gains, errors, bound: float, last: int = 8) -> tuple[float, str]:
    """Per-order decay ratio for the geometric tail past the pilot's last measured order, and how it was chosen.

    The pilot's own decay: a weighted least-squares fit of log(gain) against the order
    over its `last` highest orders measured to 30 % (at least 4), ratio = exp(slope +
    2 se(slope)). `bound` (rho_max for reflections, albedo_max for scattering) caps it when
    below 1 (each further order keeps at most that fraction: the diffuse-field
    assumption), and is used alone when too few orders are measured. With bound = 1 (a
    white room, or sigma_a = 0) the fit is the only estimate; infinity (no finite bound
    is stated) when it is not below 1 or too few orders are measured.
    """
    g = np.asarray(gains, float)
    e = np.asarray([x or 0.0 for x in errors], float)
    good = np.flatnonzero((g > 0) & (e <= 0.3 * np.where(g > 0, g, 1.0)))
    good = good[good >= 1][-last:]
    a_priori = (bound, f"at most {bound:.3g} per order (the largest {{what}})")
    if len(good) < 4:
        return (
            a_priori
            if bound < 1.0
            else (math.inf, "unbounded: {what} is 1 and the pilot measured too few orders to fit their decay")
        )
    y = np.log(g[good])
    w = 1.0 / np.maximum(e[good] / g[good], 1e-3) ** 2  # var(log g) ~ (se / g)^2
    x = good.astype(float)
    xm = (w * x).sum() / w.sum()
    slope = (w * (x - xm) * (y - (w * y).sum() / w.sum())).sum() / (w * (x - xm) ** 2).sum()
    se = math.sqrt(1.0 / (w * (x - xm) ** 2).sum())
    r = math.exp(slope + 2.0 * se)
    if bound < 1.0 and r >= bound:
        return a_priori
    if bound < 1.0:
        return r, (
            f"{r:.3g} per order, the upper bound (2 se) of a fit to the pilot's orders {good[0]}-{good[-1]} "
            f"(below {{what}} = {bound:.3g}; an estimate that assumes geometric decay past them)"
        )
    if r >= 1.0:
        return math.inf, (
            f"unbounded: {{what}} is 1 and the pilot's last orders show no decay (fitted ratio "
            f"{math.exp(slope):.3g}, upper bound {r:.3g})"
        )
    return r, (
        f"{r:.3g} per order, the upper bound (2 se) of a fit to the pilot's orders {good[0]}-{good[-1]} "
        f"({{what}} is 1: no a-priori bound; an estimate that assumes geometric decay past them)"
    )


def _order_moments(cir_by_order, t_mid):
    """Per order: (mean delay, mean squared delay) of its binned pilot CIR [s, s^2] (0 where it is empty)."""
    h = np.asarray(cir_by_order, float)
    m0 = h.sum(axis=1)
    safe = np.where(m0 > 0, m0, 1.0)
    return np.where(m0 > 0, h @ t_mid / safe, 0.0), np.where(m0 > 0, h @ (t_mid * t_mid) / safe, 0.0)


def _tail_moments(n, gains, errors, t1, t2, ratio):
    """Power P of the orders above n and its delay moments P t, P t^2 [per watt, s, s^2].

    The pilot's orders up to its last well-measured one L (relative error <= 30 %) count as
    measured; past L (or past n, if later) the tail is geometric with the per-order `ratio`
    from g_L, keeping the mean delay step dt = t1[L] - t1[L-1] per order and the spread of
    order L; the pilot's own noisy values past L count instead where they are larger;
    two pilot standard errors of the orders above n are added.
    """
    gains = np.asarray(gains, float)
    errors = np.asarray([e or 0.0 for e in errors], float)
    good = np.flatnonzero((gains > 0) & (errors <= 0.3 * np.where(gains > 0, gains, 1.0)))
    if not len(good):
        p = gains[n + 1 :].sum()
        noise = 2.0 * math.sqrt(float((errors[n + 1 :] ** 2).sum()))
        return (0.0, 0.0, 0.0) if p + noise == 0 else (math.inf, math.inf, math.inf)
    L = int(good[-1])
    upto = slice(n + 1, L + 1)
    p = gains[upto].sum()
    p1 = (gains[upto] * t1[upto]).sum()
    p2 = (gains[upto] * t2[upto]).sum()
    start = max(L, n)
    beyond = slice(start + 1, None)
    measured_beyond = (gains[beyond].sum(), (gains[beyond] * t1[beyond]).sum(), (gains[beyond] * t2[beyond]).sum())
    if gains[L] > 0:
        if not math.isfinite(ratio) or ratio >= 1.0:
            return math.inf, math.inf, math.inf
        g_start = gains[L] * ratio ** (start - L)
        step = max(t1[L] - t1[L - 1], 0.0) if L >= 1 and gains[L - 1] > 0 else 0.0
        var_L = max(t2[L] - t1[L] ** 2, 0.0)
        s0 = ratio / (1 - ratio)  # sum r^i, i >= 1
        s1 = ratio / (1 - ratio) ** 2  # sum i r^i
        s2 = ratio * (1 + ratio) / (1 - ratio) ** 3  # sum i^2 r^i
        base = t1[L] + (start - L) * step
        geo = (
            g_start * s0,
            g_start * (base * s0 + step * s1),
            g_start * ((base * base + var_L) * s0 + 2 * base * step * s1 + step * step * s2),
        )
        extra = geo if geo[0] >= measured_beyond[0] else measured_beyond
    else:
        extra = measured_beyond
    p, p1, p2 = p + extra[0], p1 + extra[1], p2 + extra[2]
    noise = 2.0 * math.sqrt(float((errors[n + 1 :] ** 2).sum()))
    if p > 0 and noise > 0:  # the pilot's error on the tail, at the tail's delays
        scale = (p + noise) / p
        p, p1, p2 = p * scale, p1 * scale, p2 * scale
    elif noise > 0:
        p, p1, p2 = noise, noise * t1[min(n, len(t1) - 1)], noise * t2[min(n, len(t2) - 1)]
    return p, p1, p2


def _delay_shift(h0, tau0, tau_rms, p, p1, p2):
    """(|shift of tau0|, |shift of tau_rms|) [s] when power p with delay moments p1, p2 is left out of a link
    whose full response has gain h0, mean delay tau0 and RMS delay spread tau_rms."""
    if not math.isfinite(p) or p >= h0:
        return math.inf, math.inf
    if p <= 0:
        return 0.0, 0.0
    h, m1, m2 = h0 - p, h0 * tau0 - p1, h0 * (tau_rms**2 + tau0**2) - p2  # what the truncated run measures
    t0_cut = m1 / h
    rms_cut = math.sqrt(max(m2 / h - t0_cut**2, 0.0))
    return abs(t0_cut - tau0), abs(rms_cut - tau_rms)


def _tail_order(gains, errors, ratio: float, allowed: float, cap: int, delays=None, limit: int | None = None):
    """Smallest order n whose tail is within its allowance (else the cap), and that tail [per watt].

    tail(n) = the pilot's orders above n + the geometric tail past its last measured
    order (`tail_ratio`) + 2 pilot standard errors. With `delays` = (t1, t2, h0, tau0,
    tau_rms, rel) (per-order delay moments, the link's H0 and delays, the relative
    allowance), the order must also keep the shifts of tau0 and tau_rms that dropping
    the tail causes (`_delay_shift`, a late tail weighted by its delay) under
    rel x tau_rms each. With `limit` (> the pilot's orders), a finite ratio < 1 and a
    power past the pilot's last order over the allowance, the search goes on past the
    pilot along the geometric tail, tail(n) = g_L r^(n - L + 1)
    / (1 - r), up to n = limit (returned when even that is not enough), with the
    allowance and the delays of the full response (the pilot's and the tail past it).
    Returns (n, tail power, tau0 shift, tau_rms shift, the allowance at n, delay shifts within theirs).
    """
    n_orders = len(gains)
    zeros = np.zeros(n_orders)
    t1, t2 = (delays[0], delays[1]) if delays is not None else (zeros, zeros)
    last = (math.inf, math.inf, math.inf, allowed, True)
    beyond = limit is not None and limit >= n_orders and math.isfinite(ratio) and ratio < 1.0
    full = (0.0, 0.0, 0.0)
    allowed_beyond = allowed

    def orders():
        """The pilot's orders, then (`beyond`, when the power of the orders past the pilot's last one is over
        the allowance) the orders past it that may meet it."""
        nonlocal full, allowed_beyond
        yield from range(n_orders)
        if not beyond or last[0] <= allowed:  # the pilot's orders meet the power allowance: as they are
            return
        assert limit is not None
        full = _tail_moments(n_orders - 1, gains, errors, t1, t2, ratio)
        measured = float(np.sum(gains))
        if measured > 0:  # the allowance is relative to H0: the pilot's, plus the tail it did not reach
            allowed_beyond = allowed * (1.0 + full[0] / measured)
        first = n_orders
        if full[0] > allowed_beyond > 0:  # tail(n) = full r^(n - n_orders + 1): skip the orders that cannot do
            first = n_orders - 2 + math.ceil(math.log(allowed_beyond / full[0]) / math.log(ratio))
        yield from range(min(max(first, n_orders), limit), limit + 1)

    extended = False
    for n in orders():
        p, p1, p2 = _tail_moments(n, gains, errors, t1, t2, ratio)
        extended = n >= n_orders
        allow = allowed if n < n_orders else allowed_beyond
        if delays is not None:
            h0, tau0, tau_rms, rel = delays[2:]
            if n >= n_orders:  # the full response: the pilot's orders and the geometric tail past them
                m1, m2 = h0 * tau0 + full[1], h0 * (tau_rms**2 + tau0**2) + full[2]
                h0 += full[0]
                tau0 = m1 / h0
                tau_rms = math.sqrt(max(m2 / h0 - tau0**2, 0.0))
            d0, d_rms = _delay_shift(h0, tau0, tau_rms, p, p1, p2)  # the pilot holds every order it reached
            ok_delay = d0 <= rel * tau_rms and d_rms <= rel * tau_rms
        else:
            d0 = d_rms = 0.0
            ok_delay = True
        last = (p, d0, d_rms, allow, ok_delay)
        if p <= allow and ok_delay:
            return n, *last
    return (limit if extended else cap), *last


def validated(doc: dict, what: str) -> SceneSpec:
    """The SceneSpec of a document the engine derived (`what` names it); its problems as one SceneError."""
    try:
        return SceneSpec.model_validate(doc)
    except ValidationError as err:
        problems = "; ".join(f"{loc or '(document)'}: {msg}" for loc, msg in located(err.errors()))
        raise SceneError(f"{what}: {problems}") from None


@dataclass(frozen=True)
class PilotRun:
    """The truncation pilot the job runner must run: its document and its scene (the job's scene with the
    chosen receivers: nothing rebuilt), the receivers it traces and the caps it measures up to."""

    spec: SceneSpec
    scene: Scene
    receivers: list[int]
    cap_k: int
    cap_s: int
    t_long: float


@dataclass(frozen=True)
class Resolution:
    """The job's settings so far: `spec` (explicit where decided), the `scene` it runs on, the `modeled`
    section explaining them, the `update`s still to apply after the `pilot` (None: no pilot needed)."""

    original: SceneSpec
    spec: SceneSpec
    scene: Scene
    modeled: ModeledPublic
    pilot: PilotRun | None = None
    update: dict = field(default_factory=dict)
    doc_update: dict = field(default_factory=dict)


def _apply(spec: SceneSpec, scene: Scene, update: dict, doc_update: dict) -> tuple[SceneSpec, Scene]:
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
            scene, spec=resolved, medium=None, phase=None, medium_far_distance=math.inf
        )
    return resolved, dataclasses.replace(scene, spec=resolved)


def plan(spec: SceneSpec, scene: Scene) -> Resolution:
    """First step of the resolution: the algorithm, and the settings known without a pilot; the pilot to run if
    K, S or the window are automatic (`finish` reads its result)."""
    sim = spec.simulation
    modeled = ModeledPublic(rules="engine/run/auto.py")
    update: dict = {}
    doc_update: dict = {}
    if sim.algorithm == "auto":
        room_bounds = (np.asarray(spec.room.lo), np.asarray(spec.room.hi)) if spec.room is not None else None
        number, why, drop_medium = choose_algorithm(spec, scene.medium, room_bounds)
        update["algorithm"] = number
        modeled.algorithm_reason = why
        if drop_medium and spec.medium is not None:
            doc_update["medium"] = None
    else:
        number = sim.algorithm
        modeled.algorithm_reason = f"algorithm {number} requested"
    alg = algorithm(number)
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
        longest = max(math.dist(t.position, r.position) for t in spec.transmitters for r in _extreme_receivers(spec))
        n_bins = max(1, math.ceil((longest / SPEED_OF_LIGHT - sim.t_min_s) / sim.time_bin_s + 1e-9) + 1)
        update["t_max_s"] = sim.t_min_s + n_bins * sim.time_bin_s
        modeled.time_window_reason = "line of sight only: the window ends after the longest direct path"
        need_t = False
    resolved, job_scene = _apply(spec, scene, update, doc_update)
    if not (need_k or need_s or need_t):
        return Resolution(spec, resolved, job_scene, modeled)
    # --- the truncation pilot: the job's scene with up to PILOT_RECEIVERS of its receivers -------------------
    extent = (
        float(
            np.ptp(
                np.concatenate([scene.geometry.vertices, scene.transmitters.positions, scene.receivers.positions]),
                axis=0,
            ).max()
        )
        if len(scene.geometry.vertices)
        else 10.0
    )
    cap_k = PILOT_CAP if need_k else resolved.simulation.max_reflections
    cap_s = PILOT_CAP if need_s else resolved.simulation.max_scattering
    # (S counted as at least 1: algorithm 1's S = 0 keeps the window the rule always gave it)
    t_long = resolved.simulation.t_max_s or (sim.t_min_s + (cap_k + max(cap_s, 1) + 3) * 1.8 * extent / SPEED_OF_LIGHT)
    usable = np.flatnonzero(scene.masked == "")  # grid points in furniture or outside the room are not run
    if not len(usable):
        usable = np.arange(len(scene.receivers))
    pick = sorted(
        set(usable[np.linspace(0, len(usable) - 1, min(len(usable), PILOT_RECEIVERS)).round().astype(int)].tolist())
    )
    pilot_spec = resolved.model_copy(
        update={
            "receivers": [resolved.receiver_at(i) for i in pick],
            "receiver_grids": [],
            "transmitter_groups": [],
            "outputs": OutputsSpec(cir=True, orders=True),  # the pilot reads the order split and the CIR
            "simulation": resolved.simulation.model_copy(
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
    pilot = PilotRun(pilot_spec, with_receivers(job_scene, pilot_spec), pick, cap_k, cap_s, t_long)
    return Resolution(spec, resolved, job_scene, modeled, pilot, update, doc_update)


def with_receivers(scene: Scene, spec: SceneSpec) -> Scene:
    """The built scene with the receivers of `spec` (same surfaces, transmitters and medium): what
    build_scene(spec) would give, without building the geometry or the medium again (a spectral scene's
    receiver tables follow the receivers: spectra.with_receivers)."""
    from owcsim.engine.scene.scene import _far_distance, mask_reasons, receivers_from_scene
    from owcsim.engine.spectral import spectra

    receivers, grid_slices = receivers_from_scene(spec)
    tables = scene.spectra
    if tables is not None:
        tables = spectra.with_receivers(tables, spec, len(scene.transmitters), len(receivers))
    return dataclasses.replace(
        scene,
        spec=spec,
        receivers=receivers,
        grid_slices=grid_slices,
        masked=mask_reasons(spec, receivers, len(spec.receivers)),
        medium_far_distance=_far_distance(spec, scene.geometry, scene.medium, receivers.positions),
        spectra=tables,
    )


def finish(step: Resolution, pilot: SimulationResultPublic) -> Resolution:
    """Second step of the resolution: K, S and the window from the truncation pilot's result."""
    spec, scene, run = step.original, step.scene, step.pilot
    assert run is not None
    sim = spec.simulation
    modeled, update = step.modeled.model_copy(), dict(step.update)
    alg = algorithm(update.get("algorithm", sim.algorithm))
    need_k = sim.max_reflections is None
    need_s = alg.scattering_orders is None and sim.max_scattering is None and "max_scattering" not in update
    need_t = "t_max_s" not in update and sim.t_max_s is None
    links = pilot.links
    h0 = max(max(link.dc_gain or 0.0 for link in links), 1e-300)
    gains = [link.dc_gain for link in links if link.dc_gain]
    allowed = sim.tolerance * min(gains) if gains else sim.tolerance * h0
    rho_max = _max_reflectance(spec, scene)
    k_tail = s_tail = 0.0
    bins = pilot.time_bins
    t_mid = bins.t_min_s + bins.time_bin_s * (np.arange(PILOT_BINS) + 0.5)
    rel = sim.tolerance / 2  # half the allowance to K, half to S (like the power)
    notes = []

    def choose(what, key, bound, cap, extra=0):
        """(order, tail, reason) over the pilot links: the largest order any link needs."""
        best = None
        for lk in links:
            gains, errors = getattr(lk, f"dc_gain_by_{key}_order"), getattr(lk, f"dc_gain_by_{key}_order_stderr")
            ratio, how = tail_ratio(gains, errors, bound)
            if key == "scattering" and bound >= 1.0 and not len(scene.geometry.faces):
                ratio, how = (
                    math.inf,
                    (
                        "unbounded: {what} is 1 and no surface closes the medium: light diffuses "
                        "without loss and the orders decay algebraically, not geometrically"
                    ),
                )
            delays = None
            if lk.mean_delay_s is not None and lk.rms_delay_spread_s:
                t1, t2 = _order_moments(getattr(lk.cir, f"by_{key}_order"), t_mid)
                delays = (t1, t2, lk.dc_gain, lk.mean_delay_s, lk.rms_delay_spread_s, rel)
            n, tail, d0, d_rms, allow, ok_delay = _tail_order(
                gains, errors, ratio, allowed / 2, cap, delays, limit=MAX_ORDER
            )
            n = max(n, extra)
            cand = (n, tail, d0, d_rms, how.format(what=what), allow, ok_delay)
            if best is None or (cand[0], cand[1]) > (best[0], best[1]):
                best = cand
            if n > cap and delays is not None:  # past the pilot: the window must hold the orders up to n
                ends.append(_order_window_end(gains, errors, delays[0], delays[1], n))
        assert best is not None  # the pilot has at least one link
        n, tail, d0, d_rms, how, allow, ok_delay = best
        name = {"reflection": "reflection order", "scattering": "scattering order"}[key]
        past = (
            f", past the pilot's {cap} orders along the geometric tail (Russian roulette ends the paths, so "
            "the cost per path stays near that of the orders that carry the power)"
            if n > cap
            else ""
        )
        highest = "the highest allowed" if n >= MAX_ORDER else "the pilot's highest"
        shifts = (
            f"dropping them shifts the mean delay by {d0:.2e} s and the RMS delay spread by {d_rms:.2e} s"
            if math.isfinite(d0) and math.isfinite(d_rms)
            else "that is at least the pilot's whole H0: the delay shifts cannot be stated"
        )
        if math.isfinite(tail) and tail <= allow and ok_delay:
            reason = (
                f"{name} capped at {n}{past}: estimated power of higher orders {tail:.2e} per watt <= "
                f"{allow:.2e} (half the allowed truncation); dropping them shifts the mean delay by "
                f"{d0:.2e} s and the RMS delay spread by {d_rms:.2e} s (each <= {rel:g} x tau_rms); "
                f"tail past the pilot's orders: {how}"
            )
        elif math.isfinite(tail) and tail <= allow:
            reason = (
                f"{name} capped at {n}, {highest}{past}: estimated power of higher orders {tail:.2e} per watt "
                f"<= {allow:.2e} (half the allowed truncation), but {shifts}, more than "
                f"{rel:g} x tau_rms; tail past the pilot's orders: {how}"
            )
        elif math.isfinite(tail):
            reason = (
                f"{name} capped at {n}, {highest}: the tail could not be brought under the "
                f"allowance (estimated {tail:.2e} per watt against {allow:.2e}; {shifts}); tail: {how}"
            )
        else:
            reason = (
                f"{name} capped at {n}, the pilot's highest: no finite bound on the power of higher orders "
                f"can be stated ({how}); set it explicitly and compare runs"
            )
        met.append(math.isfinite(tail) and tail <= allow)
        notes.append(f"{what}: {how}")
        return n, tail, reason

    met: list[bool] = []  # per order chosen: its tail is within the allowance
    ends: list[float] = []  # window ends that hold the orders chosen past the pilot [s]
    if need_k:
        K, k_tail, modeled.max_reflections_reason = choose("rho_max", "reflection", rho_max, run.cap_k)
        update["max_reflections"] = K
    if need_s:
        S, s_tail, modeled.max_scattering_reason = choose(
            "albedo_max", "scattering", _max_albedo(step.spec), run.cap_s, extra=1
        )
        update["max_scattering"] = S
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
        dt = sim.time_bin_s
        edges = bins.t_min_s + bins.time_bin_s * np.arange(PILOT_BINS + 1)
        t_end = max(_window_end(edges, lk, allowed / 2) for lk in links)
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
        update["t_max_s"] = sim.t_min_s + n_bins * dt
        modeled.time_window_reason = (
            f"window ends at {update['t_max_s'] * 1e9:.1f} ns: the power arriving later, extrapolated from the "
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
    modeled.pilot = PilotPublic(
        paths=sim.pilot_paths,
        receivers=[scene.receivers.ids[i] for i in run.receivers],
        max_reflections=run.cap_k,
        max_scattering=run.cap_s,
        t_max_s=run.t_long,
        allowed_truncation_per_watt=float(allowed),
        rho_max=rho_max,
    )
    total_tail = float(k_tail + s_tail)
    modeled.truncation_estimate_per_watt = total_tail if math.isfinite(total_tail) else None
    modeled.truncation_within_allowance = all(met) if met else None
    modeled.truncation_note = (
        "estimated from the pilot: the orders it measured plus a geometric tail past its "
        "last order (" + "; ".join(notes) + "), plus two of its standard errors"
        if notes
        else "no order was chosen automatically"
    )
    resolved, job_scene = _apply(spec, scene, update, doc_update)
    return Resolution(spec, resolved, job_scene, modeled)


def _order_window_end(gains, errors, t1, t2, n: int) -> float:
    """End of a window that holds reflection (scattering) orders up to n past the pilot [s].

    Order j > L (the pilot's last order measured to 30 %) arrives on average at t1[L] + (j - L) dt, dt
    = t1[L] - t1[L - 1] the pilot's per-order step, with a variance growing like the order's number
    of segments, var_L j / L; the end is order n's mean plus 4 of its standard deviations.
    """
    g = np.asarray(gains, float)
    e = np.asarray([x or 0.0 for x in errors], float)
    good = np.flatnonzero((g > 0) & (e <= 0.3 * np.where(g > 0, g, 1.0)))
    if not len(good) or good[-1] < 1:
        return 0.0
    L = int(good[-1])
    step = max(t1[L] - t1[L - 1], 0.0) if g[L - 1] > 0 else 0.0
    var = max(t2[L] - t1[L] ** 2, 0.0) * n / L
    return float(t1[L] + (n - L) * step + 4.0 * math.sqrt(var))


def _extreme_receivers(spec: SceneSpec):
    """The explicit receivers and the corners of every grid: the farthest point from any transmitter is one
    of them (the distance to a point is convex over a grid's rectangle)."""
    out = list(spec.receivers)
    for g in spec.receiver_grids:
        nu, nv = g.shape
        out += [g.point(i, j) for i in {0, nu - 1} for j in {0, nv - 1}]
    return out


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
    from owcsim.engine.core.sampling import sample_cosine_cone, to_world

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


def _window_end(edges, link: LinkPublic, allowed: float) -> float:
    """Time after which less than `allowed` power arrives, for one pilot link.

    The pilot measures the power arriving after each time well while it is a sizeable
    fraction of H0, but too few of its paths live long enough to measure the far tail.
    A room's late response decays exponentially (diffuse field), so the tail is
    extrapolated from a fit of log(power after t) over the well-measured range
    (3e-2 .. 1e-3 of H0), aiming at a third of `allowed`.
    """
    assert link.cir is not None and link.dc_gain is not None  # the pilot asks for the CIR of every link
    after = np.cumsum(np.asarray(link.cir.total)[::-1])[::-1] + (link.late_gain or 0.0)  # after each left edge
    h0 = link.dc_gain
    if h0 <= 0:
        return float(edges[0])
    direct = np.flatnonzero(after <= allowed)
    fit = np.flatnonzero((after <= 0.03 * h0) & (after >= 1e-3 * h0))
    if len(fit) >= 3:
        slope, icept = np.polyfit(edges[fit], np.log(after[fit]), 1)
        if slope < 0:  # aim at a third of the allowance: the decay slows down as the slowest mode takes over
            return float(max(edges[fit[-1]], (np.log(allowed / 3.0) - icept) / slope))
    return float(edges[direct[0]] if len(direct) else edges[-1])
