"""Turn merged tallies into the typed result (schemas.results.SimulationResultPublic).

The result is built as columns (one array per figure over links), turned into rows once and
validated once into the pydantic model, which the engine returns: the schemas layer sits below
the engine, so the wire model is the engine's result type too, and the command line, the
server and the client read its attributes; it becomes JSON only where bytes leave the process.

A link is estimated by one direction's paths, or by both (algorithm 4): independent
estimators of the same quantity, so means and variances add.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from owcsim.engine.core.arrays import BoolArray, FloatArray
from owcsim.engine.integrator.lobe import LOBE_PEAK, phase_lobe_wanted
from owcsim.engine.integrator.path import KernelSettings
from owcsim.engine.media.phase import PhaseFunction
from owcsim.engine.results import metrics
from owcsim.engine.results.cells import cells_block
from owcsim.engine.results.channel_spectrum import group_bandwidths
from owcsim.engine.results.job import FinishedJob
from owcsim.engine.results.lighting import Lighting
from owcsim.engine.results.orientation import receivers_as_held
from owcsim.engine.results.result_parts import cir_block, column, document_rows, grid_maps, group_power, order_block
from owcsim.engine.results.spectral import result_block
from owcsim.engine.scene.los import los_gain_grey, los_geometry
from owcsim.engine.scene.scene import Scene
from owcsim.engine.tally import reliability
from owcsim.engine.tally.estimates import (
    channel_moments,
    link_moments,
    link_reliability,
    los_moments,
    reported_rel_stderr,
)
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas import SceneSpec
from owcsim.schemas.algorithms import Direction, algorithm
from owcsim.schemas.results import ModeledPublic, SimulationResultPublic, UnreachablePublic
from owcsim.schemas.units import unit_warnings
from owcsim.version import __version__  # the package's one version lookup


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


#: Mean cosine above which a phase function is flagged as too peaked for next-event estimation.
PEAKED_PHASE_G = 0.95


def _warnings(spec: SceneSpec, scene: Scene) -> list[str]:
    """The scene's and the algorithm's warnings: a peaked phase function, light the algorithm leaves out,
    receivers too large for a point, and values plausible only in another unit."""
    out = []
    alg = algorithm(spec.simulation.algorithm)
    phase = scene.phase if isinstance(scene.phase, PhaseFunction) else None
    if phase is not None and alg.counts_scattering and abs(phase.mean_cosine) > PEAKED_PHASE_G:
        out.append(
            f"phase function mean cosine {phase.mean_cosine:.4g}: connections from scattering "
            "points to point-like devices are heavy-tailed, so the scattered part converges slowly and its "
            "error bars may be too small; compare runs with different seeds"
        )
    if alg.warning_in_scattering_medium and scene.scatters:
        out.append(alg.warning_in_scattering_medium)
    out += _size_warnings(scene)
    return out + unit_warnings(spec, surface_extent(scene))


def surface_extent(scene) -> float | None:
    """Largest side [m] of the surfaces' bounding box (None without surfaces)."""
    v = scene.geometry.vertices
    return float(np.ptp(v, axis=0).max()) if len(v) else None


#: Fraction of H0 outside the time window above which the result warns.
OUTSIDE_WINDOW_WARNING = 0.1


def _window_warnings(cols: dict[str, list]) -> list[str]:
    """Links with much of H0 arriving before t_min_s or after t_max_s (early_gain + late_gain)."""
    outside = [
        (early + late) / h0
        for h0, early, late in zip(cols["dc_gain"], cols["early_gain"], cols["late_gain"])
        if h0 and early is not None
    ]
    worst = max(outside, default=0.0)
    if worst <= OUTSIDE_WINDOW_WARNING:
        return []
    n = sum(f > OUTSIDE_WINDOW_WARNING for f in outside)
    return [
        f"{n} link(s) receive more than {OUTSIDE_WINDOW_WARNING:.0%} of H0 outside the time window (up to "
        f"{worst:.0%}): the binned CIR, the h2-weighted delay figures and the 3 dB bandwidth describe only the "
        "part inside it (H0, mean delay and tau_rms count every arrival); widen t_min_s..t_max_s"
    ]


#: Estimated fraction of H0 in the orders above a user-given K (S) above which the result warns.
TRUNCATION_WARNING = 0.1


def _truncation_warnings(cols: dict[str, list], modeled: ModeledPublic | None, sim) -> list[str]:
    """The orders left out carry more than the user may think: automatic K / S that could not meet their
    allowance (the pilot's estimate), or links whose `truncated_gain_estimate` exceeds TRUNCATION_WARNING of
    H0 (user-given K / S), or that have no finite estimate at all."""
    share = [
        (t / h0 if t is not None else math.inf, i)
        for i, (h0, t, split) in enumerate(
            zip(cols["dc_gain"], cols["truncated_gain_estimate"], cols["dc_gain_by_reflection_order"])
        )
        if h0 and split is not None
    ]
    worst, at = max(share, default=(0.0, -1))
    where = f" (link {cols['transmitter'][at]}-{cols['receiver'][at]})" if at >= 0 else ""
    cut = f"K = {sim.max_reflections}" + (f", S = {sim.scattering_orders}" if sim.scattering_orders > 1 else "")
    if modeled is not None and modeled.truncation_within_allowance is False:
        est = modeled.truncation_estimate_per_watt
        size = (
            f"up to {worst:.2%} of dc_gain{where}"
            if math.isfinite(worst) and worst > 0
            else (f"{est:.3g} per watt (pilot)" if est is not None else "an amount no finite bound can be stated for")
        )
        return [
            f"the automatic orders ({cut}) could not keep the truncated power within its allowance of "
            f"{sim.tolerance:g} x H0: the orders left out carry an estimated {size}, not in dc_gain; "
            "modeled.max_reflections_reason says why; set max_reflections (max_scattering) and compare runs"
        ]
    if not math.isfinite(worst):
        return [
            f"no finite bound on the power of the orders above {cut} can be stated{where} (no geometric decay "
            "measured): dc_gain may miss a large part; raise max_reflections (max_scattering) and compare runs"
        ]
    if worst > TRUNCATION_WARNING:
        n = sum(f > TRUNCATION_WARNING for f, _ in share)
        return [
            f"{n} link(s) miss more than {TRUNCATION_WARNING:.0%} of H0 in the orders above {cut}: up to an "
            f"estimated {worst:.0%} of dc_gain{where} (truncated_gain_estimate: a geometric tail, at the "
            "largest per-order ratio the scene allows when few orders are measured); raise max_reflections "
            "(max_scattering) or leave them automatic"
        ]
    return []


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
    return [
        f"{len(big)} receiver(s) too large for the point-receiver model, e.g. {scene.receivers.ids[j]}: side "
        f"sqrt(area) = {math.sqrt(areas[j]):.3g} m against {nearest[j]:.3g} m to the nearest transmitter "
        f"(the model needs under {POINT_RECEIVER_RATIO:g} of it); their gains are overestimated and may exceed 1"
    ]


def _modeled(job: FinishedJob) -> ModeledPublic:
    """The result's `modeled` section: what the automatic settings said (`job.modeled`), and what ran."""
    spec, scene, settings = job.spec, job.scene, job.settings
    sim = spec.simulation
    alg = algorithm(sim.algorithm)
    chosen = (
        job.modeled
        if job.modeled is not None
        else ModeledPublic(algorithm_reason=f"algorithm {sim.algorithm} requested")
    )
    families, left_out = alg.families_at(sim.scattering_orders)
    left = list(left_out) if scene.scatters else []
    left.append(f"reflection orders above K = {sim.max_reflections}")
    if alg.scattering_orders is None and scene.medium is not None:  # S chosen, not fixed by the algorithm
        left.append(f"scattering orders above S = {sim.max_scattering}")
    left.append(f"arrivals after t_max_s = {settings.bins.edges[-1]:.4g} s in the binned CIR (counted in late_gain)")
    why = (
        "it faces into a solid or lies flush against a surface (no transmitter in view): no light reaches it; "
        "not simulated"
    )
    return chosen.model_copy(
        update=dict(
            algorithm=sim.algorithm,
            families=families if scene.medium is not None else "vacuum paths, reflection orders 0..K",
            left_out=left,
            medium=(
                scene.medium_model.report(scene.phase if isinstance(scene.phase, PhaseFunction) else None)
                if scene.medium_model is not None
                else None
            ),
            max_reflections=sim.max_reflections,
            max_scattering=sim.scattering_orders if scene.medium is not None else 0,
            time_window_s=(settings.bins.t_min, float(settings.bins.edges[-1])),
            unreachable_receivers=[
                UnreachablePublic(receiver=scene.receivers.ids[j], reason=why) for j in job.unreachable
            ],
        )
    )


def _paths_traced(accs: Mapping[Direction, Accumulator], n_tx: int, n_rx: int) -> int:
    """Paths traced, not path-link pairs: a forward path serves every link of its transmitter
    (the largest count among them), a backward path every link of its receiver."""
    fwd = accs[Direction.FORWARD].n_paths.reshape(n_tx, n_rx)
    bwd = accs[Direction.BACKWARD].n_paths.reshape(n_tx, n_rx)
    return int(fwd.max(axis=1).sum() + bwd.max(axis=0).sum())


#: Per-link figures that only some links have (a CIR, an order split, a finite delay of h^2): None elsewhere.
OPTIONAL_LINK_COLUMNS = (
    "mean_delay_h2_s",
    "rms_delay_spread_h2_s",
    "rms_delay_spread_h2_s_stderr",
    "bandwidth_3db_hz",
    "bandwidth_3db_hz_stderr",
    "truncated_gain_estimate",
    "dc_gain_by_reflection_order",
    "dc_gain_by_reflection_order_stderr",
    "dc_gain_by_scattering_order",
    "dc_gain_by_scattering_order_stderr",
    "early_gain",
    "late_gain",
    "cir",
)


@dataclass(frozen=True, slots=True)
class _LinkFigures:
    """Per link: the line of sight with masked links zeroed, its moments (a, b, c of metrics), and the delay
    figures of the merged moments with masked links NaN (`masked`: per link, its receiver is masked)."""

    masked: BoolArray
    los_gain: FloatArray
    los_abc: FloatArray  # (L, 3)
    h0: FloatArray
    delay: dict[str, FloatArray]  # dc_gain, mean_delay_s, rms_delay_spread_s and their stderr


def _link_figures(job: FinishedJob) -> _LinkFigures:
    """H0 and the delay figures of every link from the merged moments plus the closed-form line of sight."""
    scene = job.scene
    masked = np.tile(scene.masked != "", len(scene.transmitters))
    los_gain = np.where(masked, 0.0, job.los.gain)
    los_abc = los_moments(los_gain, job.los.delay)
    mean, cov = link_moments(job.accs, los_abc)
    delay = metrics.delay_metrics_from_moments(mean, cov)
    h0 = np.where(masked, np.nan, delay["dc_gain"])
    nan_masked = {k: np.where(masked, np.nan, v) for k, v in delay.items()}
    return _LinkFigures(masked, los_gain, los_abc, h0, nan_masked)


def _link_columns(job: FinishedJob, f: _LinkFigures) -> dict[str, list]:
    """The links' columns (one list per figure over links), the optional ones None until filled."""
    scene = job.scene
    tx, rx = scene.transmitters, scene.receivers
    link_tx, link_rx = np.divmod(np.arange(scene.n_links), len(rx))
    n_paths = np.sum([a.n_paths for a in job.accs.values()], axis=0)
    h0, d = f.h0, f.delay
    cols: dict[str, list] = {
        "transmitter": [tx.ids[i] for i in link_tx],
        "receiver": [rx.ids[j] for j in link_rx],
        "transmitter_index": link_tx.tolist(),
        "receiver_index": link_rx.tolist(),
        "receiver_position": [tuple(p) for p in rx.positions[link_rx].tolist()],
        "direction": [Direction.of_code(c) for c in job.directions],
        "paths": n_paths.tolist(),
        "dc_gain": column(h0),
        "dc_gain_stderr": column(d["dc_gain_stderr"]),
        "path_loss_db": column(metrics.path_loss_db(h0)),
        "received_power_w": column(h0 * tx.power[link_tx]),
        "mean_delay_s": column(d["mean_delay_s"]),
        "mean_delay_s_stderr": column(d["mean_delay_s_stderr"]),
        "rms_delay_spread_s": column(d["rms_delay_spread_s"]),
        "rms_delay_spread_s_stderr": column(d["rms_delay_spread_s_stderr"]),
        "los_gain": column(np.where(f.masked, np.nan, f.los_gain)),
        "los_delay_s": job.los.delay.tolist(),
    }
    for key in OPTIONAL_LINK_COLUMNS:
        cols[key] = [None] * scene.n_links
    return cols


def _cir_and_orders(job: FinishedJob, f: _LinkFigures, cols: dict[str, list]) -> dict:
    """Fill the CIR and the per-order columns of the links that ask for them (result_parts.py); the CIR
    totals per link (the channels' CIR sums them)."""
    scene, settings = job.scene, job.settings
    plan = settings.tally
    links = np.arange(scene.n_links)
    cir_links = np.flatnonzero(plan.cir_slots(links) >= 0)
    cir_totals = cir_block(job.accs, plan, cir_links, f.los_gain, job.los.delay, cols)
    order_links = np.flatnonzero(plan.order_slots(links) >= 0)
    rho_max = scene.max_reflectance
    # the albedo tail concerns algorithm 5's truncated scattering orders (algorithm 4's S = 2 is a family, not a cut)
    albedo_max = (
        scene.max_albedo if settings.free_flight and settings.max_scattering > 1 and scene.medium is not None else None
    )
    enclosed = len(scene.geometry.faces) > 0
    order_block(job.accs, plan, order_links, f.los_gain, cols, rho_max, albedo_max, enclosed=enclosed)
    for link in np.flatnonzero(f.masked & (plan.cir_slots(links) >= 0)):
        cols["cir"][link] = None
    return cir_totals


def _run_section(job: FinishedJob, los_gain: FloatArray) -> dict:
    """The result's `run` section: how it stopped, its error, time, workers, batches, paths and rays."""
    spec, scene, info = job.spec, job.scene, job.info
    rel = reported_rel_stderr(job.accs, los_gain, scene, job.settings.tally, spec.simulation.target_scope)
    all_accs = list(job.accs.values())
    return {
        "stop_reason": info.stop_reason,
        "target_rel_error": spec.simulation.target_rel_error,
        "max_dc_gain_rel_stderr": _num(rel.max()) if len(rel) else None,
        "wall_time_s": info.wall_time_s,
        "workers": info.workers,
        "batches": info.batches,
        "paths_total": _paths_traced(job.accs, len(scene.transmitters), len(scene.receivers)),
        "rays_intersect": sum(a.rays_intersect for a in all_accs),
        "rays_occluded": sum(a.rays_occluded for a in all_accs),
        "direction_choice": info.direction_choice,
    }


def _diagnostics(job: FinishedJob) -> dict:
    """Power on surfaces and escaped per transmitter (per forward path), and the medium's evaluations."""
    scene, fwd = job.scene, job.accs[Direction.FORWARD]

    def per_tx(values: Mapping[int, float]) -> dict[str, float]:
        return {
            scene.transmitters.ids[i]: float(p) / max(fwd.n_paths[scene.link(i, 0) : scene.link(i + 1, 0)].max(), 1)
            for i, p in values.items()
        }

    return {
        "power_on_surfaces": per_tx(fwd.surface_power),
        "escaped_power": per_tx(fwd.escaped_power),
        "medium_evaluations": sum(a.medium_evaluations for a in job.accs.values()),
    }


def _all_warnings(job: FinishedJob, f: _LinkFigures, cols: dict[str, list]) -> list[str]:
    """Every warning of the result, in the order the result lists them."""
    spec, scene = job.spec, job.scene
    return (
        _warnings(spec, scene)
        + _window_warnings(cols)
        + _truncation_warnings(cols, job.modeled, spec.simulation)
        + _mask_warnings(scene)
        + _peaked_phase_warnings(scene, job.settings)
        + reliability.warnings(
            link_reliability(job.accs, f.los_gain),
            [f"{t}-{r}" for t, r in zip(cols["transmitter"], cols["receiver"])],
            sampled=reliability.from_accumulators(job.accs.values()),
        )
    )


def build_result(job: FinishedJob) -> SimulationResultPublic:
    """The typed result of a finished job; every per-link figure is computed for all links at once as arrays."""
    spec, scene = job.spec, job.scene
    plan = job.settings.tally
    bins = plan.bins
    f = _link_figures(job)
    cols = _link_columns(job, f)
    cir_totals = _cir_and_orders(job, f, cols)
    geometry = job.los.geometry
    lighting = Lighting(spec, scene, geometry, job.accs) if geometry is not None else None
    if lighting is not None:
        lighting.add_link_columns(cols, f.h0, f.delay["rms_delay_spread_s"], f.masked)
    links = document_rows(cols, scene.n_links)
    masked_rx = scene.masked != ""
    bandwidth = group_bandwidths(  # (value, stderr), (G, R) each
        plan.group_weights, f.los_gain, job.los.delay, cir_totals, plan.cir_rank >= 0, bins.t_min, bins.dt
    )
    channels, channel_cols = _channels(
        spec, scene, job.accs, plan, f.los_abc, cir_totals, masked_rx, lighting, bandwidth
    )
    run = _run_section(job, f.los_gain)
    diagnostics = _diagnostics(job)
    receivers = _receivers(spec, scene)
    doc: dict[str, Any] = {
        "owcsim_version": __version__,
        "algorithm": spec.simulation.algorithm,
        "warnings": _all_warnings(job, f, cols),
        "modeled": _modeled(job),
        "families": algorithm(spec.simulation.algorithm).families,
        "time_bins": {"t_min_s": bins.t_min, "time_bin_s": bins.dt, "n_bins": bins.n},
        "links": links,
        "receivers": receivers,
        "channels": channels,
        "maps": grid_maps(spec, scene, channel_cols, [g.name for g in spec.transmitter_groups])
        if channels
        else grid_maps(spec, scene, cols, list(scene.transmitters.ids)),
        "cells": cells_block(spec, scene, plan, cols, channel_cols, job.directions),
        "run": run,
        "diagnostics": diagnostics,
        "scene": job.original or spec,  # the model itself: not validated again
    }
    held, held_warnings = receivers_as_held(spec, scene, cols, channel_cols, doc["maps"])  # docs/orientation.md
    doc.update(held, warnings=doc["warnings"] + held_warnings)
    if lighting is not None:  # luminous fluxes and EN 12464-1 figures (engine/results/lighting.py)
        doc["lighting"] = lighting.section(
            plan.group_weights, [g.name for g in spec.transmitter_groups] or list(scene.transmitters.ids), masked_rx
        )
        doc["warnings"] += lighting.warnings
    if scene.spectra is not None:  # per band and combined (engine/results/spectral.py)
        g = geometry if geometry is not None else los_geometry(scene)
        doc["spectral"] = result_block(spec, scene, job.accs, g, los_gain_grey(scene, g), job.los.delay)
        doc["warnings"] += scene.spectra.warnings
    return SimulationResultPublic.model_validate(doc)


def _peaked_phase_warnings(scene, settings: KernelSettings) -> list[str]:
    """A phase peak above lobe.LOBE_PEAK x isotropic (HG |g| >= 0.81) where the phase lobe does not cover
    the run: the single-scattering needle along Tx -> p -> Rx (or through a mirror image of a device) is missed
    by most runs, with a small error bar (issue 22 item 5; tests/matrix.py at g = +-0.999: z up to 46 in spectral
    scenes, with mirrors, and with a backward peak and reflections; forward peaks with diffuse walls held)."""
    if scene.medium is None or not phase_lobe_wanted(scene.phase):
        return []
    peak = 4.0 * math.pi * float(np.max(scene.phase.eval(np.array([1.0, -1.0]))))
    if scene.spectra is not None:
        why, fix = "the phase-lobe sampling is off in spectral scenes", "run it grey (no `spectral`)"
    elif not settings.phase_lobe:
        why, fix = "this algorithm and direction do not sample the phase lobe", "use algorithm 5"
    elif scene.mirror_planes and settings.max_reflections > 0:
        why = "paths through mirror images of the devices are not covered by the phase-lobe sampling"
        fix = "compare a forward and a backward run"
    elif settings.max_reflections > 0 and 4.0 * math.pi * float(scene.phase.eval(np.array([-1.0]))[0]) > LOBE_PEAK:
        why = "paths that scatter back off the walls are not covered by the phase-lobe sampling"
        fix = "compare a forward and a backward run"
    else:
        return []
    return [
        f"every link through the smoke has an unreliable error bar on H0: the phase function peaks at "
        f"{peak:.3g} x isotropic and {why}, so most runs miss the scattering near the device axis (off, with a "
        f"small error bar); {fix}, or compare several seeds before quoting it"
    ]


def _mask_warnings(scene) -> list[str]:
    spec = scene.spec  # the grid points only: their orientation samples (hidden receivers after them) share the mask
    points = len(spec.receivers) + sum(g.count for g in spec.receiver_grids)
    masked = np.flatnonzero(scene.masked[:points] != "")
    if not len(masked):
        return []
    return [
        f"{len(masked)} grid point(s) not simulated (values null), e.g. {scene.receivers.ids[masked[0]]}: "
        f"{scene.masked[masked[0]]}; the receivers list gives every reason"
    ]


def _receivers(spec, scene) -> list[dict]:
    rx = scene.receivers
    grid = [None] * len(rx)
    ii, jj = [None] * len(rx), [None] * len(rx)
    for g, (first, (nu, nv)) in zip(spec.receiver_grids, scene.grid_slices):
        i, j = np.divmod(np.arange(nu * nv), nv)
        grid[first : first + nu * nv] = [g.id_prefix] * (nu * nv)
        ii[first : first + nu * nv] = i.tolist()
        jj[first : first + nu * nv] = j.tolist()
    cols = {
        "id": list(rx.ids),
        "position": [tuple(p) for p in rx.positions.tolist()],
        "normal": [tuple(n) for n in rx.normals.tolist()],
        "grid": grid,
        "i": ii,
        "j": jj,
        "masked": [m or None for m in scene.masked.tolist()],
    }
    return document_rows(cols, len(rx))


def _channel_paths(accs, w: np.ndarray) -> np.ndarray:
    """(G, R) paths traced for each group's channel at each receiver: the most of its member links'."""
    n_paths = np.sum([a.n_paths for a in accs.values()], axis=0).reshape(w.shape[1], -1)
    return np.where(w[:, :, None] > 0, n_paths[None], 0).max(axis=1)


def _channels(
    spec, scene, accs, plan, los_abc, cir_totals, masked_rx, lighting=None, bandwidth=None
) -> tuple[list[dict], dict]:
    """The transmitter groups' channels at every receiver (group-major), as rows and as columns; `bandwidth`
    (value, stderr) of their 3 dB bandwidths [Hz], (G, R) each (channel_spectrum.group_bandwidths)."""
    w = plan.group_weights
    if not w.size:
        return [], {}
    mean, cov = channel_moments(accs, los_abc, plan)
    d = metrics.delay_metrics_from_moments(mean, cov)
    n_groups, n_rx = mean.shape[:2]
    power = group_power(w, scene.transmitters.power)
    nan = masked_rx[None, :]
    h0 = np.where(nan, np.nan, d["dc_gain"])
    g_idx, r_idx = np.divmod(np.arange(n_groups * n_rx), n_rx)
    flat = {k: np.where(nan, np.nan, v).ravel() for k, v in d.items()}
    cols = {
        "group": [spec.transmitter_groups[g].name for g in g_idx],
        "receiver": [scene.receivers.ids[j] for j in r_idx],
        "receiver_index": r_idx.tolist(),
        "paths": _channel_paths(accs, w).ravel().tolist(),
        "dc_gain": column(h0.ravel()),
        "dc_gain_stderr": column(flat["dc_gain_stderr"]),
        "path_loss_db": column(metrics.path_loss_db(h0.ravel())),
        "received_power_w": column((h0 * power[:, None]).ravel()),
        "mean_delay_s": column(flat["mean_delay_s"]),
        "mean_delay_s_stderr": column(flat["mean_delay_s_stderr"]),
        "rms_delay_spread_s": column(flat["rms_delay_spread_s"]),
        "rms_delay_spread_s_stderr": column(flat["rms_delay_spread_s_stderr"]),
        "cir": [None] * (n_groups * n_rx),
    }
    if bandwidth is not None:
        cols["bandwidth_3db_hz"] = column(bandwidth[0].ravel())
        cols["bandwidth_3db_hz_stderr"] = column(bandwidth[1].ravel())
    if lighting is not None:
        lighting.add_channel_columns(cols, w, h0, np.where(nan, np.nan, d["rms_delay_spread_s"]), power)
    n_tx = w.shape[1]
    for j in np.flatnonzero(plan.cir_rank >= 0):  # receivers with a CIR: a loop over few explicit receivers
        members = [cir_totals.get(i * n_rx + j) for i in range(n_tx)]
        for g in range(n_groups):
            if masked_rx[j]:
                continue
            parts = [(w[g, i], m) for i, m in enumerate(members) if w[g, i] > 0 and m is not None]
            if not parts:
                continue
            total = sum(wi * m[0] for wi, m in parts)
            groups = sum(wi * m[1] for wi, m in parts)
            se = metrics.bin_stderr(groups, np.ones(len(groups))) if len(groups) >= 2 else np.full(len(total), np.nan)
            cols["cir"][g * n_rx + j] = {"total": total.tolist(), "total_stderr": column(se)}
    return document_rows(cols, n_groups * n_rx), cols
