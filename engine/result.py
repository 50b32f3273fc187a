"""Turn merged tallies into the result document (schemas.results.SimulationResultPublic).

A link is estimated by one direction's paths, or by both (algorithm 4): independent
estimators of the same quantity, so means and variances add.
"""
from __future__ import annotations

import math
from importlib.metadata import PackageNotFoundError, version

import numpy as np

from owcsim.schemas.results import SimulationResultPublic

from . import metrics
from .auto import _max_albedo, _scatters
from .tally import combined_rel_stderr

FAMILIES = {
    1: "paths without scattering (s = 0), reflection orders 0..K; extinction on every segment",
    2: "s = 0 paths up to K reflections, plus single scattering lit directly by the transmitter: "
       "Tx -> p -> (k <= K reflections) -> Rx",
    3: "s = 0 paths up to K reflections, plus single scattering seen directly by the receiver: "
       "Tx -> (k <= K reflections) -> p -> Rx",
    4: "s = 0 paths up to K reflections, plus Tx -> p -> (k <= K) -> Rx and Tx -> (k <= K) -> p -> Rx, "
       "the shared family Tx -> p -> Rx counted once (balance heuristic)",
    5: "all paths with at most K reflections and S scattering events, in any order",
}
DIRECTION_NAMES = {0: "forward", 1: "backward", 2: "both", 3: "none"}
LEFT_OUT = {
    1: ["scattered light (s >= 1)"],
    2: ["single scattering reached after reflections from the transmitter (Tx -> k >= 1 -> p -> Rx)",
        "scattering orders s >= 2"],
    3: ["single scattering lit after reflections (Tx -> p -> k >= 1 -> Rx)", "scattering orders s >= 2"],
    4: ["single scattering with reflections on both sides of p", "scattering orders s >= 2"],
    5: [],
}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _owcsim_version() -> str:
    try:
        return version("owcsim")
    except PackageNotFoundError:  # running from a source tree without installing
        return "0+unknown"


#: Mean cosine above which a phase function is flagged as too peaked for next-event estimation.
PEAKED_PHASE_G = 0.95


def _warnings(spec, scene) -> list[str]:
    out = []
    sim = spec.simulation
    if scene.phase is not None and sim.algorithm > 1 and abs(scene.phase.mean_cosine) > PEAKED_PHASE_G:
        out.append(f"phase function mean cosine {scene.phase.mean_cosine:.4g}: connections from scattering "
                   "points to point-like devices are heavy-tailed, so the scattered part converges slowly and its "
                   "error bars may be too small; compare runs with different seeds")
    if sim.algorithm == 1 and _scatters(spec.medium):
        out.append("algorithm 1 counts only unscattered light: with sigma_s > 0 it underestimates "
                   "(use algorithm 4 or 5 for scattered light)")
    out += _size_warnings(scene)
    return out


#: Fraction of H0 outside the time window above which the result warns.
OUTSIDE_WINDOW_WARNING = 0.1


def _window_warnings(links) -> list[str]:
    """Links with much of H0 arriving before t_min_s or after t_max_s (early_gain + late_gain)."""
    outside = [(lk["early_gain"] + lk["late_gain"]) / lk["dc_gain"] for lk in links if lk["dc_gain"] > 0]
    worst = max(outside, default=0.0)
    if worst <= OUTSIDE_WINDOW_WARNING:
        return []
    n = sum(f > OUTSIDE_WINDOW_WARNING for f in outside)
    return [f"{n} link(s) receive more than {OUTSIDE_WINDOW_WARNING:.0%} of H0 outside the time window (up to "
            f"{worst:.0%}): the binned CIR, the h2-weighted delay figures and the 3 dB bandwidth describe only the "
            "part inside it (H0, mean delay and tau_rms count every arrival); widen t_min_s..t_max_s"]


#: A receiver is a point while its side sqrt(area) is below this fraction of its distance to a transmitter.
POINT_RECEIVER_RATIO = 0.1


def _size_warnings(scene) -> list[str]:
    """Receivers too large for the point-receiver model (gain ~ A cos / d^2, physics.md §2) next to a transmitter."""
    areas = scene.receivers.area
    d = np.linalg.norm(scene.receivers.positions[:, None, :] - scene.transmitters.positions[None, :, :], axis=2)
    nearest = d.min(axis=1)
    big = np.flatnonzero(np.sqrt(areas) > POINT_RECEIVER_RATIO * nearest)
    if not len(big):
        return []
    j = big[0]
    return [f"{len(big)} receiver(s) too large for the point-receiver model, e.g. {scene.receivers.ids[j]}: side "
            f"sqrt(area) = {math.sqrt(areas[j]):.3g} m against {nearest[j]:.3g} m to the nearest transmitter "
            f"(the model needs under {POINT_RECEIVER_RATIO:g} of it); their gains are overestimated and may exceed 1"]


def _albedo_max(scene) -> float:
    return _max_albedo(scene.spec)



def _combined(accs):
    """Per-link sums over directions: mean (a, b, c), its covariance, CIR, early/late, order moments."""
    accs = list(accs)
    served = [a for a in accs if a.n_paths.any()]
    pool = served or accs[:1]  # nothing ran (every receiver unreachable): zeros of the right shapes
    first = served[0] if served else None
    mean = sum(a.moments()[0] for a in pool)
    cov = sum(a.moments()[1] for a in pool)
    cir = sum(a.per_path(a.cir) for a in pool)
    early = sum(a.per_path(a.early) for a in pool)
    late = sum(a.per_path(a.late) for a in pool)
    order_mean = sum(a.order_moments()[0] for a in pool)
    order_var = sum(a.order_moments()[1] for a in pool)
    return first, served, mean, cov, cir, early, late, order_mean, order_var


def _group_estimates(accs, link):
    """Per batch group: that group's own estimate of the per-path CIR, summed over directions.

    Returned as (group sums, group weights) for metrics.jackknife / bin_stderr: sum = estimate x weight.
    """
    used = np.all([a.group_paths[:, link] > 0 for a in accs], axis=0)
    est = sum(a.groups[used, link] / a.group_paths[used, link][:, None] for a in accs)
    weight = sum(a.group_paths[used, link] for a in accs) / len(accs)
    return est * weight[:, None], weight


def _paths_traced(accs, n_tx: int, n_rx: int) -> int:
    """Paths traced, not path-link pairs: a forward path serves every link of its transmitter
    (the largest count among them), a backward path every link of its receiver."""
    fwd = accs["forward"].n_paths.reshape(n_tx, n_rx)
    bwd = accs["backward"].n_paths.reshape(n_tx, n_rx)
    return int(fwd.max(axis=1).sum() + bwd.max(axis=0).sum())


def _geometric_tail(gain: float, ratio: float) -> float:
    return gain * ratio / (1.0 - ratio) if ratio < 1.0 else math.inf


def _modeled(spec, scene, modeled, unreachable, settings) -> dict:
    sim = spec.simulation
    out = dict(modeled or {"algorithm_reason": f"algorithm {sim.algorithm} requested", "pilot": None})
    left = list(LEFT_OUT[sim.algorithm]) if spec.medium is not None and _scatters(spec.medium) else []
    left.append(f"reflection orders above K = {sim.max_reflections}")
    if sim.algorithm == 5 and scene.medium is not None:
        left.append(f"scattering orders above S = {sim.max_scattering}")
    left.append(f"arrivals after t_max_s = {settings.bins.edges[-1]:.4g} s in the binned CIR (counted in late_gain)")
    out["algorithm"] = sim.algorithm
    out["families"] = FAMILIES[sim.algorithm] if scene.medium is not None else "vacuum paths, reflection orders 0..K"
    out["left_out"] = left
    out["max_reflections"] = sim.max_reflections
    out["max_scattering"] = sim.scattering_orders if scene.medium is not None else 0
    out["time_window_s"] = [settings.bins.t_min, float(settings.bins.edges[-1])]
    out["unreachable_receivers"] = [
        {"receiver": scene.receivers.ids[j], "reason": "it faces into a solid or lies flush against a surface "
                                                       "(no transmitter in view): no light reaches it; not simulated"}
        for j in unreachable]
    return out


def build_result(spec, scene, accs, settings, los_gain, los_delay, directions, info, original=None, modeled=None,
                 unreachable=()) -> dict:
    bins = settings.bins
    # Binned metrics see times from t_min: spread and bandwidth do not depend on the origin, and edges
    # t_min + k dt would be uneven in float64 when t_min >> dt.
    rel_edges = bins.dt * np.arange(bins.n + 1)
    first, used_accs, mean, cov, cir, early_all, late_all, order_mean, order_var = _combined(accs.values())
    los_abc = np.stack([los_gain, los_gain * los_delay, los_gain * los_delay**2], axis=-1)
    delay = metrics.delay_metrics_from_moments(mean + los_abc, cov)
    n_paths = sum(a.n_paths for a in accs.values())
    with np.errstate(over="ignore"):  # a delay far outside the window may overflow the bin index: no bin, then
        los_pos = (los_delay - bins.t_min) / bins.dt
    los_bin = np.where((los_pos >= 0) & (los_pos < bins.n), np.floor(np.clip(los_pos, 0, bins.n)), -1).astype(np.int64)
    tx_ids, rx_ids = scene.transmitters.ids, scene.receivers.ids
    n_rx = len(rx_ids)
    links = []
    for link in range(scene.n_links):  # loop over links to assemble the document, not over paths
        ti, ri = divmod(link, n_rx)
        cir_ks = cir[link].copy()  # (K+1, S+1, bins)
        early, late = float(early_all[link].sum()), float(late_all[link].sum())
        los_vec = np.zeros(bins.n)
        if los_gain[link] > 0:
            if 0 <= los_bin[link] < bins.n:
                cir_ks[0, 0, los_bin[link]] += los_gain[link]
                los_vec[los_bin[link]] = los_gain[link]
            elif los_delay[link] < bins.t_min:
                early += los_gain[link]
            else:
                late += los_gain[link]
        cir_k = cir_ks.sum(axis=1)
        total = cir_k.sum(axis=0)
        serving = [a for a in used_accs if a.n_paths[link] > 0]
        if serving:
            groups, weight = _group_estimates(serving, link)
        else:
            groups, weight = np.zeros((0, bins.n)), np.zeros(0)
        enough = len(weight) >= 2
        bin_se = metrics.bin_stderr(groups, weight) if enough else np.full(bins.n, np.nan)

        def per_path(x, _w=float(weight.sum()) if len(weight) else 1.0, _los=los_vec):
            return x / _w + _los

        t0_h2, rms_h2 = metrics.rms_delay_spread_h2(rel_edges, total)
        t0_h2 = bins.t_min + t0_h2
        rms_h2_se = np.nan
        if enough:
            _, rms_h2_se = metrics.jackknife(lambda x: metrics.rms_delay_spread_h2(rel_edges, per_path(x))[1],
                                             groups, weight)
        bw = metrics.bandwidth_3db(rel_edges, total)
        bw_se = None
        if bw is not None and enough:
            _, bw_se = metrics.jackknife(lambda x: metrics.bandwidth_3db(rel_edges, per_path(x)), groups, weight)
        by_k = order_mean[link].sum(axis=1)
        by_k[0] += los_gain[link]
        by_k_se = np.sqrt(order_var[link].sum(axis=1))
        by_s = order_mean[link].sum(axis=0)
        by_s[0] += los_gain[link]
        by_s_se = np.sqrt(order_var[link].sum(axis=0))
        h0 = float(delay["dc_gain"][link])
        rho_max = float(scene.geometry.reflectance.max()) if len(scene.geometry.reflectance) else 0.0
        tail = _geometric_tail(float(by_k[-1]) if len(by_k) > 1 else 0.0, rho_max) if len(by_k) > 1 else 0.0
        if settings.max_scattering > 1 and scene.medium is not None:
            tail += _geometric_tail(float(by_s[-1]), _albedo_max(scene))
        links.append({
            "transmitter": tx_ids[ti], "receiver": rx_ids[ri], "transmitter_index": ti, "receiver_index": ri,
            "direction": DIRECTION_NAMES[int(directions[link])], "paths": int(n_paths[link]),
            "dc_gain": h0, "dc_gain_stderr": _num(delay["dc_gain_stderr"][link]),
            "path_loss_db": _num(metrics.path_loss_db(h0)),
            "received_power_w": h0 * float(scene.transmitters.power[ti]),
            "mean_delay_s": _num(delay["mean_delay_s"][link]),
            "mean_delay_s_stderr": _num(delay["mean_delay_s_stderr"][link]),
            "rms_delay_spread_s": _num(delay["rms_delay_spread_s"][link]),
            "rms_delay_spread_s_stderr": _num(delay["rms_delay_spread_s_stderr"][link]),
            "mean_delay_h2_s": _num(t0_h2), "rms_delay_spread_h2_s": _num(rms_h2),
            "rms_delay_spread_h2_s_stderr": _num(rms_h2_se),
            "bandwidth_3db_hz": None if bw is None else _num(bw),
            "bandwidth_3db_hz_stderr": None if bw_se is None else _num(bw_se),
            "truncated_gain_estimate": _num(tail),
            "los_gain": float(los_gain[link]), "los_delay_s": float(los_delay[link]),
            "dc_gain_by_reflection_order": [float(v) for v in by_k],
            "dc_gain_by_reflection_order_stderr": [_num(v) for v in by_k_se],
            "dc_gain_by_scattering_order": [float(v) for v in by_s],
            "dc_gain_by_scattering_order_stderr": [_num(v) for v in by_s_se],
            "early_gain": early, "late_gain": late,
            "cir": {"total": total.tolist(), "total_stderr": [_num(v) for v in bin_se],
                    "by_reflection_order": cir_k.tolist(),
                    "by_scattering_order": cir_ks.sum(axis=0).tolist()},
        })
    rel = combined_rel_stderr(accs.values(), los_gain)
    fwd = accs["forward"]
    all_accs = list(accs.values())
    run = {
        "stop_reason": info.stop_reason, "target_rel_error": spec.simulation.target_rel_error,
        "max_dc_gain_rel_stderr": _num(rel.max()) if len(rel) else None,
        "wall_time_s": info.wall_time_s, "workers": info.workers, "batches": info.batches,
        "paths_total": _paths_traced(accs, len(tx_ids), n_rx),
        "rays_intersect": sum(a.rays_intersect for a in all_accs),
        "rays_occluded": sum(a.rays_occluded for a in all_accs), "direction_choice": info.pilot,
    }

    def per_tx(values):
        return {tx_ids[i]: float(p) / max(fwd.n_paths[scene.link(i, 0):scene.link(i + 1, 0)].max(), 1)
                for i, p in values.items()}

    diagnostics = {
        "power_on_surfaces": per_tx(fwd.surface_power), "escaped_power": per_tx(fwd.escaped_power),
        "medium_evaluations": sum(a.medium_evaluations for a in all_accs),
    }
    doc = {
        "owcsim_version": _owcsim_version(), "algorithm": spec.simulation.algorithm,
        "warnings": _warnings(spec, scene) + _window_warnings(links),
        "modeled": _modeled(spec, scene, modeled, unreachable, settings),
        "families": FAMILIES[spec.simulation.algorithm],
        "time_bins": {"t_min_s": bins.t_min, "time_bin_s": bins.dt, "n_bins": bins.n},
        "links": links, "run": run, "diagnostics": diagnostics, "scene": (original or spec).model_dump(mode="json"),
    }
    SimulationResultPublic.model_validate(doc)  # the document matches its published schema
    return doc
