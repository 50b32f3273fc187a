"""Pieces of the result document built as arrays: columns, the binned CIR, the order split, maps.

Per-link figures are columns (one array over links) turned into JSON lists once; only the
links that asked for a CIR (a handful of explicit receivers by default) get per-link work
(the jackknife of their h^2 delay spread and 3 dB bandwidth).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from functools import reduce
from operator import add

import numpy as np

from owcsim.engine.results import metrics
from owcsim.engine.results.truncation import geometric_tail, tail_ratio
from owcsim.engine.tally.plan import TallyPlan
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas.algorithms import Direction


def column(x) -> list:
    """A float array as a JSON list, NaN and inf as None."""
    a = np.asarray(x, float)
    finite = np.isfinite(a)
    if finite.all():
        return a.tolist()
    o = a.astype(object)
    o[~finite] = None
    return o.tolist()


def document_rows(cols: dict[str, list], n: int) -> list[dict]:
    """Columns of equal length n as a list of row dicts (the JSON layout of links, receivers, channels)."""
    keys = list(cols)
    return [dict(zip(keys, row)) for row in zip(*(cols[k] for k in keys))] if n else []


def _total(parts: Iterable[np.ndarray]) -> np.ndarray:
    """The sum of the arrays (sum() of arrays, typed: its start 0 is not an array)."""
    return reduce(add, parts)


def _per_path(acc: Accumulator, links: np.ndarray, x: np.ndarray) -> np.ndarray:
    n = acc.n_paths.take(links).astype(float).reshape((-1,) + (1,) * (x.ndim - 1))
    return np.where(n > 0, x / np.maximum(n, 1.0), 0.0)


def _split(x: np.ndarray | None) -> np.ndarray:
    """An order-split tally (present when the plan splits the CIR by order)."""
    assert x is not None
    return x


def _group_estimates(accs, link: int, slot: int):
    """Per batch group: that group's own estimate of the per-path CIR of one link, summed over directions.

    A link that ran one batch per direction has one batch group: its groups are then the path groups of
    that batch (sample index mod N_GROUPS, tally.TallyPlan.first_batch_groups) where they were tallied.
    Returned as (group sums, group weights) for metrics.jackknife / bin_stderr: sum = estimate x weight.
    """
    serving = [a for a in accs if a.n_paths[link] > 0]
    if not serving:
        return np.zeros((0, 1)), np.zeros(0)
    groups, paths = [a.groups for a in serving], [a.group_paths for a in serving]
    one_batch = all(
        a.first_groups is not None and a.first_group_paths[:, link].sum() == a.n_paths[link] for a in serving
    )
    if one_batch:  # the first batch is the whole run: its path groups
        groups, paths = [a.first_groups for a in serving], [a.first_group_paths for a in serving]
    used = np.all([p[:, link] > 0 for p in paths], axis=0)
    est = sum(g[used, slot] / p[used, link][:, None] for g, p in zip(groups, paths))
    weight = sum(p[used, link] for p in paths) / len(serving)
    return est * weight[:, None], weight


def cir_block(
    accs: Mapping[Direction, Accumulator], plan: TallyPlan, cir_links: np.ndarray, los_gain, los_delay, cols: dict
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Fill the CIR columns of the links that have one; returns {link: (total per bin, per-group per-path
    estimates (N_GROUPS, bins))} for the groups' channels."""
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    if not len(cir_links):
        return out
    bins = plan.bins
    rel_edges = bins.dt * np.arange(bins.n + 1)  # metrics on times from t_min: even edges when t_min >> dt
    slots = plan.cir_slots(cir_links)
    pool = list(accs.values())
    total = _total(_per_path(a, cir_links, a.cir[slots]) for a in pool)
    early = _total(_per_path(a, cir_links, a.early[slots]) for a in pool)
    late = _total(_per_path(a, cir_links, a.late[slots]) for a in pool)
    by_k: np.ndarray | None = None
    by_s: np.ndarray | None = None
    if plan.by_order_cir:
        by_k = _total(_per_path(a, cir_links, _split(a.cir_k)[slots]) for a in pool)
        by_s = _total(_per_path(a, cir_links, _split(a.cir_s)[slots]) for a in pool)
    with np.errstate(over="ignore"):  # a delay far outside the window may overflow the bin index: no bin, then
        pos = (los_delay[cir_links] - bins.t_min) / bins.dt
    inside = (pos >= 0) & (pos < bins.n)
    los_bin = np.where(inside, np.floor(np.clip(pos, 0, bins.n)), 0).astype(np.int64)
    g = los_gain[cir_links]
    rows = np.arange(len(cir_links))
    los_vec = np.zeros_like(total)
    los_vec[rows[inside], los_bin[inside]] = g[inside]
    total = total + los_vec
    early = early + np.where(~inside & (los_delay[cir_links] < bins.t_min), g, 0.0)
    late = late + np.where(~inside & (los_delay[cir_links] >= bins.t_min), g, 0.0)
    if by_k is not None and by_s is not None:
        by_k[:, 0] += los_vec
        by_s[:, 0] += los_vec
    for r, link in enumerate(cir_links.tolist()):  # the few links with a CIR: per-link jackknife
        groups, weight = _group_estimates(pool, link, int(slots[r]))
        enough = len(weight) >= 2
        bin_se = metrics.bin_stderr(groups, weight) if enough else np.full(bins.n, np.nan)
        w_sum = float(weight.sum()) if len(weight) else 1.0

        def per_path(x, _w=w_sum, _los=los_vec[r]):
            return x / _w + _los

        t0_h2, rms_h2 = metrics.rms_delay_spread_h2(rel_edges, total[r])
        rms_h2_se = np.nan
        if enough:
            _, rms_h2_se = metrics.jackknife(
                lambda x: metrics.rms_delay_spread_h2(rel_edges, per_path(x))[1], groups, weight, vectorized=True
            )
        bw = metrics.bandwidth_3db(rel_edges, total[r])
        bw_se = None
        if bw is not None and enough:
            _, bw_se = metrics.jackknife(
                lambda x: metrics.bandwidth_3db(rel_edges, per_path(x)), groups, weight, vectorized=True
            )
        cols["mean_delay_h2_s"][link] = _num(bins.t_min + t0_h2)
        cols["rms_delay_spread_h2_s"][link] = _num(rms_h2)
        cols["rms_delay_spread_h2_s_stderr"][link] = _num(rms_h2_se)
        cols["bandwidth_3db_hz"][link] = None if bw is None else _num(bw)
        cols["bandwidth_3db_hz_stderr"][link] = None if bw_se is None else _num(bw_se)
        cols["early_gain"][link] = float(early[r])
        cols["late_gain"][link] = float(late[r])
        cols["cir"][link] = {
            "total": total[r].tolist(),
            "total_stderr": column(bin_se),
            "by_reflection_order": None if by_k is None else by_k[r].tolist(),
            "by_scattering_order": None if by_s is None else by_s[r].tolist(),
        }
        est = groups / np.where(weight > 0, weight, 1.0)[:, None] if len(weight) else np.zeros((0, bins.n))
        out[link] = (total[r], est + los_vec[r])
    return out


def order_block(
    accs: Mapping[Direction, Accumulator],
    plan: TallyPlan,
    order_links: np.ndarray,
    los_gain,
    cols: dict,
    rho_max: float,
    albedo_max: float | None,
    enclosed: bool = True,
) -> None:
    """Fill the order-split columns (H0 per reflection and scattering order) and the truncation estimate."""
    if not len(order_links):
        return
    moments = [acc.order_moments(order_links) for acc in accs.values()]  # rows in slot order: the sorted links
    mean = _total(m for m, _ in moments)
    var = _total(v for _, v in moments)
    by_k = mean.sum(axis=2)
    by_k[:, 0] += los_gain[order_links]
    by_s = mean.sum(axis=1)
    by_s[:, 0] += los_gain[order_links]
    by_k_se, by_s_se = np.sqrt(var.sum(axis=2)), np.sqrt(var.sum(axis=1))
    tail = np.zeros(len(order_links))
    for r in range(len(order_links)):  # the decay past the last order: fitted to the measured orders, capped by
        if by_k.shape[1] > 1:  # rho_max (albedo_max) when below 1 (truncation.tail_ratio)
            tail[r] += geometric_tail(by_k[r, -1], tail_ratio(by_k[r], by_k_se[r], rho_max)[0])
        if (
            albedo_max is not None
        ):  # albedo 1 and no surface: algebraic decay, no geometric bound (as engine/run/auto.py)
            ratio = tail_ratio(by_s[r], by_s_se[r], albedo_max)[0] if albedo_max < 1.0 or enclosed else np.inf
            tail[r] += geometric_tail(by_s[r, -1], ratio)
    for r, link in enumerate(order_links.tolist()):
        cols["dc_gain_by_reflection_order"][link] = by_k[r].tolist()
        cols["dc_gain_by_reflection_order_stderr"][link] = column(by_k_se[r])
        cols["dc_gain_by_scattering_order"][link] = by_s[r].tolist()
        cols["dc_gain_by_scattering_order_stderr"][link] = column(by_s_se[r])
        cols["truncated_gain_estimate"][link] = _num(tail[r])


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def group_power(weights: np.ndarray, power: np.ndarray) -> np.ndarray:
    """(G,) optical power of each transmitter group [W]: the sum of its members' `power` (weights (G, n_tx) > 0)."""
    return np.array([power[weights[g] > 0].sum() for g in range(len(weights))])


#: Map quantities: key in the link / channel columns -> (unit, the key of its standard error or None).
MAP_QUANTITIES = {
    "dc_gain": ("1", "dc_gain_stderr"),
    "path_loss_db": ("dB", None),
    "received_power_w": ("W", None),
    "received_power_dbm": ("dBm", None),
    "mean_delay_s": ("s", "mean_delay_s_stderr"),
    "rms_delay_spread_s": ("s", "rms_delay_spread_s_stderr"),
}
#: Quantities of a map whose points traced paths (none for an exact line-of-sight map): each point's achieved
#: relative error dc_gain_stderr / dc_gain, and its paths (its own allocation: engine/run/allocation.py).
TRACED_MAP_QUANTITIES = {"dc_gain_rel_error": "1", "paths": "1"}
#: Quantities a map has when the scene asks for them (luminous output, link budget): included where finite.
OPTIONAL_MAP_QUANTITIES = {
    "illuminance_lx": "lx",
    "illuminance_direct_lx": "lx",
    "cylindrical_illuminance_direct_lx": "lx",
    "snr_db": "dB",
    "ber": "1",
    "max_bit_rate_bps": "bit/s",
    "bandwidth_3db_hz": "Hz",  # group channels with a CIR (engine/results/channel_spectrum.py)
}
#: The standard error of an optional quantity: its key in the columns.
OPTIONAL_MAP_STDERR = {"illuminance_lx": "illuminance_lx_stderr", "bandwidth_3db_hz": "bandwidth_3db_hz_stderr"}


def grid_maps(spec, scene, columns: dict[str, list], names: list[str]) -> list[dict]:
    """Each receiver grid as 2-D arrays per channel: `columns` are the result's link columns (one channel per
    transmitter) or its group-channel columns, channel-major over the receivers; `names` the channels."""
    if not scene.grid_slices:
        return []
    n_rx = len(scene.receivers)
    out = []
    for grid, (first, (nu, nv)) in zip(spec.receiver_grids, scene.grid_slices):
        u = np.asarray(grid.u, float) / np.linalg.norm(grid.u)
        v = np.asarray(grid.v, float) / np.linalg.norm(grid.v)
        su, sv = grid.steps
        for c, name in enumerate(names):
            sl = slice(c * n_rx + first, c * n_rx + first + nu * nv)

            def part(key, sl=sl, nu=nu, nv=nv):
                return np.array(columns[key][sl], dtype=float).reshape(nu, nv)  # None becomes NaN

            values, stderr, units = {}, {}, {}
            for q, (unit, se_key) in MAP_QUANTITIES.items():
                if q == "received_power_dbm":
                    p = part("received_power_w")
                    with np.errstate(divide="ignore", invalid="ignore"):
                        arr = np.where(p > 0, 10.0 * np.log10(np.where(p > 0, p, 1.0) / 1e-3), np.nan)
                else:
                    arr = part(q)
                values[q], units[q] = column(arr), unit
                if se_key is not None:
                    stderr[q] = column(part(se_key))
            for q, unit in OPTIONAL_MAP_QUANTITIES.items():
                if q in columns and np.isfinite(arr := part(q)).any():
                    values[q], units[q] = column(arr), unit
                    if OPTIONAL_MAP_STDERR.get(q) in columns:
                        stderr[q] = column(part(OPTIONAL_MAP_STDERR[q]))
            if "paths" in columns and np.nanmax(part("paths"), initial=0.0) > 0:  # Monte Carlo ran
                with np.errstate(divide="ignore", invalid="ignore"):
                    rel = part("dc_gain_stderr") / part("dc_gain")
                values["dc_gain_rel_error"] = column(np.where(np.isfinite(rel), rel, np.nan))
                values["paths"] = column(part("paths"))
                units.update(TRACED_MAP_QUANTITIES)
            out.append(
                {
                    "grid": grid.id_prefix,
                    "channel": name,
                    "shape": (nu, nv),
                    "origin": tuple(grid.origin),
                    "u": tuple(u.tolist()),
                    "v": tuple(v.tolist()),
                    "spacing": su if su == sv else None,
                    "spacing_uv": (su, sv),
                    "normal": tuple(np.asarray(grid.receiver_normal, float) / np.linalg.norm(grid.receiver_normal)),
                    "units": units,
                    "values": values,
                    "stderr": stderr,
                }
            )
    return out
