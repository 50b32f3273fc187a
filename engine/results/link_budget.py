"""Photometry and link budget: illuminance, received power, SNR and BER of OOK-NRZ (docs/link-budget.md).

Pure numpy (scipy for erfc, imported when a BER is computed), vectorized over links / receivers; no
floating-point warnings and no inf: where a figure does not exist (no power, 0 dBm of nothing)
the arrays hold NaN, which callers map to JSON null. SI units throughout.

Reference: T. Komine and M. Nakagawa, "Fundamental analysis for visible-light communication
system using LED lights", IEEE Trans. Consumer Electronics 50(1), 100-107, 2004.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from owcsim.schemas.link_budget import IsiSplit  # one enum: the document's

__all__ = [
    "IsiSplit",
    "LinkBudget",
    "ber_ook",
    "dco_ofdm_rate",
    "ook_rate",
    "ook_required_snr",
    "shannon_rate",
    "thermal_coefficients",
    "illuminance_los",
    "isi_split",
    "link_budget_from_spec",
    "luminous_flux_from_intensity",
    "luminous_intensity_center",
    "max_bit_rate",
    "noise_variances",
    "power_dbm",
    "received_power",
    "snr",
    "to_db",
]

#: Elementary charge q [C] and Boltzmann constant k [J/K]: exact by definition of the SI (BIPM 2019), the
#: values scipy.constants gives (not imported for them: scipy costs a command's start-up, issue 10).
Q_E = 1.602176634e-19
K_B = 1.380649e-23


@dataclass(frozen=True)
class LinkBudget:
    """Receiver model of Komine & Nakagawa 2004 (mirror of schemas.link_budget.LinkBudgetSpec).

    noise_bandwidth B [Hz]; responsivity gamma [A/W]; bit_rate R_b [bit/s] or None;
    background_current I_bg [A]; temperature T_k [K]; open_loop_gain G [-];
    capacitance_per_area eta [F/m^2]; channel_noise_factor Gamma [-]; transconductance g_m [S];
    i2, i3 noise-bandwidth factors [-]; isi_split the CIR signal/ISI rule. Defaults: Komine's values.
    Multi-cell rates (engine/results/cells.py): ber_target of OOK-NRZ [-]; dco_ofdm_subcarriers N [-] and
    dco_ofdm_bias k [standard deviations] of DCO-OFDM.
    """

    noise_bandwidth: float
    responsivity: float = 0.53
    bit_rate: float | None = None
    background_current: float = 5.1e-3
    temperature: float = 295.0
    open_loop_gain: float = 10.0
    capacitance_per_area: float = 1.12e-6
    channel_noise_factor: float = 1.5
    transconductance: float = 0.03
    i2: float = 0.562
    i3: float = 0.0868
    isi_split: IsiSplit = IsiSplit.NRZ
    ber_target: float = 1e-6
    dco_ofdm_subcarriers: int = 64
    dco_ofdm_bias: float = 2.0

    @property
    def bit_period(self) -> float | None:
        """T = 1 / R_b [s], or None without a bit rate."""
        return None if self.bit_rate is None else 1.0 / self.bit_rate


def link_budget_from_spec(spec) -> LinkBudget:
    """schemas.link_budget.LinkBudgetSpec -> LinkBudget (B = bandwidth, else the bit rate)."""
    return LinkBudget(
        noise_bandwidth=spec.noise_bandwidth,
        responsivity=spec.responsivity,
        bit_rate=spec.bit_rate,
        background_current=spec.background_current,
        temperature=spec.temperature,
        open_loop_gain=spec.open_loop_gain,
        capacitance_per_area=spec.capacitance_per_area,
        channel_noise_factor=spec.channel_noise_factor,
        transconductance=spec.transconductance,
        i2=spec.noise_bandwidth_factor_i2,
        i3=spec.noise_bandwidth_factor_i3,
        isi_split=spec.isi_split,
        ber_target=spec.ber_target,
        dco_ofdm_subcarriers=spec.dco_ofdm_subcarriers,
        dco_ofdm_bias=spec.dco_ofdm_bias,
    )


# --- photometry -------------------------------------------------------------------------------


def luminous_intensity_center(luminous_flux, m):
    """Centre luminous intensity I_v(0) = (m + 1) Phi_v / (2 pi) [cd] of a Lambertian source of order m.

    From Phi_v = integral of I_v(0) cos^m(phi) over the hemisphere = 2 pi I_v(0) / (m + 1)
    (Komine & Nakagawa 2004). luminous_flux Phi_v [lm], m [-].
    """
    return (np.asarray(m, float) + 1.0) * np.asarray(luminous_flux, float) / (2.0 * math.pi)


def luminous_flux_from_intensity(center_intensity, m):
    """Luminous flux Phi_v = 2 pi I_v(0) / (m + 1) [lm]; inverse of `luminous_intensity_center`."""
    return 2.0 * math.pi * np.asarray(center_intensity, float) / (np.asarray(m, float) + 1.0)


def illuminance_los(center_intensity, m, cos_phi, cos_psi, d, visible=True):
    """Direct horizontal illuminance E = sum_tx I_v(0) cos^m(phi) cos(psi) / d^2 [lx].

    Komine & Nakagawa 2004 (E_hor). Illuminance on the receiver's plane (normal = receiver normal),
    direct light only, summed over transmitters; no field-of-view limit (a lux meter is
    cosine-corrected over the hemisphere). Arguments, transmitter axis first:
      center_intensity I_v(0) [cd] and m [-]: shape (n_tx,) (or scalars);
      cos_phi (emission angle at the transmitter), cos_psi (incidence angle at the receiver),
      d [m]: shape (n_tx, ...) e.g. (n_tx, n_rx);
      visible: bool or factor in [0, 1] of the same shape (False / 0 when blocked; exp(-sigma_t d)
      in smoke), default True.
    A link contributes 0 when cos_phi <= 0 (behind the transmitter), cos_psi <= 0 (behind the
    receiver's plane), d <= 0 or not visible. Returns shape cos_phi.shape[1:], e.g. (n_rx,).
    """
    cos_phi, cos_psi, d = (np.asarray(a, float) for a in np.broadcast_arrays(cos_phi, cos_psi, d))
    lead = (-1,) + (1,) * (cos_phi.ndim - 1)
    i0 = np.asarray(center_intensity, float).reshape(lead) if np.ndim(center_intensity) else center_intensity
    mm = np.asarray(m, float).reshape(lead) if np.ndim(m) else m
    ok = (cos_phi > 0) & (cos_psi > 0) & (d > 0)
    with np.errstate(under="ignore"):
        e = np.where(ok, i0 * np.where(ok, cos_phi, 1.0) ** mm * cos_psi / np.where(ok, d, 1.0) ** 2, 0.0)
    return (e * np.asarray(visible, float)).sum(axis=0)


# --- power ------------------------------------------------------------------------------------


def received_power(power, dc_gain):
    """Received optical power P_r = sum_tx P_t H(0) [W]; power (n_tx,) [W], dc_gain (n_tx, ...) [-]."""
    g = np.asarray(dc_gain, float)
    p = np.asarray(power, float).reshape((-1,) + (1,) * (g.ndim - 1)) if np.ndim(power) else power
    return (p * g).sum(axis=0)


def to_db(x):
    """10 log10(x) [dB]; NaN where x <= 0 or x is NaN (no -inf, no warning)."""
    x = np.asarray(x, float)
    ok = x > 0
    return np.where(ok, 10.0 * np.log10(np.where(ok, x, 1.0)), np.nan)


def power_dbm(power):
    """Optical power in dBm, 10 log10(P / 1 mW); NaN where P <= 0 (no power, no -inf)."""
    return to_db(np.asarray(power, float) / 1e-3)


# --- noise, SNR, BER --------------------------------------------------------------------------


def noise_variances(budget: LinkBudget, area, p_signal, p_isi=0.0):
    """(shot, thermal) noise variances [A^2] of Komine & Nakagawa 2004.

    sigma_shot^2    = 2 q gamma (P_signal + P_isi) B + 2 q I_bg I2 B
    sigma_thermal^2 = 8 pi k T_k / G * eta A I2 B^2 + 16 pi^2 k T_k Gamma / g_m * eta^2 A^2 I3 B^3
    area A [m^2] (photodiode; the capacitance is eta A), p_signal, p_isi [W]; all broadcast.
    """
    b, kt = budget.noise_bandwidth, K_B * budget.temperature
    a = np.asarray(area, float)
    shot = (
        2.0 * Q_E * budget.responsivity * (np.asarray(p_signal, float) + np.asarray(p_isi, float)) * b
        + 2.0 * Q_E * budget.background_current * budget.i2 * b
    )
    cap = budget.capacitance_per_area * a
    thermal = (
        8.0 * math.pi * kt / budget.open_loop_gain * cap * budget.i2 * b**2
        + 16.0 * math.pi**2 * kt * budget.channel_noise_factor / budget.transconductance * cap**2 * budget.i3 * b**3
    )
    return tuple(np.broadcast_arrays(shot, thermal))


def snr(budget: LinkBudget, area, p_signal, p_isi=0.0):
    """Electrical SNR [-] (linear) of Komine & Nakagawa 2004:

    SNR = (gamma P_signal)^2 / (sigma_shot^2 + sigma_thermal^2 + gamma^2 P_isi^2).
    Without a CIR, P_isi = 0 and P_signal is the whole received power [W]. 0 where P_signal = 0.
    """
    shot, thermal = noise_variances(budget, area, p_signal, p_isi)
    g = budget.responsivity
    return (g * np.asarray(p_signal, float)) ** 2 / (shot + thermal + (g * np.asarray(p_isi, float)) ** 2)


def ber_ook(snr_linear):
    """Bit-error rate of OOK-NRZ, BER = Q(sqrt(SNR)) = erfc(sqrt(SNR / 2)) / 2 (Komine & Nakagawa 2004).

    SNR linear [-]; 0.5 at SNR = 0; NaN stays NaN.
    """
    from scipy.special import erfc  # on first use (scipy's import time)

    return 0.5 * erfc(np.sqrt(np.maximum(np.asarray(snr_linear, float), 0.0) / 2.0))


def max_bit_rate(rms_delay_spread, factor=10.0):
    """Bit rate the delay spread allows, R_max = 1 / (factor tau_rms) [bit/s], factor 10 by default.

    Rule of thumb for OOK without equalizer: ISI is negligible while tau_rms <= T/10, i.e.
    R_b <= 1 / (10 tau_rms) (Ghassemlooy, Popoola & Rajbhandari 2019, "Optical Wireless
    Communications: System and Channel Modelling with MATLAB"; the OOK power penalty of
    Kahn & Barry 1997 grows fast beyond tau_rms/T = 0.1). rms_delay_spread [s].
    NaN where tau_rms <= 0 or NaN (a single path: no dispersion limit).
    """
    tau = np.asarray(rms_delay_spread, float)
    ok = tau > 0
    return np.where(ok, 1.0 / (factor * np.where(ok, tau, 1.0)), np.nan)


# --- signal and ISI from a binned CIR ---------------------------------------------------------


def _signal_primitive(x, period, rule: IsiSplit):
    """G(x) = integral_{-inf}^{x} w(u) du minus its value at 0, with w the signal weight of an arrival
    at u = t - t0: w = 1 for u < 0; NRZ: (1 - u/T)_+; WINDOW: 1 for u < T, else 0."""
    y = np.clip(x, 0.0, period)
    if rule is IsiSplit.NRZ:
        return np.minimum(x, 0.0) + y - y * y / (2.0 * period)
    return np.minimum(x, 0.0) + y


def _isi_primitive(x, period, rule: IsiSplit):
    """K(x) = x - G(x): the primitive of 1 - w, zero for x <= 0 (kept separate for precision)."""
    y = np.clip(x, 0.0, period)
    excess = np.maximum(x - period, 0.0)
    if rule is IsiSplit.NRZ:
        return y * y / (2.0 * period) + excess
    return excess


def isi_split(cir_power, dt, bit_period, *, t_min=0.0, t_first=None, rule=IsiSplit.NRZ):
    """(P_signal, P_isi) [W] of OOK-NRZ from a binned CIR (Komine & Nakagawa 2004).

    cir_power: received power per bin [W], shape (..., n_bins), bin k = [t_min + k dt, t_min + (k+1) dt);
    dt, t_min [s]; bit_period T [s]; t_first [s], shape (...): the first arrival t0, default the
    start of each link's first non-empty bin. Power is taken uniform within a bin, so a bin
    straddling a boundary is split exactly (resolution dt). With rule NRZ a path at t0 + tau gives
    (1 - tau/T) of its power to the signal for tau < T and the rest to ISI (the CIR convolved with
    the rectangular NRZ pulse, integrated over the bit [t0, t0 + T] and after it, over T); with
    WINDOW all power within [t0, t0 + T) is signal. Power before t0 counts as signal.
    P_signal + P_isi = sum(cir_power). Links without power give (0, 0).
    """
    h = np.asarray(cir_power, float)
    edges = t_min + dt * np.arange(h.shape[-1] + 1)
    if t_first is None:
        nonzero = h > 0
        first = np.argmax(nonzero, axis=-1)
        t0 = np.where(nonzero.any(axis=-1), t_min + dt * first, t_min)
    else:
        t0 = np.asarray(t_first, float)
    x = edges - np.asarray(t0, float)[..., None]
    rule = IsiSplit(rule)
    signal = (h * np.diff(_signal_primitive(x, bit_period, rule), axis=-1) / dt).sum(axis=-1)
    isi = (h * np.diff(_isi_primitive(x, bit_period, rule), axis=-1) / dt).sum(axis=-1)
    return signal, isi


# --- rates (multi-cell LiFi, engine/results/cells.py) -----------------------------------------


def shannon_rate(bandwidth, sinr_linear):
    """Shannon rate C = B log2(1 + SINR) [bit/s]; bandwidth B [Hz], SINR linear [-] (NaN stays NaN)."""
    return bandwidth * np.log2(1.0 + np.maximum(np.asarray(sinr_linear, float), 0.0))


def dco_ofdm_rate(bandwidth, sinr_ac, subcarriers: int):
    """DCO-OFDM rate R = B (N - 2) / (2N) log2(1 + SINR_ac) [bit/s] (Dimitrov & Haas 2015, ch. 4-5).

    An N-point IFFT with Hermitian symmetry carries data on N/2 - 1 of its N subcarriers (the DC and the
    N/2 subcarrier are zero), each at most log2(1 + SINR_ac) bits per symbol (Gaussian signalling, flat
    channel), B the sampling rate [Hz]. SINR_ac [-] is the SINR of the AC (data) part of the signal.
    """
    n = float(subcarriers)
    return bandwidth * (n - 2.0) / (2.0 * n) * np.log2(1.0 + np.maximum(np.asarray(sinr_ac, float), 0.0))


def ook_required_snr(ber_target: float) -> float:
    """SNR [-] at which OOK-NRZ reaches a BER: Q(sqrt(SNR)) = BER, so SNR = Q^-1(BER)^2 (`ber_ook`)."""
    from scipy.special import erfcinv  # on first use (scipy's import time)

    return float((math.sqrt(2.0) * erfcinv(2.0 * ber_target)) ** 2)


def thermal_coefficients(budget: LinkBudget, area):
    """(c2, c3) of sigma_thermal^2 = c2 B^2 + c3 B^3 [A^2] (`noise_variances`), per receiver area A [m^2]."""
    kt, cap = K_B * budget.temperature, budget.capacitance_per_area * np.asarray(area, float)
    c2 = 8.0 * math.pi * kt / budget.open_loop_gain * cap * budget.i2
    c3 = 16.0 * math.pi**2 * kt * budget.channel_noise_factor / budget.transconductance * cap**2 * budget.i3
    return c2, c3


#: Bisection steps of `ook_rate` on a bracket [r/3, r]: 3^(-2^-60) ~ 1e-18 relative width at the end.
_OOK_STEPS = 64


def ook_rate(budget: LinkBudget, area, p_signal, interference_a2, p_total, required_snr: float):
    """Highest OOK-NRZ bit rate R_b [bit/s] whose SINR reaches `required_snr`, the noise bandwidth being R_b
    (Komine & Nakagawa 2004: B = R_b), without the cap at the budget's bandwidth (cells.py applies it).

    Solves c1 R + c2 R^2 + c3 R^3 = (gamma P_s)^2 / SNR_req - I for R > 0, with c1 = 2 q (gamma P_total +
    I_bg I2) (shot noise) and c2, c3 the thermal terms (`thermal_coefficients`); the left side grows with R,
    so the root is unique, bracketed by [r / 3, r], r = min(Y/c1, sqrt(Y/c2), cbrt(Y/c3)) and found by
    bisection. 0 where the interference I [A^2] alone exceeds the allowance (no rate meets it), NaN where
    an input is NaN. p_signal, p_total [W]; interference_a2 = sum (gamma P_k)^2 [A^2].
    """
    g = budget.responsivity
    c1 = 2.0 * Q_E * (g * np.asarray(p_total, float) + budget.background_current * budget.i2)
    c2, c3 = thermal_coefficients(budget, area)
    y = (g * np.asarray(p_signal, float)) ** 2 / required_snr - np.asarray(interference_a2, float)
    c1, c2, c3, y = np.broadcast_arrays(c1, c2, c3, y)
    ok = y > 0
    yy = np.where(ok, y, 1.0)
    hi = np.minimum(np.minimum(yy / c1, np.sqrt(yy / c2)), np.cbrt(yy / c3))
    lo = hi / 3.0
    for _ in range(_OOK_STEPS):  # a loop over bisection steps, each over all receivers at once
        mid = np.sqrt(lo * hi)
        above = c1 * mid + c2 * mid**2 + c3 * mid**3 >= yy
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
    rate = np.where(ok, np.sqrt(lo * hi), 0.0)
    return np.where(np.isnan(y), np.nan, rate)
