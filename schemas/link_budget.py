"""Photometry of a transmitter and the receiver's link budget (docs/link-budget.md).

Two input models:

- `LuminousOutputSpec`: how bright a transmitter is to the eye, as its luminous flux Phi_v [lm]
  or its centre (on-axis) luminous intensity I_v(0) [cd]. Its optical power stays the
  transmitter's `power` [W]; photometry only adds illuminance [lx] to the results.
- `LinkBudgetSpec`: the photodiode and its preamplifier, for the SNR and the BER of OOK-NRZ,
  with the noise model of Komine & Nakagawa 2004 (IEEE Trans. Consumer Electron. 50(1),
  100-107), whose values are the defaults.

Noise model (Komine & Nakagawa 2004; the FET-preamplifier thermal noise is that of Smith &
Personick 1982, whose noise-bandwidth integrals are I2 and I3):
    S             = (gamma P_signal)^2                                              [A^2]
    sigma_shot^2  = 2 q gamma (P_signal + P_isi) B + 2 q I_bg I2 B                    [A^2]
    sigma_therm^2 = 8 pi k T / G * eta A I2 B^2 + 16 pi^2 k T Gamma / g_m * eta^2 A^2 I3 B^3  [A^2]
    SNR           = S / (sigma_shot^2 + sigma_therm^2 + gamma^2 P_isi^2)
with A the receiver's `area` [m^2] and B the noise bandwidth [Hz]. Komine takes B equal to the
bit rate (I2 and I3 are the noise-bandwidth factors of an NRZ receiver, so I2 * R_b is the
equivalent noise bandwidth); here B = `bandwidth` when given, else `bit_rate`.

Multi-cell figures (schemas/cells.py, engine/results/cells.py) use the same receiver: the SINR with
the other cells as interference, and rates at B: Shannon, DCO-OFDM (`dco_ofdm_subcarriers`,
`dco_ofdm_bias`) and OOK-NRZ at `ber_target`.
"""

from __future__ import annotations

import math
from enum import StrEnum

from pydantic import Field, model_validator

from .base import SpecModel

#: Largest luminous flux / intensity accepted [lm] / [cd]: a stadium floodlight is ~1e6 lm.
MAX_PHOTOMETRIC = 1e8
#: Largest bit rate / bandwidth accepted [bit/s] / [Hz]: keeps B^3 (thermal noise) far from overflow.
MAX_RATE = 1e13


class LuminousOutputSpec(SpecModel):
    """Photometry of a generalized Lambertian transmitter of order m (give exactly one field).

    I_v(phi) = I_v(0) cos^m(phi) [cd], so the flux is Phi_v = 2 pi I_v(0) / (m + 1) [lm] and
    I_v(0) = (m + 1) Phi_v / (2 pi) (Komine & Nakagawa 2004). m comes from the
    transmitter (`lambertian_order` or `half_power_semi_angle_deg`). The optical power of the
    transmitter stays its `power` [W]: the two are independent inputs (no luminous efficacy).
    Komine's luminaire: 60 x 60 LEDs of 0.73 cd, i.e. `center_luminous_intensity` = 2628 cd.
    """

    luminous_flux: float | None = Field(None, gt=0.0, le=MAX_PHOTOMETRIC, description="total luminous flux Phi_v [lm]")
    center_luminous_intensity: float | None = Field(
        None, gt=0.0, le=MAX_PHOTOMETRIC, description="luminous intensity on the axis I_v(0) [cd]"
    )

    @model_validator(mode="after")
    def _one_of(self) -> "LuminousOutputSpec":
        if (self.luminous_flux is None) == (self.center_luminous_intensity is None):
            raise ValueError("give exactly one of `luminous_flux` [lm] and `center_luminous_intensity` [cd]")
        return self

    def center_intensity(self, m: float) -> float:
        """I_v(0) [cd] for Lambertian order m."""
        if self.center_luminous_intensity is not None:
            return self.center_luminous_intensity
        assert self.luminous_flux is not None  # the validator asks for exactly one
        return (m + 1.0) * self.luminous_flux / (2.0 * math.pi)

    def flux(self, m: float) -> float:
        """Phi_v [lm] for Lambertian order m."""
        if self.luminous_flux is not None:
            return self.luminous_flux
        assert self.center_luminous_intensity is not None
        return 2.0 * math.pi * self.center_luminous_intensity / (m + 1.0)


class IsiSplit(StrEnum):
    """How a CIR splits into the bit's own power (signal) and its spill into later bits (ISI).

    Times are counted from the first arrival t0; T = 1 / bit_rate.
    """

    #: Komine & Nakagawa 2004: the CIR convolved with the NRZ rectangular pulse of
    #: width T, integrated over [t0, t0 + T] (signal) and after it (ISI), divided by T. A path
    #: arriving tau after t0 gives (1 - tau/T) of its power to the signal when tau < T.
    NRZ = "nrz"
    #: Power arriving within one bit period of the first arrival is signal, the rest ISI.
    WINDOW = "window"


class LinkBudgetSpec(SpecModel):
    """Photodiode and receiver electronics for SNR and BER of OOK-NRZ (Komine & Nakagawa 2004).

    Give `bit_rate` R_b [bit/s], `bandwidth` B [Hz], or both. The noise bandwidth is B when given,
    else R_b (Komine's choice, B = R_b). The bit rate sets the bit period T = 1/R_b used by the BER
    and the signal / ISI split of a CIR; without it only the SNR is defined (P_isi = 0).
    Defaults are the values of Komine & Nakagawa 2004.
    """

    responsivity: float = Field(
        0.53,
        gt=0.0,
        le=10.0,
        description="photodiode responsivity gamma [A/W] (Komine: 0.53 A/W); "
        "above 10 A/W would need an internal gain this model lacks",
    )
    bit_rate: float | None = Field(
        None, gt=0.0, le=MAX_RATE, description="OOK-NRZ bit rate R_b [bit/s]; bit period T = 1/R_b"
    )
    bandwidth: float | None = Field(
        None, gt=0.0, le=MAX_RATE, description="noise bandwidth B [Hz]; default: the bit rate (Komine)"
    )
    background_current: float = Field(
        5.1e-3,
        ge=0.0,
        le=1.0,
        description="photocurrent of the ambient light I_bg [A] (Komine: 5100 uA, after Moreira et al. 1997)",
    )
    temperature: float = Field(295.0, gt=0.0, le=1000.0, description="absolute temperature T_k [K] (Komine: 295 K)")
    open_loop_gain: float = Field(10.0, gt=0.0, le=1e6, description="open-loop voltage gain G [-] (Komine: 10)")
    capacitance_per_area: float = Field(
        1.12e-6,
        gt=0.0,
        le=1.0,
        description="fixed capacitance of the photodiode per unit area eta [F/m^2] "
        "(Komine: 112 pF/cm^2 = 1.12e-6 F/m^2)",
    )
    channel_noise_factor: float = Field(
        1.5, gt=0.0, le=10.0, description="FET channel noise factor Gamma [-] (Komine: 1.5)"
    )
    transconductance: float = Field(0.03, gt=0.0, le=10.0, description="FET transconductance g_m [S] (Komine: 30 mS)")
    noise_bandwidth_factor_i2: float = Field(
        0.562, gt=0.0, le=10.0, description="noise-bandwidth factor I2 [-] (Komine: 0.562)"
    )
    noise_bandwidth_factor_i3: float = Field(
        0.0868, gt=0.0, le=10.0, description="noise-bandwidth factor I3 [-] (Komine: 0.0868)"
    )
    isi_split: IsiSplit = Field(
        IsiSplit.NRZ,
        description="how a CIR splits into signal and ISI power: `nrz` (Komine's rectangular-pulse form) or `window`",
    )
    ber_target: float = Field(
        1e-6,
        gt=0.0,
        lt=0.5,
        description="bit-error rate the multi-cell OOK-NRZ rate must meet [-]: the required SINR is "
        "Q^-1(BER)^2 (13.5 dB at 1e-6)",
    )
    dco_ofdm_subcarriers: int = Field(
        64,
        ge=4,
        le=65536,
        description="IFFT size N of DCO-OFDM [-], even: N/2 - 1 subcarriers carry data (Hermitian symmetry)",
    )
    dco_ofdm_bias: float = Field(
        2.0,
        gt=0.0,
        le=10.0,
        description="DC bias of DCO-OFDM in standard deviations k of the OFDM signal [-] (the bias of "
        "10 log10(1 + k^2) dB: 7 dB at k = 2); the AC signal power is (gamma P)^2 / k^2",
    )

    @model_validator(mode="after")
    def _rate_or_bandwidth(self) -> "LinkBudgetSpec":
        if self.bit_rate is None and self.bandwidth is None:
            raise ValueError("give `bit_rate` [bit/s] or `bandwidth` [Hz] (or both): the noise needs a bandwidth")
        if self.dco_ofdm_subcarriers % 2:
            raise ValueError(
                f"`dco_ofdm_subcarriers` must be even (Hermitian symmetry), got {self.dco_ofdm_subcarriers}"
            )
        return self

    @property
    def noise_bandwidth(self) -> float:
        """B [Hz]: `bandwidth`, else the bit rate (Komine & Nakagawa 2004)."""
        return self.bandwidth if self.bandwidth is not None else self.bit_rate  # type: ignore[return-value]

    @property
    def bit_period(self) -> float | None:
        """T = 1 / R_b [s], or None without a bit rate."""
        return None if self.bit_rate is None else 1.0 / self.bit_rate
