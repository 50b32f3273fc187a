"""Tests for engine.results.metrics against closed-form references and simulation."""

import warnings

import numpy as np
import pytest

from owcsim.engine.results.metrics import (
    bandwidth_3db,
    bin_stderr,
    delay_metrics,
    jackknife,
    path_loss_db,
    rms_delay_spread_h2,
)

NS = 1e-9
KEYS = ["dc_gain", "mean_delay_s", "rms_delay_spread_s"]


def tallies(x):
    """(..., n, 3) per-path (a, b, c) -> (n, S1, S2) as the engine keeps them."""
    return x.shape[-2], x.sum(-2), np.einsum("...ni,...nj->...ij", x, x)


def per_path(w, t):
    """Per-path (a, b, c) from contributions w, t of shape (..., n, k)."""
    return np.stack([w.sum(-1), (w * t).sum(-1), (w * t * t).sum(-1)], -1)


def random_paths(rng, shape, n, k=3):
    """Paths with k contribution slots, each present with prob. 1/2; ~1/8 of
    paths carry nothing (unreached). Delays 10 ns + Gamma(2, 4 ns)."""
    w = rng.exponential(1e-6, shape + (n, k)) * (rng.random(shape + (n, k)) < 0.5)
    t = 10 * NS + rng.gamma(2.0, 4 * NS, shape + (n, k))
    return per_path(w, t)


# ---------------------------------------------------------------- delay_metrics
def test_two_tap_closed_form():
    p1, p2, t1, t2 = 3e-6, 1e-6, 10 * NS, 25 * NS
    x = np.tile([p1 + p2, p1 * t1 + p2 * t2, p1 * t1**2 + p2 * t2**2], (5, 1))
    r = delay_metrics(*tallies(x))
    tau0 = (p1 * t1 + p2 * t2) / (p1 + p2)
    rms = abs(t2 - t1) * np.sqrt(p1 * p2) / (p1 + p2)
    assert r["dc_gain"] == pytest.approx(p1 + p2, rel=1e-12)
    assert r["mean_delay_s"] == pytest.approx(tau0, rel=1e-12)
    assert r["rms_delay_spread_s"] == pytest.approx(rms, rel=1e-6)
    assert path_loss_db(r["dc_gain"]) == pytest.approx(-10 * np.log10(p1 + p2))
    # identical paths: no sampling error
    for k in KEYS:
        assert r[k + "_stderr"] == pytest.approx(0.0, abs=1e-6 * r[k])


def test_a_single_arrival_has_zero_spread_whatever_the_rounding():
    """c/a - (b/a)^2 of one arrival is 0 up to an ulp: the spread is 0 (not ~1e-16 s, a 1e14 bit/s max_bit_rate)."""
    from owcsim.engine.results.metrics import delay_metrics_from_moments

    a = np.geomspace(1e-9, 1e-4, 40)[:, None]
    t = np.linspace(3.0, 30.0, 50)[None, :] * NS
    m = np.stack(np.broadcast_arrays(a, a * t, a * t * t), -1)
    rms = delay_metrics_from_moments(m, np.zeros(m.shape + (3,)))["rms_delay_spread_s"]
    assert np.all(rms == 0.0)
    t1, t2 = 10 * NS, 10.002 * NS  # two equal arrivals 2 ps apart: a spread of 1 ps stays
    two = delay_metrics_from_moments(np.array([2.0, t1 + t2, t1**2 + t2**2]), np.zeros((3, 3)))
    assert two["rms_delay_spread_s"] == pytest.approx(1e-12, rel=1e-3)


def test_dc_gain_stderr_is_sample_stderr():
    rng = np.random.default_rng(1)
    x = random_paths(rng, (), 500)
    r = delay_metrics(*tallies(x))
    assert r["dc_gain"] == pytest.approx(x[:, 0].mean(), rel=1e-12)
    assert r["dc_gain_stderr"] == pytest.approx(x[:, 0].std(ddof=1) / np.sqrt(len(x)), rel=1e-9)
    # delta method for tau0 equals the textbook ratio-estimator stderr
    tau0 = x[:, 1].sum() / x[:, 0].sum()
    resid = x[:, 1] - tau0 * x[:, 0]
    se = resid.std(ddof=1) / np.sqrt(len(x)) / x[:, 0].mean()
    assert r["mean_delay_s_stderr"] == pytest.approx(se, rel=1e-9)


def test_vectorized_over_link_axes():
    rng = np.random.default_rng(2)
    x = random_paths(rng, (2, 3), 200)
    r = delay_metrics(*tallies(x))
    for i in range(2):
        for j in range(3):
            rij = delay_metrics(*tallies(x[i, j]))
            for k in r:
                assert r[k].shape == (2, 3)
                assert r[k][i, j] == pytest.approx(rij[k], rel=1e-12)


@pytest.mark.parametrize("los", [False, True])
def test_delta_method_stderr_matches_replicate_spread(los):
    """2000 independent data sets of 1000 paths: the spread of each estimate
    across data sets must match the mean reported stderr within 10 %."""
    rng = np.random.default_rng(12345)
    x = random_paths(rng, (2000,), 1000)
    L, tl = 2e-6, 8 * NS
    d = np.array([L, L * tl, L * tl**2]) if los else None
    r = delay_metrics(*tallies(x), deterministic=d)
    for k in KEYS:
        spread = r[k].std(ddof=1)
        reported = r[k + "_stderr"].mean()
        assert reported == pytest.approx(spread, rel=0.10), k


def test_deterministic_part_shifts_means_not_errors():
    rng = np.random.default_rng(3)
    x = random_paths(rng, (), 400)
    L, tl = 5e-6, 9 * NS
    d = np.array([L, L * tl, L * tl**2])
    with_d = delay_metrics(*tallies(x), deterministic=d)
    plain = delay_metrics(*tallies(x))
    # D is a constant added to every path: same as shifting each sample by D,
    # which moves the means and leaves the sample covariance unchanged
    shifted = delay_metrics(*tallies(x + d))
    for k in with_d:
        assert with_d[k] == pytest.approx(shifted[k], rel=1e-9), k
    assert with_d["dc_gain"] == pytest.approx(plain["dc_gain"] + L, rel=1e-12)
    assert with_d["dc_gain_stderr"] == pytest.approx(plain["dc_gain_stderr"], rel=1e-12)
    # pure LOS (no Monte Carlo power): exact, zero error, zero spread
    los = delay_metrics(10, np.zeros(3), np.zeros((3, 3)), deterministic=d)
    assert los["mean_delay_s"] == pytest.approx(tl)
    assert los["rms_delay_spread_s"] == 0.0
    assert all(los[k + "_stderr"] == 0.0 for k in KEYS)


def test_unreachable_and_degenerate_inputs_are_warning_and_inf_free():
    rng = np.random.default_rng(4)
    x = random_paths(rng, (3,), 50)
    x[1] = 0.0  # link 1 never reached
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = delay_metrics(*tallies(x))
        r0 = delay_metrics(0, np.zeros((2, 3)), np.zeros((2, 3, 3)))
        r1 = delay_metrics(1, x[0, 0], np.outer(x[0, 0], x[0, 0]))
        pl = path_loss_db(np.array([0.0, 1e-6, np.nan]))
        h2 = rms_delay_spread_h2(np.arange(5.0) * NS, np.zeros(4))
        bw = bandwidth_3db(np.arange(5.0) * NS, np.zeros(4))
        jk = jackknife(lambda s: bandwidth_3db(np.arange(5.0) * NS, s), np.zeros((3, 4)))
        bs = bin_stderr(np.zeros((1, 4)), 10)
    for res in (r, r0, r1):
        assert not any(np.isinf(v).any() for v in res.values())
    assert r["dc_gain"][1] == 0.0 and r["dc_gain_stderr"][1] == 0.0
    for k in KEYS[1:]:
        assert np.isnan(r[k][1]) and np.isnan(r[k + "_stderr"][1])
        assert np.isfinite(r[k][[0, 2]]).all()
    assert (r0["dc_gain"] == 0).all() and np.isnan(r0["mean_delay_s"]).all()
    assert np.isfinite(r1["mean_delay_s"]) and np.isnan(r1["dc_gain_stderr"])
    assert np.isnan(pl[0]) and pl[1] == pytest.approx(60.0) and np.isnan(pl[2])
    assert np.isnan(h2[0]) and np.isnan(h2[1]) and bw is None
    assert np.isnan(jk[0]) and np.isnan(jk[1]) and np.isnan(bs).all()


# ------------------------------------------------------------ binned response
def two_tap_bins(p1, p2, t1, t2, dt):
    edges = np.arange(0.0, t2 + 5 * dt, dt)
    p = np.zeros(edges.size - 1)
    p[int(t1 / dt)] += p1
    p[int(t2 / dt)] += p2
    return edges, p, (int(t1 / dt) + 0.5) * dt, (int(t2 / dt) + 0.5) * dt


def test_h2_two_tap_closed_form_and_bin_width_dependence():
    p1, p2 = 3e-6, 1e-6
    edges, p, t1, t2 = two_tap_bins(p1, p2, 10 * NS, 25 * NS, 0.1 * NS)
    tau0, rms = rms_delay_spread_h2(edges, p)
    assert tau0 == pytest.approx((t1 * p1**2 + t2 * p2**2) / (p1**2 + p2**2), rel=1e-12)
    assert rms == pytest.approx(abs(t2 - t1) * p1 * p2 / (p1**2 + p2**2), rel=1e-12)
    # widen the bin of tap 1 by 4x: its h^2 weight p1^2/dt drops 4x
    e2 = np.array([0.0, 4.0, 20.0, 21.0]) * NS
    tau0, rms = rms_delay_spread_h2(e2, [p1, 0.0, p2])
    w1, w2, c1, c2 = p1**2 / 4, p2**2 / 1, 2 * NS, 20.5 * NS
    assert tau0 == pytest.approx((w1 * c1 + w2 * c2) / (w1 + w2), rel=1e-12)
    assert rms == pytest.approx(abs(c2 - c1) * np.sqrt(w1 * w2) / (w1 + w2), rel=1e-12)
    # vectorized over leading axes
    t0v, rv = rms_delay_spread_h2(edges, np.stack([p, 2 * p, np.zeros_like(p)]))
    assert rv[0] == pytest.approx(rv[1]) and np.isnan(rv[2])


def exponential_pdp(T, dt, span=40):
    edges = np.arange(0.0, span * T + dt / 2, dt)
    return edges, np.exp(-edges[:-1] / T) * (1.0 - np.exp(-dt / T))


def test_exponential_profile():
    T, dt = 10 * NS, 0.05 * NS
    edges, p = exponential_pdp(T, dt)
    tc = 0.5 * (edges[1:] + edges[:-1])
    x = np.array([p.sum(), (p * tc).sum(), (p * tc**2).sum()])
    r = delay_metrics(2, 2 * x, 2 * np.outer(x, x))
    assert r["dc_gain"] == pytest.approx(1.0, rel=1e-9)
    assert r["rms_delay_spread_s"] == pytest.approx(T, rel=1e-4)
    assert r["mean_delay_s"] == pytest.approx(T, rel=1e-3)
    tau0_h2, rms_h2 = rms_delay_spread_h2(edges, p)  # h^2 ~ exp(-2t/T)
    assert tau0_h2 == pytest.approx(T / 2, rel=1e-3)
    assert rms_h2 == pytest.approx(T / 2, rel=1e-4)
    f3 = bandwidth_3db(edges, p)
    # |H|^2 = 1/(1 + (2 pi f T)^2) -> 1/(2 pi T); exact for the binned profile:
    # |H|^2 = (1-q)^2 / (1 - 2 q cos(2 pi f dt) + q^2), q = exp(-dt/T)
    q = np.exp(-dt / T)
    f_exact = np.arccos((1 + q**2 - 2 * (1 - q) ** 2) / (2 * q)) / (2 * np.pi * dt)
    assert f3 == pytest.approx(f_exact, rel=1e-9)
    assert f3 == pytest.approx(1 / (2 * np.pi * T), rel=1e-3)


def test_bandwidth_two_taps_and_los():
    dt = 0.1 * NS
    edges, p, t1, t2 = two_tap_bins(1.0, 1.0, 10 * NS, 25 * NS, dt)
    # |H|^2 = |H0|^2 cos^2(pi f (t2 - t1)) -> f3 = 1 / (4 (t2 - t1))
    assert bandwidth_3db(edges, p) == pytest.approx(1 / (4 * (t2 - t1)), rel=1e-9)
    p1, p2 = 1.0, 0.5
    edges, p, t1, t2 = two_tap_bins(p1, p2, 10 * NS, 25 * NS, dt)
    cosx = ((p1 + p2) ** 2 / 2 - p1**2 - p2**2) / (2 * p1 * p2)
    f = np.arccos(cosx) / (2 * np.pi * (t2 - t1))
    assert bandwidth_3db(edges, p) == pytest.approx(f, rel=1e-9)
    # weak echo: the notch never reaches -3 dB -> None
    edges, p, _, _ = two_tap_bins(1.0, 0.1, 10 * NS, 25 * NS, dt)
    assert bandwidth_3db(edges, p) is None
    # pure LOS: one bin, flat |H| up to Nyquist
    assert bandwidth_3db([0.0, dt], [1e-6]) is None
    e = np.arange(0.0, 100.5 * dt, dt)
    los = np.zeros(100)
    los[37] = 1e-6
    assert bandwidth_3db(e, los) is None


# ------------------------------------------------------- group-based stderrs
def test_jackknife_of_mean_equals_batch_means():
    rng = np.random.default_rng(5)
    groups = rng.exponential(1.0, (12, 7)) * 40
    n = 40
    val, se = jackknife(lambda s: s / (12 * n), groups)
    assert val == pytest.approx(groups.sum(0) / (12 * n), rel=1e-12)
    ref = (groups / n).std(0, ddof=1) / np.sqrt(12)
    assert bin_stderr(groups, n) == pytest.approx(ref, rel=1e-12)
    assert se == pytest.approx(ref, rel=1e-10)
    # unequal groups: jackknife of a scale-invariant ratio stays finite/positive
    nj = rng.integers(20, 60, 12)
    v, s = jackknife(lambda s: s[1] / s[0], groups, n_per_group=nj)
    assert v == pytest.approx(groups[:, 1].sum() / groups[:, 0].sum())
    assert 0 < s < np.inf
    assert np.isnan(jackknife(lambda s: s.sum(), groups[:1])[1])


def test_jackknife_stderr_matches_replicate_spread():
    """h^2 delay spread and 3 dB bandwidth from 20 groups of 100 paths over
    300 independent data sets: mean jackknife stderr vs spread within 15 %."""
    rng = np.random.default_rng(777)
    n_rep, G, n, nb, dt = 300, 20, 100, 64, 1 * NS
    edges = np.arange(nb + 1) * dt
    k = np.minimum(rng.geometric(0.15, (n_rep, G, n)) - 1, nb - 1)
    w = rng.exponential(1.0, (n_rep, G, n)) + 1.5 * (k == 2)
    idx = (np.arange(n_rep * G)[:, None] * nb + k.reshape(n_rep * G, n)).ravel()
    groups = np.bincount(idx, w.ravel(), n_rep * G * nb).reshape(n_rep, G, nb)
    h2 = np.array([jackknife(lambda s: rms_delay_spread_h2(edges, s)[1], g) for g in groups])
    bw = np.array([jackknife(lambda s: bandwidth_3db(edges, s), g) for g in groups])
    pb = np.array([bin_stderr(g, n) for g in groups])
    mean_p = groups.sum(1) / (G * n)
    assert h2[:, 1].mean() == pytest.approx(h2[:, 0].std(ddof=1), rel=0.15)
    assert bw[:, 1].mean() == pytest.approx(bw[:, 0].std(ddof=1), rel=0.15)
    assert pb.mean(0)[:8] == pytest.approx(mean_p.std(0, ddof=1)[:8], rel=0.15)


def test_bandwidth_rows_and_vectorized_jackknife_match_one_row_at_a_time():
    """Rows at once (the jackknife's replicates in one call) give each row's own bandwidth, None as NaN,
    and the vectorized jackknife the loop's value and error."""
    rng = np.random.default_rng(11)
    nb = 200
    edges = np.arange(nb + 1) * NS
    k = np.minimum(rng.geometric(0.08, (16, 300)) - 1, nb - 1)
    groups = np.bincount((np.arange(16)[:, None] * nb + k).ravel(), rng.exponential(1.0, k.size), 16 * nb)
    groups = groups.reshape(16, nb)
    rows = np.vstack([groups, np.zeros(nb), np.eye(1, nb, 5)[0]])  # + an empty row and a pure one-bin row (None)
    want = [bandwidth_3db(edges, r) for r in rows]
    got = bandwidth_3db(edges, rows)
    assert got.shape == (18,) and want[-2] is None and want[-1] is None and np.isnan(got[-2:]).all()
    np.testing.assert_allclose(got[:-2], np.array(want[:-2], float), rtol=1e-12)
    for est in (lambda s: bandwidth_3db(edges, s), lambda s: rms_delay_spread_h2(edges, s)[1]):
        loop = jackknife(est, groups, n_per_group=np.arange(16) + 10)
        rows_at_once = jackknife(est, groups, n_per_group=np.arange(16) + 10, vectorized=True)
        np.testing.assert_allclose(rows_at_once, loop, rtol=1e-10)
        assert loop[1] > 0  # a real error to compare


def test_bandwidth_rows_in_chunks_of_bounded_memory_give_the_same_values(monkeypatch):
    """Rows are transformed in chunks of at most FFT_ELEMENTS grid points (a long window's jackknife stays
    bounded in memory); chunking changes no value."""
    from owcsim.engine.results import metrics

    rng = np.random.default_rng(12)
    nb = 300
    edges = np.arange(nb + 1) * NS
    k = np.minimum(rng.geometric(0.05, (17, 400)) - 1, nb - 1)
    rows = np.bincount((np.arange(17)[:, None] * nb + k).ravel(), rng.exponential(1.0, k.size), 17 * nb)
    rows = rows.reshape(17, nb)
    whole = bandwidth_3db(edges, rows)
    assert np.isfinite(whole).sum() >= 10  # most rows have a crossing (the comparison has something to compare)
    monkeypatch.setattr(metrics, "FFT_ELEMENTS", 1)  # one row per chunk
    np.testing.assert_array_equal(bandwidth_3db(edges, rows), whole)
