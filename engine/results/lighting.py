"""Illuminance and the link budget of every link, group channel and map point (issue: coverage maps).

- Illuminance [lx] on the receiver's plane, direct light only (Komine & Nakagawa 2004):
  E = sum_i I0_i cos^m(phi) cos(psi) / d^2 over the transmitters that give a luminous output
  (link_budget.illuminance_los), blocked by furniture, attenuated by smoke, no FOV limit. A
  transmitter with a photometric file and no `luminous_output` lights with the file's own candela,
  I(gamma, C) (Photometry.luminous_flux); a given `luminous_output` wins (it rescales the file's shape).
- With `link_budget`: received power P_r = P_t H0 [W], SNR of the Komine-Nakagawa noise model
  (shot noise of signal and background, thermal noise of the preamplifier), BER of OOK-NRZ,
  and the bit rate the delay spread allows, 1 / (10 tau_rms). The signal is the whole received
  power (P_isi = 0) unless the link has a binned CIR and the budget a bit rate: then the power
  arriving after the first bit period is ISI (link_budget.isi_split).
Quantities that do not apply are NaN (null in the document).
"""

from __future__ import annotations

import numpy as np

from owcsim.engine.results import link_budget as lb
from owcsim.engine.results.result_parts import column
from owcsim.engine.scene.los import LosGeometry


class Lighting:
    """Per-link illuminance and link-budget figures, shared by links, channels and maps."""

    def __init__(self, spec, scene, geometry: LosGeometry):
        self.scene = scene
        tx, rx = scene.transmitters, scene.receivers
        self.n_tx, self.n_rx = len(tx), len(rx)
        shape = (self.n_tx, self.n_rx)
        # Luminous intensity toward a direction [cd] = Phi_v R(dir) (R the response per watt [1/sr], so R / its
        # integral over the sphere = 1), or I0 R(dir) / R(aim) from the centre intensity I0 (= I0 cos^m(phi)
        # for a Lambertian source: link_budget.illuminance_los).
        r_aim = tx.response(np.arange(self.n_tx), np.ones(self.n_tx), tx.normals)
        scale = np.full(self.n_tx, np.nan)  # [lm]: intensity = scale * R(dir)
        patterns = tx.patterns or [None] * self.n_tx
        for i, t in enumerate(spec.transmitters):  # a loop over transmitters
            out = t.luminous_output
            if out is not None and out.luminous_flux is not None:
                scale[i] = out.luminous_flux
            elif out is not None and r_aim[i] > 0:
                scale[i] = out.center_luminous_intensity / r_aim[i]
            elif out is None and patterns[i] is not None:  # a photometric file: its own candela (given output wins)
                scale[i] = patterns[i].luminous_flux
        self.has_light = bool(np.isfinite(scale).any())
        self.illuminance = np.full(shape, np.nan)  # per link [lx]
        if self.has_light:
            ti = np.repeat(np.arange(self.n_tx), self.n_rx)
            c_rx, d, clear = geometry.cos_rx, geometry.distance, geometry.clear
            ok = (c_rx > 0) & (clear > 0)
            with np.errstate(under="ignore", invalid="ignore"):
                e = (
                    np.nan_to_num(scale)[ti]
                    * tx.response(ti, geometry.cos_tx, geometry.directions)
                    * c_rx
                    / np.where(ok, d, 1.0) ** 2
                    * clear
                )
            self.illuminance = np.where(np.isfinite(scale)[ti], np.where(ok, e, 0.0), np.nan).reshape(shape)
        self.budget = lb.link_budget_from_spec(spec.link_budget) if spec.link_budget is not None else None
        self.area = rx.area

    def _budget_columns(self, received_power: np.ndarray, rms: np.ndarray, area: np.ndarray) -> dict[str, np.ndarray]:
        if self.budget is None:
            return {}
        with np.errstate(divide="ignore", invalid="ignore"):
            snr = lb.snr(self.budget, area, np.nan_to_num(received_power), 0.0)
            snr = np.where(np.isfinite(received_power), snr, np.nan)
            return {"snr_db": lb.to_db(snr), "ber": lb.ber_ook(snr), "max_bit_rate_bps": lb.max_bit_rate(rms)}

    def add_link_columns(self, cols: dict, h0: np.ndarray, rms: np.ndarray, masked: np.ndarray) -> None:
        arrays = {"illuminance_lx": np.where(masked, np.nan, self.illuminance.ravel())}
        power = h0 * np.repeat(self.scene.transmitters.power, self.n_rx)
        arrays.update(self._budget_columns(power, rms, np.tile(self.area, self.n_tx)))
        for key, values in arrays.items():
            cols[key] = column(values)

    def add_channel_columns(
        self, cols: dict, weights: np.ndarray, h0: np.ndarray, rms: np.ndarray, group_power: np.ndarray
    ) -> None:
        """weights (G, n_tx); h0, rms (G, n_rx) of the groups' channels; group_power (G,) [W]."""
        member = weights > 0
        illum = np.where(member[:, :, None], np.nan_to_num(self.illuminance)[None], 0.0).sum(axis=1)
        has = (member & np.isfinite(self.illuminance).any(axis=1)[None, :]).any(axis=1)
        arrays = {"illuminance_lx": np.where(has[:, None] & np.isfinite(h0), illum, np.nan)}
        arrays.update(self._budget_columns(h0 * group_power[:, None], rms, self.area[None, :]))
        for key, values in arrays.items():
            cols[key] = column(values.ravel())
