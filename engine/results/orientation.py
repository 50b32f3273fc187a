"""Receivers as people hold them: per-point statistics over random orientation, and angle-diversity combining.

Random orientation (schemas/orientation.py, Soltani et al. 2019): a point's K = n_theta x n_omega
oriented receivers are one point each of the cells of a stratified rule over (F(theta), omega / 2 pi),
so for any per-sample figure g_k (received power, SNR, the outage indicator 1[SNR_k < SNR_th])
    E[g] ~ Q = (1/K) sum_k g_k,
an unbiased estimate over the orientation law. Its quadrature error is the collapsed-strata estimate
of a stratified mean with one unit per cell (Cochran, Sampling Techniques, 3rd ed., 1977, section 5A):
cells paired along theta, sigma_Q^2 = (1/K^2) sum_pairs (g_a - g_b)^2 (conservative for smooth g).
The Monte Carlo error of each sample's power (all orders) enters as if the samples' errors were fully
correlated (they share paths): sigma_MC <= (1/K) sum_k |dg/dP_k| sigma_k, an upper bound; for the outage
indicator, half the weight of the samples whose SNR lies within two of its standard errors of the
threshold. The reported error is sqrt(sigma_Q^2 + sigma_MC^2); in line of sight sigma_MC = 0.

SNR (engine/results/link_budget.py, Komine & Nakagawa 2004): SNR(P) = (gamma P)^2 / (a + b P) with
b = 2 q gamma B (the signal's shot noise) and a the background shot and thermal noise of the receiver's
area, so dSNR/dP = gamma^2 P (2a + bP) / (a + bP)^2. `snr_mean_db` is 10 log10 of the mean linear SNR.

Angle diversity (Carruthers & Kahn 2000; Chen et al. 2018), photocurrents I_i = gamma P_i, noise
sigma_i^2 = a_i + b P_i of each photodiode:
    SC  = max_i I_i^2 / sigma_i^2
    EGC = (sum_i I_i)^2 / sum_i sigma_i^2     (= (sum sqrt(S_i))^2 / (N sigma^2) for equal noise)
    MRC = sum_i I_i^2 / sigma_i^2             (weights I_i / sigma_i^2)
with Monte Carlo errors propagated to first order as for orientation (an upper bound).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.results import link_budget as lb
from owcsim.engine.results.result_parts import column, document_rows
from owcsim.schemas.orientation import HiddenBlock, hidden_blocks

#: dB per natural-log unit: d(10 log10 x) = DB_PER_NEPER dx / x.
DB_PER_NEPER = 10.0 / math.log(10.0)


@dataclass(frozen=True)
class ChannelPowers:
    """Received power [W] and its standard error [W] per channel (the maps' channels) and receiver: (C, n_rx)."""

    names: list[str]
    power: FloatArray
    stderr: FloatArray


def channel_powers(spec, scene, columns: dict[str, list], names: list[str]) -> ChannelPowers:
    """From the result's link or group-channel columns (channel-major over receivers, as result_parts.grid_maps
    reads them): received_power_w, and dc_gain_stderr times the channel's power (a group's summed power)."""
    n_rx = len(scene.receivers)
    shape = (len(names), n_rx)
    power = np.array(columns["received_power_w"], dtype=float).reshape(shape)
    se_gain = np.array(columns["dc_gain_stderr"], dtype=float).reshape(shape)
    tx = scene.transmitters
    if spec.transmitter_groups:
        index = {t: i for i, t in enumerate(tx.ids)}
        scale = np.array([sum(tx.power[index[t]] for t in g.transmitters) for g in spec.transmitter_groups])
    else:
        scale = np.asarray(tx.power, float)
    return ChannelPowers(names, power, np.nan_to_num(se_gain) * scale[:, None])


def _noise(budget: lb.LinkBudget, area: FloatArray) -> tuple[FloatArray, float]:
    """(a, b) of sigma^2 = a + b P [A^2]: a the background shot and thermal noise of `area` [m^2], b = 2 q gamma B."""
    shot0, thermal = lb.noise_variances(budget, area, 0.0)
    return np.asarray(shot0 + thermal, float), 2.0 * lb.Q_E * budget.responsivity * budget.noise_bandwidth


def snr_and_slope(budget: lb.LinkBudget, area, power) -> tuple[FloatArray, FloatArray]:
    """(SNR [-], dSNR/dP [1/W]) of received power P [W] on `area` [m^2] (P_isi = 0), broadcast."""
    a, b = _noise(budget, np.asarray(area, float))
    g2 = budget.responsivity**2
    p = np.asarray(power, float)
    return g2 * p * p / (a + b * p), g2 * p * (2.0 * a + b * p) / (a + b * p) ** 2


def stratified_mean(g: FloatArray, mc: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(mean, standard error) over the last two axes (n_theta, n_omega) of per-sample values `g`, with `mc` the
    per-sample Monte Carlo error bound already in units of g: collapsed-strata quadrature error (cells paired along
    theta) and (1/K) sum mc, added in quadrature. NaN where any sample is NaN."""
    n_theta, n_omega = g.shape[-2:]
    k = n_theta * n_omega
    mean = g.mean(axis=(-2, -1))
    pairs = g[..., 0::2, :] - g[..., 1::2, :]
    sigma_q = np.sqrt((pairs**2).sum(axis=(-2, -1))) / k
    sigma_mc = mc.sum(axis=(-2, -1)) / k
    return mean, np.hypot(sigma_q, sigma_mc)


def _to_db(mean: FloatArray, se: FloatArray) -> tuple[FloatArray, FloatArray]:
    db = lb.to_db(mean)
    with np.errstate(divide="ignore", invalid="ignore"):
        return db, np.where(mean > 0, DB_PER_NEPER * se / np.where(mean > 0, mean, 1.0), np.nan)


def orientation_statistics(block: HiddenBlock, cp: ChannelPowers, area: FloatArray, budget) -> dict[str, FloatArray]:
    """Per channel and point of an orientation block, (C, n_points) arrays: received_power_mean_w, snr_mean_db,
    outage_probability and their `_stderr` (the SNR figures only with a budget)."""
    assert block.orientation is not None
    n_theta, n_omega = block.orientation.strata
    sl = slice(block.first, block.first + block.count)
    shape = (len(cp.names), len(block.points), n_theta, n_omega)
    p, se = cp.power[:, sl].reshape(shape), cp.stderr[:, sl].reshape(shape)
    out: dict[str, FloatArray] = {}
    out["received_power_mean_w"], out["received_power_mean_w_stderr"] = stratified_mean(p, se)
    if budget is None:
        return out
    with np.errstate(invalid="ignore", divide="ignore"):
        snr, slope = snr_and_slope(budget, area[sl].reshape(shape[1:]), p)
        snr_se = np.abs(slope) * se
        mean, mean_se = stratified_mean(snr, snr_se)
        out["snr_mean_db"], out["snr_mean_db_stderr"] = _to_db(mean, mean_se)
        threshold = block.orientation.threshold_snr
        outage = np.where(np.isnan(snr), np.nan, (snr < threshold).astype(float))
        uncertain = np.where(np.abs(snr - threshold) <= 2.0 * snr_se, 0.5, 0.0)
        uncertain = np.where(snr_se > 0, uncertain, 0.0)
        out["outage_probability"], out["outage_probability_stderr"] = stratified_mean(outage, uncertain)
    return out


#: Map quantities of random orientation: name -> unit (each with its standard error).
ORIENTATION_MAP_QUANTITIES = {"received_power_mean_w": "W", "snr_mean_db": "dB", "outage_probability": "1"}


def _orientation_rows(spec, scene, block: HiddenBlock, cp: ChannelPowers, stats: dict) -> list[dict]:
    assert block.orientation is not None
    n_c, n_p = len(cp.names), len(block.points)
    c_idx, p_idx = np.divmod(np.arange(n_c * n_p), n_p)
    points = np.asarray(block.points)[p_idx]
    nan = np.full(n_c * n_p, np.nan)
    cols = {
        "receiver": [scene.receivers.ids[i] for i in points],
        "receiver_index": points.tolist(),
        "channel": [cp.names[c] for c in c_idx],
        "samples": [block.per_point] * (n_c * n_p),
        "first_sample_index": (block.first + p_idx * block.per_point).tolist(),
        "outage_snr_db": [10.0 * math.log10(block.orientation.threshold_snr)] * (n_c * n_p),
    }
    for q in ORIENTATION_MAP_QUANTITIES:
        cols[q] = column(stats.get(q, nan).ravel())
        cols[q + "_stderr"] = column(stats.get(q + "_stderr", nan).ravel())
    return document_rows(cols, n_c * n_p)


def _add_to_maps(spec, scene, block: HiddenBlock, cp: ChannelPowers, stats: dict, maps: list[dict]) -> None:
    """Orientation quantities on the map of the grid the block belongs to, for every channel."""
    for grid, (first, (nu, nv)) in zip(spec.receiver_grids, scene.grid_slices):
        if block.points.start != first:
            continue
        for m in maps:
            if m["grid"] != grid.id_prefix or m["channel"] not in cp.names:
                continue
            c = cp.names.index(m["channel"])
            for q, unit in ORIENTATION_MAP_QUANTITIES.items():
                if q in stats:
                    m["values"][q] = column(stats[q][c].reshape(nu, nv))
                    m["stderr"][q] = column(stats[q + "_stderr"][c].reshape(nu, nv))
                    m["units"][q] = unit


def combined_snr(budget: lb.LinkBudget, area: FloatArray, power: FloatArray, stderr: FloatArray) -> dict:
    """SNR of every photodiode and of SC, EGC and MRC over the last axis (the photodiodes), with first-order Monte
    Carlo errors summed in absolute value (an upper bound for correlated errors). Linear SNRs; NaN where any
    photodiode is NaN."""
    gamma = budget.responsivity
    a, b = _noise(budget, area)
    with np.errstate(invalid="ignore", divide="ignore"):
        snr, slope = snr_and_slope(budget, area, power)
        current, noise = gamma * power, a + b * power
        i_sum, n_sum = current.sum(axis=-1), noise.sum(axis=-1)
        egc = i_sum**2 / n_sum
        d_egc = 2.0 * gamma * i_sum[..., None] / n_sum[..., None] - (i_sum**2 / n_sum**2)[..., None] * b
        sel = np.argmax(np.nan_to_num(snr, nan=-np.inf), axis=-1)
        take = np.take_along_axis
        return {
            "snr": snr,
            "selected": sel,
            "sc": take(snr, sel[..., None], -1)[..., 0],
            "sc_se": take(np.abs(slope) * stderr, sel[..., None], -1)[..., 0],
            "egc": egc,
            "egc_se": (np.abs(d_egc) * stderr).sum(axis=-1),
            "mrc": snr.sum(axis=-1),
            "mrc_se": (np.abs(slope) * stderr).sum(axis=-1),
        }


def _diversity_rows(scene, block: HiddenBlock, cp: ChannelPowers, budget) -> list[dict]:
    assert block.diversity is not None
    sl = slice(block.first, block.first + block.count)
    ids = list(scene.receivers.ids[sl])
    power, stderr = cp.power[:, sl], cp.stderr[:, sl]
    rows = []
    comb = combined_snr(budget, scene.receivers.area[sl], power, stderr) if budget is not None else None
    for c, name in enumerate(cp.names):  # a loop over channels (few)
        row: dict = {
            "receiver": block.diversity.id,
            "channel": name,
            "photodiodes": ids,
            "first_photodiode_index": block.first,
            "received_power_w": column(power[c]),
            "snr_db": [None] * len(ids),
        }
        if comb is not None:
            row["snr_db"] = column(lb.to_db(comb["snr"][c]))
            valid = bool(np.isfinite(power[c]).all())
            row["selected"] = int(comb["selected"][c]) if valid else None
            for key in ("sc", "egc", "mrc"):
                db, se = _to_db(comb[key][c : c + 1], comb[key + "_se"][c : c + 1])
                row[f"snr_{key}_db"] = column(db)[0] if valid else None
                row[f"snr_{key}_db_stderr"] = column(se)[0] if valid else None
        rows.append(row)
    return rows


def receivers_as_held(spec, scene, link_cols: dict, channel_cols: dict, maps: list[dict]) -> tuple[dict, list[str]]:
    """({"orientation": rows, "angle_diversity": rows}, warnings) of the result; adds the orientation quantities to
    `maps` (the grid_maps dicts) in place. The channels are those of the maps: the transmitter groups' channels
    (`channel_cols`) when the scene has groups, else each transmitter's links (`link_cols`)."""
    blocks = hidden_blocks(spec)
    out: dict = {"orientation": [], "angle_diversity": []}
    if not blocks:
        return out, []
    if spec.transmitter_groups:
        cp = channel_powers(spec, scene, channel_cols, [g.name for g in spec.transmitter_groups])
    else:
        cp = channel_powers(spec, scene, link_cols, list(scene.transmitters.ids))
    budget = lb.link_budget_from_spec(spec.link_budget) if spec.link_budget is not None else None
    for block in blocks:  # a loop over requests (a few), each vectorized over its points and samples
        if block.diversity is not None:
            out["angle_diversity"] += _diversity_rows(scene, block, cp, budget)
            continue
        stats = orientation_statistics(block, cp, scene.receivers.area, budget)
        out["orientation"] += _orientation_rows(spec, scene, block, cp, stats)
        _add_to_maps(spec, scene, block, cp, stats, maps)
    warnings = []
    if budget is None:
        warnings.append(
            "orientation and angle-diversity SNRs (snr_mean_db, outage_probability, the combined SNRs) need "
            "`link_budget`: they are null"
        )
    return out, warnings
