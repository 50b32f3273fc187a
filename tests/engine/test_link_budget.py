"""engine.results.link_budget against hand computations (Komine & Nakagawa 2004's room and receiver).

Each expected value is written out from the formula and the paper's parameters, or from an
independent reference (plain loops, numerical convolution, numerical Gaussian tail), never
from the code under test.
"""

import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from owcsim.engine.results.link_budget import (
    IsiSplit,
    LinkBudget,
    ber_ook,
    illuminance_los,
    isi_split,
    link_budget_from_spec,
    luminous_flux_from_intensity,
    luminous_intensity_center,
    max_bit_rate,
    noise_variances,
    power_dbm,
    received_power,
    snr,
    to_db,
)
from owcsim.schemas.link_budget import IsiSplit as IsiSplitSpec
from owcsim.schemas.link_budget import LinkBudgetSpec

ROOT = Path(__file__).resolve().parents[2]
Q, K = 1.602176634e-19, 1.380649e-23  # exact SI values [C], [J/K]
M70 = -math.log(2) / math.log(math.cos(math.radians(70)))  # 0.64606, Komine's semi-angle 70 deg
I0 = 3600 * 0.73  # Komine's luminaire: 60 x 60 LEDs of 0.73 cd [cd]
LEDS = [(1.25, 1.25), (1.25, 3.75), (3.75, 1.25), (3.75, 3.75)]
H = 3.0 - 0.85  # luminaire plane to receiver plane [m]


def komine_geometry(points):
    """(cos_phi, cos_psi, d), shape (4, n): luminaires face down, receivers face up."""
    pts = np.asarray(points, float)
    dx = pts[None, :, 0] - np.array(LEDS)[:, 0, None]
    dy = pts[None, :, 1] - np.array(LEDS)[:, 1, None]
    d = np.sqrt(dx**2 + dy**2 + H**2)
    return H / d, H / d, d


@pytest.fixture(autouse=True)
def _no_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


# --- photometry ----------------------------------------------------------------------------------


def test_lambertian_m1_flux_is_pi_times_intensity():
    # A Lambertian (m = 1) source: Phi = pi I0 (Lambert's cosine law).
    assert luminous_flux_from_intensity(100.0, 1.0) == pytest.approx(math.pi * 100.0, rel=1e-12)
    assert luminous_intensity_center(math.pi * 100.0, 1.0) == pytest.approx(100.0, rel=1e-12)


def test_komine_luminaire_intensity_flux_round_trip():
    # 2628 cd at m = 0.64606: Phi = 2 pi 2628 / 1.64606 = 10031.4 lm.
    flux = luminous_flux_from_intensity(I0, M70)
    assert flux == pytest.approx(10031.36, rel=1e-5)
    back = luminous_intensity_center(np.array([flux, 2 * flux]), np.array([M70, M70]))
    np.testing.assert_allclose(back, [I0, 2 * I0], rtol=1e-12)


def test_illuminance_hand_values_komine_room():
    # Centre (2.5, 2.5): all 4 luminaires at d^2 = 2 * 1.25^2 + 2.15^2 = 7.7475 m^2, cos = 2.15 / d.
    d2 = 2 * 1.25**2 + H**2
    centre = 4 * I0 * (H / math.sqrt(d2)) ** (M70 + 1) / d2
    assert centre == pytest.approx(887.0, abs=0.1)  # the hand figure of docs/link-budget.md
    # Corner (0, 0): distances^2 = 1.25^2 * 2, 1.25^2 + 3.75^2 (twice), 3.75^2 * 2, each + 2.15^2.
    corner = sum(I0 * (H / math.sqrt(r2 + H**2)) ** (M70 + 1) / (r2 + H**2) for r2 in (3.125, 15.625, 15.625, 28.125))
    assert corner == pytest.approx(314.7, abs=0.1)
    e = illuminance_los(np.full(4, I0), np.full(4, M70), *komine_geometry([(2.5, 2.5, 0), (0, 0, 0)]))
    np.testing.assert_allclose(e, [centre, corner], rtol=1e-12)


def test_illuminance_equals_sum_over_leds_at_several_points():
    rng = np.random.default_rng(9)
    pts = np.column_stack([rng.uniform(0, 5, 25), rng.uniform(0, 5, 25), np.zeros(25)])
    intensities, orders = np.array([2628.0, 1000.0, 500.0, 3000.0]), np.array([M70, 1.0, 0.0, 5.0])
    got = illuminance_los(intensities, orders, *komine_geometry(pts))
    for k, (x, y, _) in enumerate(pts):  # plain loop: E = sum I0 cos^m(phi) cos(psi) / d^2
        ref = 0.0
        for (lx, ly), i0, m in zip(LEDS, intensities, orders):
            d = math.dist((x, y, 0.0), (lx, ly, H))
            ref += i0 * (H / d) ** m * (H / d) / d**2
        assert got[k] == pytest.approx(ref, rel=1e-12)
    # A grid keeps its shape: (n_tx, 5, 5) in, (5, 5) out.
    grid = [a.reshape(4, 5, 5) for a in komine_geometry(pts)]
    np.testing.assert_allclose(illuminance_los(intensities, orders, *grid), got.reshape(5, 5), rtol=1e-15)


def test_illuminance_zero_behind_blocked_or_coincident():
    i0, m = np.array([100.0, 100.0, 100.0, 100.0, 100.0]), np.array([0.0, 1.0, 1.0, 1.0, 1.0])
    # link 0: behind the transmitter (m = 0 would give cos^0 = 1 without the mask); 1: behind the
    # receiver; 2: blocked; 3: coincident; 4: a clear link at 2 m, normal incidence -> 100 / 4 = 25 lx.
    cos_phi = np.array([[-0.5], [0.8], [1.0], [1.0], [1.0]])
    cos_psi = np.array([[0.8], [-0.1], [1.0], [1.0], [1.0]])
    d = np.array([[1.0], [1.0], [1.0], [0.0], [2.0]])
    visible = np.array([[True], [True], [False], [True], [True]])
    assert illuminance_los(i0, m, cos_phi, cos_psi, d, visible) == pytest.approx([25.0])
    # A transmittance factor in [0, 1] (smoke) scales the contribution.
    assert illuminance_los(100.0, 1.0, [[1.0]], [[1.0]], [[2.0]], [[0.5]]) == pytest.approx([12.5])


# --- power -------------------------------------------------------------------------------------


def test_dbm_conversion():
    np.testing.assert_allclose(power_dbm([1e-3, 1.0, 1e-6, 2e-3]), [0.0, 30.0, -30.0, 10 * math.log10(2)], atol=1e-12)
    out = power_dbm([0.0, -1e-3, np.nan])
    assert np.isnan(out).all()
    assert np.isnan(to_db(0.0)) and to_db(100.0) == pytest.approx(20.0)


def test_received_power_komine_centre():
    # H = (m+1) A / (2 pi d^2) cos^(m+1)(phi) per luminaire, A = 1 cm^2, P_t = 3600 x 20 mW = 72 W.
    d2 = 2 * 1.25**2 + H**2
    gain_one = (M70 + 1) * 1e-4 / (2 * math.pi * d2) * (H / math.sqrt(d2)) ** (M70 + 1)
    p_hand = 4 * 72.0 * gain_one  # 6.3665e-4 W
    assert p_hand == pytest.approx(6.3665e-4, rel=1e-4)
    p = received_power(np.full(4, 72.0), np.full((4, 1), gain_one))
    assert p == pytest.approx([p_hand], rel=1e-12)
    assert power_dbm(p) == pytest.approx([10 * math.log10(p_hand / 1e-3)], rel=1e-12)
    assert power_dbm(p)[0] == pytest.approx(-1.961, abs=1e-3)
    # A blocked or out-of-view link (gain 0) adds nothing; a receiver with no link gets NaN dBm.
    p2 = received_power([72.0, 72.0], [[gain_one, 0.0], [0.0, 0.0]])
    assert p2[0] == pytest.approx(72.0 * gain_one) and p2[1] == 0.0 and np.isnan(power_dbm(p2)[1])


# --- noise, SNR, BER ---------------------------------------------------------------------------


def test_noise_terms_komine_receiver_by_hand():
    # Komine's receiver at B = R_b = 10 Mbit/s, A = 1 cm^2 (so eta A = 112 pF), P = 1 mW.
    budget = LinkBudget(noise_bandwidth=1e7, bit_rate=1e7)
    shot_sig = 2 * Q * 0.53 * 1e-3 * 1e7  # 1.698e-15 A^2
    shot_bg = 2 * Q * 5.1e-3 * 0.562 * 1e7  # 9.184e-15 A^2
    th_fb = 8 * math.pi * K * 295 / 10 * 112e-12 * 0.562 * 1e14  # 6.443e-17 A^2
    th_fet = 16 * math.pi**2 * K * 295 * 1.5 / 0.03 * 112e-12**2 * 0.0868 * 1e21  # 3.502e-17 A^2
    assert (shot_sig, shot_bg, th_fb, th_fet) == pytest.approx((1.698e-15, 9.184e-15, 6.443e-17, 3.502e-17), rel=1e-3)
    shot, thermal = noise_variances(budget, 1e-4, 1e-3)
    assert shot == pytest.approx(shot_sig + shot_bg, rel=1e-12)
    assert thermal == pytest.approx(th_fb + th_fet, rel=1e-12)
    s = snr(budget, 1e-4, 1e-3)
    assert s == pytest.approx((0.53e-3) ** 2 / (shot_sig + shot_bg + th_fb + th_fet), rel=1e-12)
    assert to_db(s) == pytest.approx(10 * math.log10(2.809e-7 / 1.0980e-14), abs=0.01)  # 74.08 dB


def test_snr_with_isi_and_area_broadcast():
    budget = LinkBudget(noise_bandwidth=1e8, bit_rate=1e8, background_current=0.0)
    area = np.array([1e-4, 4e-4])
    p_sig, p_isi = 1e-4, 2e-5
    got = snr(budget, area, p_sig, p_isi)
    for k, a in enumerate(area):  # Komine's SNR written out, I_bg = 0
        c = 1.12e-6 * a
        shot = 2 * Q * 0.53 * (p_sig + p_isi) * 1e8
        th = (
            8 * math.pi * K * 295 / 10 * c * 0.562 * 1e16
            + 16 * math.pi**2 * K * 295 * 1.5 / 0.03 * c**2 * 0.0868 * 1e24
        )
        assert got[k] == pytest.approx((0.53 * p_sig) ** 2 / (shot + th + (0.53 * p_isi) ** 2), rel=1e-12)
    # ISI power 1/5 of the signal caps the SNR near 25 (14 dB) however strong the light.
    assert snr(budget, 1e-4, 1.0, 0.2) == pytest.approx(25.0, rel=1e-3)


def test_zero_signal_gives_zero_snr_half_ber_nan_db():
    budget = LinkBudget(noise_bandwidth=1e7)
    s = snr(budget, 1e-4, np.array([0.0, np.nan]))
    assert s[0] == 0.0 and np.isnan(s[1])
    assert ber_ook(s[0]) == 0.5 and np.isnan(ber_ook(s[1]))
    assert np.isnan(to_db(s)).all()


def _gaussian_tail(x):
    """Q(x) by the trapezoid rule on exp(-u^2/2)/sqrt(2 pi) over [x, x + 12] (independent of erfc)."""
    u = np.linspace(x, x + 12.0, 200_001)
    f = np.exp(-u * u / 2) / math.sqrt(2 * math.pi)
    return float(((f[1:] + f[:-1]) / 2 * np.diff(u)).sum())


def test_ber_ook():
    # Textbook anchor: Q(6) = 9.866e-10, i.e. SNR = 36 (15.6 dB) gives BER ~ 1e-9.
    assert ber_ook(36.0) == pytest.approx(9.866e-10, rel=1e-3)
    # SNR = 10^1.5 (15 dB): Q(sqrt(31.62)) = Q(5.623) = 9.36e-9.
    assert ber_ook(10**1.5) == pytest.approx(_gaussian_tail(math.sqrt(10**1.5)), rel=1e-6)
    assert ber_ook(10**1.5) == pytest.approx(9.36e-9, rel=1e-3)
    snrs = np.array([0.0, 1.0, 4.0, 9.0, 16.0])
    np.testing.assert_allclose(ber_ook(snrs), [0.5] + [_gaussian_tail(x) for x in (1, 2, 3, 4)], rtol=1e-6)


def test_max_bit_rate():
    np.testing.assert_allclose(max_bit_rate([5e-9, 1e-9]), [20e6, 100e6], rtol=1e-12)
    assert max_bit_rate(5e-9, factor=5) == pytest.approx(40e6)
    assert np.isnan(max_bit_rate([0.0, np.nan])).all()


# --- signal / ISI split --------------------------------------------------------------------------


def test_isi_split_by_hand():
    # T = 10 ns, dt = 1 ns; power 1 W in bin 0 ([0, 1) ns), 0.5 W in bin 4, 0.25 W in bin 14.
    cir = np.zeros(20)
    cir[[0, 4, 14]] = [1.0, 0.5, 0.25]
    # WINDOW: bins 0 and 4 lie within [0, 10) ns of the first arrival, bin 14 beyond.
    assert isi_split(cir, 1e-9, 10e-9, rule=IsiSplit.WINDOW) == pytest.approx((1.5, 0.25), rel=1e-12)
    # NRZ: weight = mean of (1 - tau/T) over the bin: 1 - 0.5/10 = 0.95, 1 - 4.5/10 = 0.55, 0.
    sig = 1.0 * 0.95 + 0.5 * 0.55
    assert isi_split(cir, 1e-9, 10e-9) == pytest.approx((sig, 1.75 - sig), rel=1e-12)
    # A bin straddling T splits by its overlap (uniform power within the bin): T = 10.5 ns cuts
    # bin 10, [10, 11) ns, in half.
    one = np.zeros(12)
    one[0], one[10] = 1.0, 1.0
    assert isi_split(one, 1e-9, 10.5e-9, t_min=0.0, rule="window") == pytest.approx((1.5, 0.5), rel=1e-12)


def test_isi_split_first_arrival_and_links():
    # Two links in one call, a shifted time axis, an explicit and a default first arrival, an empty link.
    cir = np.zeros((3, 30))
    cir[0, 5], cir[0, 20] = 2.0, 1.0  # first arrival bin 5 -> second path 15 bins = 7.5 ns later
    cir[1, 8] = 1.0
    t_min, dt, period = 100e-9, 0.5e-9, 10e-9
    sig, isi = isi_split(cir, dt, period, t_min=t_min)
    w_first = 1 - 0.25 / 10  # bin 5 relative [0, 0.5) ns
    w_echo = 1 - 7.75 / 10  # bin 20 relative [7.5, 8) ns
    np.testing.assert_allclose(sig, [2 * w_first + w_echo, w_first, 0.0], rtol=1e-12)
    np.testing.assert_allclose(sig + isi, cir.sum(-1), rtol=1e-12)
    # t_first at the end of the first bin: that bin counts wholly as signal.
    sig2, _ = isi_split(cir[:1], dt, period, t_min=t_min, t_first=[t_min + 3e-9])
    assert sig2[0] == pytest.approx(2.0 + 1.0 * (1 - 7.25 / 10), rel=1e-12)


def test_nrz_split_equals_numerical_convolution_with_the_pulse():
    # Komine's form: (1/T) integral over [t0, t0 + T] of (h * rect_T)(t) dt, by brute force on a
    # fine grid (0.01 ns), against the bin-exact formula on the same CIR put in 0.5 ns bins.
    rng = np.random.default_rng(4)
    fine_dt, period = 0.01e-9, 10e-9
    h_fine = np.zeros(4000)  # 40 ns
    h_fine[:50] = 1.0 / 50  # a 0.5 ns-wide first arrival
    tail = rng.exponential(1.0, 3950) * np.exp(-np.arange(3950) * fine_dt / 6e-9)
    h_fine[50:] = 0.8 * tail / tail.sum()
    pulse = np.ones(int(round(period / fine_dt)))
    y = np.convolve(h_fine, pulse)  # received waveform of one bit, per unit amplitude
    n_t = pulse.size
    sig_ref = y[:n_t].sum() / n_t
    isi_ref = y[n_t:].sum() / n_t
    h_bins = h_fine.reshape(80, 50).sum(-1)  # 0.5 ns bins
    sig, isi = isi_split(h_bins, 0.5e-9, period)
    # Measured: 0.12 % and 0.4 %; the bins see the tail as uniform within 0.5 ns, and the reference
    # puts each 0.01 ns sample at its left edge (a 0.05 % shift). A 2-5 % error would fail.
    assert sig == pytest.approx(sig_ref, rel=2e-3)
    assert isi == pytest.approx(isi_ref, rel=1e-2)
    assert abs(isi - isi_ref) < 0.1 * abs(isi_ref - isi_split(h_bins, 0.5e-9, period, rule="window")[1])


# --- spec conversion ---------------------------------------------------------------------------


def test_link_budget_from_spec():
    lb = link_budget_from_spec(LinkBudgetSpec(bit_rate=2e7))
    assert lb == LinkBudget(noise_bandwidth=2e7, bit_rate=2e7)  # Komine's defaults, B = R_b
    assert lb.bit_period == pytest.approx(5e-8)
    lb = link_budget_from_spec(LinkBudgetSpec(bit_rate=2e7, bandwidth=3e7, isi_split="window", responsivity=0.4))
    assert (lb.noise_bandwidth, lb.bit_rate, lb.isi_split, lb.responsivity) == (3e7, 2e7, IsiSplit.WINDOW, 0.4)
    assert link_budget_from_spec(LinkBudgetSpec(bandwidth=1e6)).bit_period is None


def test_isi_enum_matches_schema():
    assert {e.value for e in IsiSplit} == {e.value for e in IsiSplitSpec}


# --- the worked example ------------------------------------------------------------------------


def test_demo_script_prints_the_hand_values():
    out = subprocess.run(
        [sys.executable, "-W", "error", str(ROOT / "examples" / "link_budget_demo.py")],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout
    v = {line.split(" = ")[0]: float(line.split(" = ")[1].split()[0]) for line in out.splitlines()}
    d2c = 2 * 1.25**2 + H**2
    p_centre = 4 * 72.0 * (M70 + 1) * 1e-4 / (2 * math.pi * d2c) * (H / math.sqrt(d2c)) ** (M70 + 1)
    assert v["center_luminous_intensity"] == 2628 and v["luminous_flux"] == pytest.approx(10031.4, abs=0.1)
    assert v["illuminance_center"] == pytest.approx(887.0, abs=0.1)
    assert v["illuminance_corner"] == pytest.approx(314.7, abs=0.1)
    assert v["illuminance_min"] == pytest.approx(314.7, abs=0.1)  # the corners, on a 5 cm grid
    assert 880 < v["illuminance_max"] < 950  # between the luminaires' peaks
    assert v["received_power_center"] == pytest.approx(p_centre, rel=1e-5)
    assert v["received_power_center_dbm"] == pytest.approx(-1.961, abs=1e-3)
    p_corner = 72.0 * sum(
        (M70 + 1) * 1e-4 / (2 * math.pi * (r2 + H**2)) * (H / math.sqrt(r2 + H**2)) ** (M70 + 1)
        for r2 in (3.125, 15.625, 15.625, 28.125)
    )
    assert v["received_power_corner"] == pytest.approx(p_corner, rel=1e-5)
    assert v["received_power_corner_dbm"] == pytest.approx(-6.461, abs=1e-3)
    shot = 2 * Q * 0.53 * p_centre * 1e7 + 2 * Q * 5.1e-3 * 0.562 * 1e7
    thermal = 6.4430e-17 + 3.5015e-17
    assert v["shot_noise_center"] == pytest.approx(shot, rel=1e-5)
    assert v["thermal_noise_center"] == pytest.approx(thermal, rel=1e-3)
    assert v["snr_center_db"] == pytest.approx(10 * math.log10((0.53 * p_centre) ** 2 / (shot + thermal)), abs=1e-3)
    # Echo of 20 % at 5-5.5 ns, T = 10 ns, 0.5 ns bins: NRZ signal = 0.975 + 0.2 * 0.475 = 1.07 of 1.2.
    assert v["nrz_signal_fraction"] == pytest.approx(1.07 / 1.2, rel=1e-5)
    assert v["window_signal_fraction"] == 1.0 and v["window_isi_fraction"] == 0.0
    assert v["rms_delay_spread"] == pytest.approx(5e-9 * math.sqrt(0.2) / 1.2, rel=1e-5)
    assert v["max_bit_rate"] == pytest.approx(1.2 / (10 * 5e-9 * math.sqrt(0.2)), rel=1e-5)
