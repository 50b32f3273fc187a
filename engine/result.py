"""Turn merged tallies into the result document (schemas.results.SimulationResultPublic)."""
from __future__ import annotations

import math
from importlib.metadata import PackageNotFoundError, version

import numpy as np

from schemas.results import SimulationResultPublic

from . import metrics
from .tally import Accumulator

FAMILIES = {1: "paths without scattering (s = 0), reflection orders 0..K; extinction on every segment"}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _owcsim_version() -> str:
    try:
        return version("owcsim")
    except PackageNotFoundError:  # running from a source tree without installing
        return "0+unknown"


def build_result(spec, scene, acc: Accumulator, settings, los_gain, los_delay, directions, info) -> dict:
    bins = settings.bins
    edges = bins.edges
    n = acc.n_paths.astype(float)
    nn = np.maximum(n, 1.0)
    los_abc = np.stack([los_gain, los_gain * los_delay, los_gain * los_delay**2], axis=-1)
    delay = metrics.delay_metrics(acc.n_paths, acc.s1, acc.s2, deterministic=los_abc)
    # Line of sight into the tallies (deterministic: no variance).
    los_bin = np.floor((los_delay - bins.t_min) / bins.dt).astype(np.int64)
    tx_ids, rx_ids = scene.transmitters.ids, scene.receivers.ids
    n_rx = len(rx_ids)
    links = []
    for link in range(scene.n_links):  # loop over links to assemble the document, not over paths
        ti, ri = divmod(link, n_rx)
        cir_k = acc.cir[link].sum(axis=1) / nn[link]  # (K+1, bins), summed over s
        early = acc.early[link].sum() / nn[link]
        late = acc.late[link].sum() / nn[link]
        los_in = 0 <= los_bin[link] < bins.n
        if los_gain[link] > 0:
            if los_in:
                cir_k[0, los_bin[link]] += los_gain[link]
            elif los_delay[link] < bins.t_min:
                early += los_gain[link]
            else:
                late += los_gain[link]
        total = cir_k.sum(axis=0)
        used = acc.group_paths[:, link] > 0
        groups, gp = acc.groups[used, link], acc.group_paths[used, link]
        los_vec = np.zeros(bins.n)
        if los_gain[link] > 0 and los_in:
            los_vec[los_bin[link]] = los_gain[link]
        bin_se = metrics.bin_stderr(groups, gp) if used.sum() >= 2 else np.full(bins.n, np.nan)

        def per_path(x, _n=float(gp.sum()) if used.any() else 1.0, _los=los_vec):
            return x / _n + _los

        t0_h2, rms_h2 = metrics.rms_delay_spread_h2(edges, total)
        _, rms_h2_se = metrics.jackknife(lambda x: metrics.rms_delay_spread_h2(edges, per_path(x))[1], groups, gp)
        bw = metrics.bandwidth_3db(edges, total)
        bw_se = None
        if bw is not None:
            _, bw_se = metrics.jackknife(lambda x: metrics.bandwidth_3db(edges, per_path(x)), groups, gp)
        order_mean = acc.order_sum[link].sum(axis=1) / nn[link]
        order_var = np.maximum(acc.order_sumsq[link].sum(axis=1) / nn[link] - order_mean**2, 0) / max(n[link] - 1, 1)
        order_mean[0] += los_gain[link]
        order_se = np.sqrt(order_var) if n[link] >= 2 else np.full_like(order_var, np.nan)
        h0 = float(delay["dc_gain"][link])
        links.append({
            "transmitter": tx_ids[ti], "receiver": rx_ids[ri], "transmitter_index": ti, "receiver_index": ri,
            "direction": "forward" if directions[link] == 0 else "backward", "paths": int(n[link]),
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
            "los_gain": float(los_gain[link]), "los_delay_s": float(los_delay[link]),
            "dc_gain_by_reflection_order": [float(v) for v in order_mean],
            "dc_gain_by_reflection_order_stderr": [_num(v) for v in order_se],
            "dc_gain_by_scattering_order": [h0],
            "early_gain": float(early), "late_gain": float(late),
            "cir": {"total": total.tolist(), "total_stderr": [_num(v) for v in bin_se],
                    "by_reflection_order": cir_k.tolist()},
        })
    rel = acc.dc_gain_rel_stderr(los_gain)
    run = {
        "stop_reason": info.stop_reason, "target_rel_error": spec.simulation.target_rel_error,
        "max_dc_gain_rel_stderr": _num(rel.max()) if len(rel) else None,
        "wall_time_s": info.wall_time_s, "workers": info.workers, "batches": info.batches,
        "paths_total": int(acc.n_paths.sum()), "rays_intersect": acc.rays_intersect,
        "rays_occluded": acc.rays_occluded, "direction_choice": info.pilot,
    }
    diagnostics = {
        "power_on_surfaces": {tx_ids[i]: float(p) / max(acc.n_paths[scene.link(i, 0):scene.link(i + 1, 0)].max(), 1)
                              for i, p in acc.surface_power.items()},
        "escaped_power": {tx_ids[i]: float(p) / max(acc.n_paths[scene.link(i, 0):scene.link(i + 1, 0)].max(), 1)
                          for i, p in acc.escaped_power.items()},
        "medium_evaluations": acc.medium_evaluations,
    }
    doc = {
        "owcsim_version": _owcsim_version(), "algorithm": spec.simulation.algorithm,
        "families": FAMILIES[spec.simulation.algorithm],
        "time_bins": {"t_min_s": bins.t_min, "time_bin_s": bins.dt, "n_bins": bins.n},
        "links": links, "run": run, "diagnostics": diagnostics, "scene": spec.model_dump(mode="json"),
    }
    SimulationResultPublic.model_validate(doc)  # the document matches its published schema
    return doc
