"""3 dB bandwidth of the transmitter groups' channels, the line of sight as exact delays (physics.md section 1).

A group g's channel at receiver j is h_gj(t) = sum_i W_gi h_ij(t) (W the group weights, engine/tally/estimates.py);
its frequency response

    H(f) = sum_i W_gi [a_ij exp(-2 pi i f tau_ij) + sum_k r_ijk exp(-2 pi i f t_k)]

has the line of sight as delta terms (gain a_ij and delay tau_ij in closed form, engine/scene/los.py) and the
reflected / scattered part binned (power r_ijk per bin, at the bin centres t_k). The 3 dB bandwidth is the
first f > 0 with |H(f)|^2 = |H(0)|^2 / 2, searched up to the binning's Nyquist frequency 1 / (2 dt): sampled on
a zero-padded FFT grid (`OVERSAMPLE` x the span of the arrivals), the first crossing refined by bisection on
the continuous sum. NaN where |H|^2 stays above the threshold up to 1 / (2 dt), where H(0) = 0, and where the
receiver has no binned CIR (asked with `outputs.cir`).
"""

from __future__ import annotations

import math

import numpy as np

from owcsim.engine.core.arrays import FloatArray

__all__ = ["OVERSAMPLE", "bandwidth_3db", "bin_gradient", "group_bandwidths"]

#: Samples of |H(f)|^2 per 1 / (span of the arrivals) before the first crossing is refined.
OVERSAMPLE = 8
#: Frequencies evaluated at once for the rows whose first crossing is not found yet (most cross in the first).
FREQ_BLOCK = 32
#: Bisection steps of the refinement: the FFT grid step / 2^52, below a double's resolution of f.
REFINE_STEPS = 52


def _power(f: FloatArray, gain, delay, binned, centres) -> FloatArray:
    """|H(f)|^2 per row at one frequency per row f (M,): gain, delay (M, D), binned (M, B), centres (B,)."""
    h = (gain * np.exp(-2j * math.pi * f[:, None] * delay)).sum(axis=1)
    if binned.shape[1]:
        h = h + (binned * np.exp(-2j * math.pi * f[:, None] * centres[None, :])).sum(axis=1)
    return np.abs(h) ** 2


def bin_gradient(f3: FloatArray, gain, delay, binned, t_min: float, dt: float) -> FloatArray:
    """(M, B) d f_3dB / d r_k of each row at its bandwidth f3 (M,) (NaN rows: 0), by implicit differentiation of
    g(f, r) = |H(f)|^2 - H(0)^2 / 2 = 0: df/dr_k = -(dg/dr_k) / (dg/df), with
    dg/dr_k = 2 Re(conj H e^(-2 pi i f t_k)) - H(0) and dg/df = 2 Re(conj H dH/df)."""
    gain, delay, binned = (np.asarray(a, float) for a in (gain, delay, binned))
    centres = t_min + dt * (np.arange(binned.shape[1]) + 0.5)
    f = np.nan_to_num(f3)[:, None]
    e_los = gain * np.exp(-2j * math.pi * f * delay)
    e_bin = np.exp(-2j * math.pi * f * centres[None, :])
    h = e_los.sum(axis=1) + (binned * e_bin).sum(axis=1)
    dh = (-2j * math.pi * delay * e_los).sum(axis=1) + (-2j * math.pi * centres * binned * e_bin).sum(axis=1)
    h0 = gain.sum(axis=1) + binned.sum(axis=1)
    dg_dr = 2.0 * np.real(np.conj(h)[:, None] * e_bin) - h0[:, None]
    dg_df = 2.0 * np.real(np.conj(h) * dh)
    ok = np.isfinite(f3) & (dg_df != 0)
    return np.where(ok[:, None], -dg_dr / np.where(ok, dg_df, 1.0)[:, None], 0.0)


def bandwidth_3db(gain, delay, binned, t_min: float, dt: float) -> FloatArray:
    """3 dB bandwidth [Hz] per row (module docstring), NaN where none below 1 / (2 dt).

    gain (M, D) [-] and delay (M, D) [s] of the delta terms; binned (M, B) [-] the power per bin of width dt
    [s] from t_min [s]. Rows are independent channels (e.g. every grid point of a group).
    """
    gain, delay = np.asarray(gain, float), np.asarray(delay, float)
    binned = np.asarray(binned, float)
    m, n_bins = binned.shape
    centres = t_min + dt * (np.arange(n_bins) + 0.5)
    h0 = gain.sum(axis=1) + binned.sum(axis=1)
    threshold = h0**2 / 2.0
    # the arrivals' span sets the sampling of |H|^2: every delta and every non-empty bin
    times = np.concatenate([np.where(gain != 0, delay, np.nan), np.where(binned != 0, centres, np.nan)], axis=1)
    with np.errstate(invalid="ignore"):
        span = np.nanmax(times, axis=1, initial=-np.inf) - np.nanmin(times, axis=1, initial=np.inf)
    span_max = float(np.max(np.where(np.isfinite(span), span, 0.0), initial=0.0))
    f_max = 1.0 / (2.0 * dt)
    n_fft = 1 << max(4, math.ceil(math.log2(OVERSAMPLE * max(n_bins, math.ceil(span_max / dt), 2))))
    freqs = np.arange(n_fft // 2 + 1) / (n_fft * dt)  # 0 .. f_max
    binned_fft = np.fft.rfft(binned, n=n_fft, axis=1) if n_bins else None
    shift = np.exp(-2j * math.pi * freqs * (t_min + 0.5 * dt))  # bin k at t_min + (k + 1/2) dt
    k = np.zeros(m, np.int64)  # first sample at or below the threshold; 0: none (yet)
    for start in range(1, len(freqs), FREQ_BLOCK):  # blocks of frequencies, only the rows not yet crossed
        rows = np.flatnonzero(k == 0)
        if not len(rows):
            break
        f = freqs[start : start + FREQ_BLOCK]
        h = (gain[rows, :, None] * np.exp(-2j * math.pi * f[None, None, :] * delay[rows, :, None])).sum(axis=1)
        if binned_fft is not None:
            h += binned_fft[rows, start : start + FREQ_BLOCK] * shift[None, start : start + FREQ_BLOCK]
        below = np.abs(h) ** 2 <= threshold[rows, None]
        hit = below.any(axis=1)
        k[rows[hit]] = start + np.argmax(below[hit], axis=1)
    found = (k > 0) & (h0 > 0)
    lo = freqs[np.maximum(k - 1, 0)]
    hi = freqs[k]
    for _ in range(REFINE_STEPS):  # bisection on the continuous sum, all rows at once
        mid = 0.5 * (lo + hi)
        under = _power(mid, gain, delay, binned, centres) <= threshold
        hi, lo = np.where(under, mid, hi), np.where(under, lo, mid)
    return np.where(found & (hi <= f_max), hi, np.nan)


def group_bandwidths(
    weights, los_gain, los_delay, cir_totals: dict, has_cir, t_min: float, dt: float
) -> tuple[FloatArray, FloatArray]:
    """(G, R) 3 dB bandwidth [Hz] of every group's channel at every receiver and its standard error, NaN where
    none.

    weights (G, n_tx) group weights; los_gain, los_delay (L,) per link (tx-major, masked links 0); cir_totals
    {link: (power per bin with the LOS in its bin, per path group estimates (n, bins))} of
    result_parts.cir_block; has_cir (R,) receivers with a binned CIR (the others get NaN: the figure is asked
    with `outputs.cir`, as its cost is per bin). The error: delta method on the bins, df = grad . dr, its
    spread over the n path groups (the batch-means error of the group channel's CIR, as `channels[].cir`):
    se = std_q(grad . r_q) / sqrt(n); NaN with fewer than 2 groups. The line of sight is exact.
    """
    w = np.asarray(weights, float)
    n_groups, n_tx = w.shape
    n_rx = len(has_cir)
    out, out_se = np.full((n_groups, n_rx), np.nan), np.full((n_groups, n_rx), np.nan)
    rx = np.flatnonzero(has_cir)
    if not n_groups or not len(rx):
        return out, out_se
    gain = np.asarray(los_gain, float).reshape(n_tx, n_rx)[:, rx]
    delay = np.asarray(los_delay, float).reshape(n_tx, n_rx)[:, rx]
    links = np.fromiter(cir_totals, np.int64, len(cir_totals))
    n_bins = len(cir_totals[int(links[0])][0]) if len(links) else 0
    reflected = np.zeros((n_tx, len(rx), n_bins))
    rank = np.full(n_rx, -1)
    rank[rx] = np.arange(len(rx))
    tx_of, rx_of = np.divmod(links, n_rx)
    keep = rank[rx_of] >= 0
    if n_bins:  # the members' binned CIRs (gathered from the dict), the LOS bin removed: it is a delta term here
        reflected[tx_of[keep], rank[rx_of[keep]]] = np.stack([cir_totals[int(k)][0] for k in links[keep]])
        with np.errstate(over="ignore", invalid="ignore"):
            pos = (delay - t_min) / dt
        inside = (pos >= 0) & (pos < n_bins)
        i_in, r_in = np.nonzero(inside)
        reflected[i_in, r_in, np.floor(pos[inside]).astype(np.int64)] -= gain[inside]
    for g in range(n_groups):  # a loop over groups, each over all its receivers at once
        members = np.flatnonzero(w[g] > 0)
        a = (w[g, members, None] * gain[members]).T
        binned = np.einsum("i,irk->rk", w[g, members], reflected[members])
        bw = bandwidth_3db(a, delay[members].T, binned, t_min, dt)
        out[g, rx] = bw
        if n_bins:
            grad = bin_gradient(bw, a, delay[members].T, binned, t_min, dt)
            out_se[g, rx] = _group_spread(grad, w[g], members, cir_totals, links[keep], tx_of[keep], rank[rx_of[keep]])
    return out, out_se


def _group_spread(grad, weights, members, cir_totals: dict, links, tx_of, rank_of) -> FloatArray:
    """(R,) std_q(grad . sum_i w_i r_iq) / sqrt(n) over the n path groups q (NaN: fewer than 2, or unequal
    group counts among the member links that have paths)."""
    n_rows = grad.shape[0]
    proj: dict[int, np.ndarray] = {}
    counts = set()
    for link, i, r in zip(links.tolist(), tx_of.tolist(), rank_of.tolist()):  # the member links with a CIR
        if weights[i] <= 0:
            continue
        est = cir_totals[link][1]
        if not len(est):  # a masked point's link: no paths, nothing to spread (its own bandwidth is NaN)
            continue
        counts.add(len(est))
        proj[r] = proj.get(r, 0.0) + weights[i] * (est @ grad[r])
    se = np.full(n_rows, np.nan)
    if len(counts) != 1 or min(counts) < 2:
        return se
    n = counts.pop()
    for r, s in proj.items():  # one small vector per receiver
        se[r] = float(np.std(s, ddof=1) / math.sqrt(n))
    return np.where(np.isfinite(grad).all(axis=1) & (np.abs(grad).sum(axis=1) > 0), se, np.nan)
