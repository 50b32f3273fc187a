"""Channel figures of merit from Monte Carlo tallies of an impulse response h(t).

Pure numpy; SI units (s, Hz, W per W transmitted). Every function is free of
inf and of floating-point warnings: where a figure does not exist (unreachable
link, too few paths) the arrays hold NaN, which callers map to JSON null.

Estimator model: N independent paths; path i gives per link the sums
a_i = sum w, b_i = sum w t, c_i = sum w t^2 over its contributions. The engine
keeps S1 = sum_i (a, b, c) and S2 = sum_i outer((a, b, c), (a, b, c)).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = [
    "delay_metrics",
    "delay_metrics_from_moments",
    "path_loss_db",
    "rms_delay_spread_h2",
    "bandwidth_3db",
    "jackknife",
    "bin_stderr",
]


def _safe(x, ok):
    """x where ok, else 1 (a harmless denominator)."""
    return np.where(ok, x, 1.0)


def delay_metrics(n_paths, s1, s2, deterministic=None) -> dict:
    """DC gain, mean delay and RMS delay spread, each with a standard error.

    m = S1/N + D is the per-path mean of (a, b, c); its covariance is
    C = [S2 - N mu mu^T] / (N - 1) / N with mu = S1/N (unbiased sample
    covariance over paths, divided by N). D = (L, L t_L, L t_L^2) is an exactly
    known part (line of sight) that shifts m but adds no variance.
      H0       = a                        (= integral of h dt)
      tau0     = b / a                    (= integral of t h dt / H0)
      tau_rms  = sqrt(c/a - (b/a)^2)      (power-weighted RMS delay spread)
    Standard errors by the delta method, se = sqrt(g^T C g), g the gradient
    w.r.t. (a, b, c). For tau_rms the error is capped at sqrt(se(tau_rms^2))
    (|sqrt x - sqrt y| <= sqrt|x - y|), which matters only when tau_rms is no
    bigger than its own uncertainty (e.g. 0 for a pure-LOS link).
    Vectorized over leading (link) axes: s1 (..., 3), s2 (..., 3, 3),
    n_paths scalar or broadcastable to s1[..., 0].
    Where H0 = 0 (unreachable): dc_gain 0, dc_gain_stderr 0, delays and their
    errors NaN. With N < 2 all stderrs are NaN (except for H0 = 0).
    """
    s1 = np.asarray(s1, float)
    s2 = np.asarray(s2, float)
    n = np.broadcast_to(np.asarray(n_paths, float), s1.shape[:-1])
    n_ok = n >= 2
    with np.errstate(all="ignore"):
        nn = _safe(n, n > 0)[..., None]
        mu = np.where(n[..., None] > 0, s1 / nn, 0.0)
        cov = s2 - nn[..., None] * mu[..., :, None] * mu[..., None, :]
        cov = cov / (_safe(n, n_ok) - 1)[..., None, None] / nn[..., None]
        cov = np.where(n_ok[..., None, None], cov, np.nan)
    m = mu if deterministic is None else mu + np.asarray(deterministic, float)
    return delay_metrics_from_moments(m, cov)


def delay_metrics_from_moments(m, cov) -> dict:
    """As `delay_metrics`, from the mean m = (a, b, c) (..., 3) and its covariance (..., 3, 3).

    Independent estimators of the same link (e.g. forward and backward runs of
    algorithm 4) combine by adding their means and their covariances first.
    """
    m = np.asarray(m, float)
    cov = np.asarray(cov, float)
    n_ok = np.all(np.isfinite(cov), axis=(-1, -2))
    with np.errstate(all="ignore"):
        a, b, c = m[..., 0], m[..., 1], m[..., 2]
        reach = a > 0
        sa = _safe(a, reach)
        tau0 = b / sa
        v = c / sa - tau0**2
        # below the rounding of the difference (a single arrival: c/a = (b/a)^2 up to an ulp) the spread is 0, not
        # ~1e-16 s (which made max_bit_rate_bps ~1e14 bit/s at some line-of-sight map points)
        v = np.where(v > 8.0 * np.finfo(float).eps * np.abs(c / sa), v, 0.0)
        zero = np.zeros_like(a)

        def se(g):
            q = np.einsum("...i,...ij,...j->...", g, cov, g)
            return np.sqrt(np.maximum(q, 0.0))

        se_a = np.where(n_ok, np.sqrt(np.maximum(cov[..., 0, 0], 0.0)), np.nan)
        se_t0 = se(np.stack([-tau0 / sa, 1.0 / sa, zero], -1))
        se_v = se(np.stack([(tau0**2 - v) / sa, -2.0 * tau0 / sa, 1.0 / sa], -1))
        rms = np.sqrt(v)
        cap = np.sqrt(se_v)
        use_delta = 2.0 * rms * cap > se_v
        se_rms = np.where(use_delta, se_v / _safe(2.0 * rms, use_delta), cap)
    nan = np.nan
    return {
        "dc_gain": np.where(reach, a, 0.0),
        "dc_gain_stderr": np.where(reach, se_a, 0.0),
        "mean_delay_s": np.where(reach, tau0, nan),
        "mean_delay_s_stderr": np.where(reach, se_t0, nan),
        "rms_delay_spread_s": np.where(reach, rms, nan),
        "rms_delay_spread_s_stderr": np.where(reach, se_rms, nan),
    }


def path_loss_db(dc_gain):
    """Optical path loss PL = -10 log10(H0) in dB; NaN where H0 <= 0 or NaN."""
    h = np.asarray(dc_gain, float)
    ok = h > 0
    with np.errstate(all="ignore"):
        out = np.where(ok, -10.0 * np.log10(_safe(h, ok)), np.nan)
    return out[()]


def _centres_widths(t_edges):
    e = np.asarray(t_edges, float)
    if e.ndim != 1 or e.size < 2 or np.any(np.diff(e) <= 0):
        raise ValueError("t_edges must be a strictly increasing 1-D array")
    return 0.5 * (e[1:] + e[:-1]), np.diff(e)


def rms_delay_spread_h2(t_edges, power_per_bin):
    """h^2-weighted mean delay and RMS delay spread from a binned response.

    h_k = P_k / dt_k (1/s) on bins with centres t_k; with the midpoint rule
      tau0_h2    = sum t_k h_k^2 dt_k / sum h_k^2 dt_k
      tau_rms_h2 = sqrt(sum (t_k - tau0_h2)^2 h_k^2 dt_k / sum h_k^2 dt_k).
    The weights P_k^2/dt_k depend on the bin width: a discrete arrival (e.g. the
    LOS) gets weight P^2/dt, so both figures change with the binning; report
    the bin width with them. power_per_bin (..., n_bins); returns arrays
    (scalars for 1-D input), NaN where the response is all zero.
    """
    t, dt = _centres_widths(t_edges)
    p = np.asarray(power_per_bin, float)
    w = p**2 / dt
    s0 = w.sum(-1)
    ok = s0 > 0
    with np.errstate(all="ignore"):
        s0s = _safe(s0, ok)
        tau0 = (w * t).sum(-1) / s0s
        var = (w * (t - tau0[..., None]) ** 2).sum(-1) / s0s
        rms = np.sqrt(np.maximum(var, 0.0))
    return np.where(ok, tau0, np.nan)[()], np.where(ok, rms, np.nan)[()]


def bandwidth_3db(t_edges, power_per_bin, oversample: int = 8) -> float | None | np.ndarray:
    """Electrical 3 dB bandwidth of the optical channel, in Hz.

    H(f) = sum_k P_k exp(-2 pi i f t_k) (t_k bin centres); returns the smallest
    f > 0 with |H(f)|^2 = |H(0)|^2 / 2. |H|^2 is sampled by a zero-padded FFT
    (>= `oversample` x the response length) up to the Nyquist frequency
    1/(2 dt); the first crossing is refined by regula falsi on the continuous sum
    to ~1e-12 relative. Returns None (never inf) if |H|^2 stays above the
    threshold up to Nyquist (e.g. a single-bin, pure-LOS response) or if the
    response is all zero. Bins must be uniform. power_per_bin (n_bins,) gives a
    float or None; (..., n_bins) an array with NaN for None, every row at once
    (the jackknife's replicates).
    """
    t, dt = _centres_widths(t_edges)
    if not np.allclose(dt, dt[0], rtol=1e-6, atol=0.0):
        raise ValueError("bandwidth_3db needs uniform bins")
    p = np.asarray(power_per_bin, float)
    if p.shape[-1:] != t.shape:
        raise ValueError("power_per_bin must have one value per bin")
    f3 = _bandwidth_rows(t, float(dt[0]), p.reshape(-1, t.size), oversample).reshape(p.shape[:-1])
    if p.ndim == 1:
        return None if np.isnan(f3) else float(f3)
    return f3


#: Most FFT points (rows x grid) `_bandwidth_rows` transforms at once (~32 MiB of complex output)
FFT_ELEMENTS = 1 << 21


def _bandwidth_rows(t, dt: float, p, oversample: int) -> np.ndarray:
    """`bandwidth_3db` of each row of p (m, n_bins), NaN where there is none: one FFT and one Illinois
    regula falsi for all rows, on one grid: the FFT of the rows' common support (one row: its own). A row
    inside a wider support gets a finer grid, which may find a dip of |H|^2 just under the threshold that
    its own grid steps over (the jackknife's replicates are all evaluated on their total's grid)."""
    out = np.full(len(p), np.nan)
    h0 = p.sum(-1)
    rows = np.flatnonzero(h0 > 0)
    if not len(rows):
        return out
    p, thr = p[rows], 0.5 * h0[rows] ** 2
    nz = np.flatnonzero(p.any(axis=0))  # the support of all rows (one row: its own)
    p, tk = p[:, nz[0] : nz[-1] + 1], t[nz[0] : nz[-1] + 1] - t[nz[0]]
    m_fft = 1 << int(np.ceil(np.log2(max(oversample * p.shape[-1], 64))))
    per_chunk = max(1, FFT_ELEMENTS // m_fft)  # rows at once: memory bounded whatever the window's bins
    for lo in range(0, len(rows), per_chunk):
        out[rows[lo : lo + per_chunk]] = _bandwidth_on_grid(
            p[lo : lo + per_chunk], thr[lo : lo + per_chunk], tk, m_fft, dt
        )
    return out


def _bandwidth_on_grid(p, thr, tk, m_fft: int, dt: float) -> np.ndarray:
    """The first f > 0 with |H(f)|^2 = thr of each row of p (m, k) at delays tk (k,), NaN where |H|^2 stays
    above it up to Nyquist: the FFT grid of m_fft points brackets it, the Illinois regula falsi refines it."""
    out = np.full(len(p), np.nan)
    mag2 = np.abs(np.fft.rfft(p, m_fft, axis=-1)) ** 2  # f_j = j / (m_fft dt), j <= m_fft/2
    below = mag2[:, 1:] <= thr[:, None]
    crossing = below.any(axis=1)
    rows, p, thr = np.flatnonzero(crossing), p[crossing], thr[crossing]
    if not len(rows):
        return out
    j = below[crossing].argmax(axis=1) + 1
    df = 1.0 / (m_fft * dt)
    lo, hi = (j - 1) * df, j * df

    def g(f, at):
        return _power_at(p[at], f[:, None] * tk) - thr[at]

    every = np.arange(len(rows))
    glo, ghi, side = g(lo, every), g(hi, every), np.zeros(len(rows))  # Illinois regula falsi
    grid = (glo <= 0) | (ghi >= 0)  # the FFT grid hit the threshold
    out[rows[grid]] = np.where(glo <= 0, lo, hi)[grid]
    live = ~grid
    for _ in range(100):
        live &= (ghi != 0) & (hi - lo > 1e-13 * hi)
        at = np.flatnonzero(live)
        if not len(at):
            break
        a, b, ga, gb, sd = lo[at], hi[at], glo[at], ghi[at], side[at]
        x = b - gb * (b - a) / (gb - ga)
        x = np.where((a < x) & (x < b), x, 0.5 * (a + b))
        gx = g(x, at)
        up = gx > 0  # the root lies above x: x becomes lo (Illinois: halve ghi on a repeated side)
        lo[at], glo[at] = np.where(up, x, a), np.where(up, gx, np.where(sd == 1, 0.5 * ga, ga))
        hi[at], ghi[at] = np.where(up, b, x), np.where(up, np.where(sd == -1, 0.5 * gb, gb), gx)
        side[at] = np.where(up, -1.0, 1.0)
    refined = ~grid
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.where(ghi == 0, hi, lo - glo * (hi - lo) / (ghi - glo))
    out[rows[refined]] = root[refined]
    return out


def _power_at(p, cycles) -> np.ndarray:
    """|sum_k p_k exp(-2 pi i x_k)|^2 per row, x = `cycles` (f t_k), from one float64 tangent per term:
    with u the fractional part of x and tau = tan(pi (u - 1/2)) (half-angle substitution about pi),
        cos 2 pi x = 1 - 2 / (1 + tau^2),   sin 2 pi x = -2 tau / (1 + tau^2).
    numpy's complex exponential and float64 cos/sin are not vectorized (~20 and ~8 ns per term here)."""
    tau = cycles - np.floor(cycles)
    tau -= 0.5
    tau *= np.pi
    np.tan(tau, out=tau)
    w = tau * tau
    w += 1.0
    np.divide(p, w, out=w)  # p / (1 + tau^2)
    tau *= w  # p tau / (1 + tau^2)
    re = p.sum(axis=-1) - 2.0 * w.sum(axis=-1)  # sum p cos(2 pi x)
    im = 2.0 * tau.sum(axis=-1)  # -sum p sin(2 pi x)
    return re * re + im * im


def jackknife(estimator: Callable, groups, n_per_group=None, vectorized: bool = False):
    """Delete-one(-group) jackknife: (estimator(total), stderr).

    groups (G, ...) holds per-group tallies (e.g. power per bin summed over the
    group's paths); T = sum_g groups[g]. Replicate j uses the other groups,
    rescaled to the full sample size, T_(j) = (T - T_j) N / (N - n_j), so an
    estimator may divide by the total path count N (per-path means) or be
    scale-invariant (h^2 delay spread, bandwidth). With equal groups
      var = (G - 1)/G sum_j (theta_(j) - mean theta_(.))^2;
    with unequal n_per_group the delete-m_j jackknife (Busing et al. 1999).
    The value is the plug-in estimate (not bias-corrected). The estimator may
    return a scalar, an array or None (mapped to NaN); stderr NaN if G < 2
    or any replicate is NaN. `vectorized`: the estimator maps a stack (m, ...)
    of tallies to (m, ...) values (NaN for none) and runs once for all replicates.
    """
    groups = np.asarray(groups, float)
    n_g = groups.shape[0]
    nj = np.ones(n_g) if n_per_group is None else np.broadcast_to(np.asarray(n_per_group, float), (n_g,))

    def est(x):
        r = estimator(x)
        return np.asarray(np.nan if r is None else r, float)

    total = groups.sum(0)
    n_tot = nj.sum()
    if vectorized and n_g >= 2:
        scale = (n_tot / (n_tot - nj)).reshape((-1,) + (1,) * (groups.ndim - 1))
        values = est(np.concatenate([total[None], (total - groups) * scale]))
        theta, reps = values[0], values[1:]
    else:
        theta = est(total[None])[0] if vectorized else est(total)
    if n_g < 2:
        return theta[()], np.full_like(theta, np.nan)[()]
    if not vectorized:
        reps = np.stack([est((total - groups[j]) * (n_tot / (n_tot - nj[j]))) for j in range(n_g)])
    hj = (n_tot / nj).reshape((-1,) + (1,) * theta.ndim)
    wj = (1.0 - nj / n_tot).reshape(hj.shape)
    with np.errstate(all="ignore"):
        theta_j = n_g * theta - (wj * reps).sum(0)
        pseudo = hj * theta - (hj - 1.0) * reps
        var = ((pseudo - theta_j) ** 2 / (hj - 1.0)).sum(0) / n_g
        se = np.sqrt(np.maximum(var, 0.0))
    return theta[()], se[()]


def bin_stderr(groups, n_per_group):
    """Batch-means standard error of the mean power per path, per bin.

    groups (G, ...): per-group sums over n_g paths (scalar or (G,)). The
    estimate is x = sum_g T_g / N, N = sum_g n_g, and
      se^2 = G/(G - 1) sum_g (T_g - n_g x)^2 / N^2,
    i.e. std(T_g/n_g, ddof=1)/sqrt(G) for equal groups. NaN if G < 2.
    """
    groups = np.asarray(groups, float)
    n_g = groups.shape[0]
    nj = np.broadcast_to(np.asarray(n_per_group, float), (n_g,))
    nj = nj.reshape((-1,) + (1,) * (groups.ndim - 1))
    if n_g < 2:
        return np.full(groups.shape[1:], np.nan)[()]
    n_tot = nj.sum()
    x = groups.sum(0) / n_tot
    var = n_g / (n_g - 1.0) * ((groups - nj * x) ** 2).sum(0) / n_tot**2
    return np.sqrt(var)[()]
