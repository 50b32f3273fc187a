"""Curves shipped with owcsim (schemas.spectra.NAMED_CURVES) and the CIE photopic curve V(lambda).

The named curves are smooth analytic models of typical parts written for owcsim, plausible
in shape and level but not measurements of any product: use a table of your own part's data
for design work. Wavelengths in metres; each function takes an array and returns an array.

- LED spectra (relative power per metre of wavelength): a white LED is a blue InGaN chip
  (Gaussian, peak 450 nm, FWHM 20 nm) plus a YAG:Ce phosphor (Gaussian, FWHM 110-140 nm)
  whose peak and weight set the colour temperature (cool: 555 nm, half the blue peak's height
  x 2.4; warm: 600 nm); infrared LEDs are Gaussians (850 nm / FWHM 40 nm, 940 nm / 45 nm).
- Reflectances: logistic steps and Gaussian bumps in wavelength, in [0, 1].
- Silicon PIN photodiode responsivity: R = eta(lambda) lambda q / (h c) [A/W], with a quantum
  efficiency rising through the blue (surface recombination) and falling to zero near the band
  gap (1.12 eV, ~1100 nm): peak about 0.6 A/W near 900 nm.
- Daylight-blocking filter: a long-pass edge at 780 nm (10 nm width), 90 % transmission.

V(lambda): the CIE 1924 photopic luminous efficiency function at 1 nm from 360 to 830 nm (zero
outside), read from colour-science (`colour.colorimetry.SDS_LEFS_PHOTOPIC`), imported only
when a spectral job asks for illuminance.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from owcsim.engine.core.errors import SceneError

#: Luminous efficacy of the CIE photopic observer at its peak, K_m [lm/W] (SI definition of the candela).
K_M = 683.0
#: Elementary charge q [C], Planck constant h [J s], speed of light c [m/s] (CODATA exact values).
_Q, _H, _C = 1.602176634e-19, 6.62607015e-34, 299_792_458.0
NM = 1e-9


def _gauss(lam, peak, fwhm):
    s = fwhm / 2.3548200450309493
    return np.exp(-0.5 * ((lam - peak) / s) ** 2)


def _logistic(lam, centre, width):
    return 1.0 / (1.0 + np.exp(-(lam - centre) / width))


def _white_led(lam, phosphor_peak, phosphor_fwhm, blue_weight):
    return blue_weight * _gauss(lam, 450 * NM, 20 * NM) + _gauss(lam, phosphor_peak, phosphor_fwhm)


def silicon_pin(lam):
    """Responsivity [A/W] of a silicon PIN photodiode (model): eta(lambda) lambda q / (h c)."""
    eta = 0.85 * _logistic(lam, 430 * NM, 35 * NM) * (1.0 - _logistic(lam, 1010 * NM, 25 * NM))
    return eta * lam * _Q / (_H * _C)


CURVES = {
    "white_led_cool": lambda lam: _white_led(lam, 555 * NM, 110 * NM, 2.4),
    "white_led_warm": lambda lam: _white_led(lam, 600 * NM, 140 * NM, 0.9),
    "ir_led_850": lambda lam: _gauss(lam, 850 * NM, 40 * NM),
    "ir_led_940": lambda lam: _gauss(lam, 940 * NM, 45 * NM),
    "white_paint": lambda lam: 0.86 - 0.30 * (1.0 - _logistic(lam, 415 * NM, 12 * NM)),
    "plaster": lambda lam: 0.74 - 0.18 * (1.0 - _logistic(lam, 440 * NM, 25 * NM)),
    "light_wood": lambda lam: 0.18 + 0.50 * _logistic(lam, 590 * NM, 45 * NM),
    "red_brick": lambda lam: 0.08 + 0.30 * _logistic(lam, 590 * NM, 20 * NM) + 0.12 * _logistic(lam, 780 * NM, 40 * NM),
    "blue_paint": lambda lam: 0.06 + 0.40 * _gauss(lam, 460 * NM, 90 * NM) + 0.55 * _logistic(lam, 720 * NM, 25 * NM),
    "grey_carpet": lambda lam: 0.14 + 0.08 * _logistic(lam, 700 * NM, 30 * NM),
    "silicon_pin": silicon_pin,
    "daylight_filter_ir": lambda lam: 0.90 * _logistic(lam, 780 * NM, 10 * NM),
}


@lru_cache(maxsize=1)
def photopic() -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths [m], V(lambda)) of the CIE 1924 photopic observer, 360-830 nm at 1 nm (colour-science)."""
    try:
        from colour.colorimetry import SDS_LEFS_PHOTOPIC
    except ImportError as err:  # pragma: no cover - the engine extra installs it
        raise SceneError(
            "illuminance of a spectral scene needs the `colour-science` package (pip install 'owcsim[engine]')"
        ) from err
    sd = SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    return np.asarray(sd.wavelengths, float) * NM, np.asarray(sd.values, float)


def v_lambda(lam) -> np.ndarray:
    """V(lambda) at wavelengths [m] (linear between the 1 nm points, 0 outside 360-830 nm)."""
    w, v = photopic()
    return np.interp(np.asarray(lam, float), w, v, left=0.0, right=0.0)


#: The photopic curve is zero outside this range [m]: bands entirely outside need no table.
VISIBLE = (360 * NM, 830 * NM)
