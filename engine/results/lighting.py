"""Illuminance and the link budget of every link, group channel and map point (issue: coverage maps).

- Illuminance [lx] on the receiver's plane (docs/lighting.md): `illuminance_lx` the total, direct light exact
  over the whole hemisphere plus every reflection and scattering order of the Monte Carlo run, with its
  standard error `illuminance_lx_stderr`; `illuminance_direct_lx` the direct part,
  E_dir = sum_i Phi_v,i R_i(dir) cos(psi) / d^2, blocked by furniture, attenuated by smoke, no FOV limit
  (Komine & Nakagawa 2004). Each transmitter lights with one luminous flux (illuminance.resolve_fluxes:
  luminous_output > photometric file > spectrum); `cylindrical_illuminance_direct_lx` on request.
- With `link_budget`: received power P_r = P_t H0 [W], SNR of the Komine-Nakagawa noise model
  (shot noise of signal and background, thermal noise of the preamplifier), BER of OOK-NRZ,
  and the bit rate the delay spread allows, 1 / (10 tau_rms). The signal is the whole received
  power (P_isi = 0) unless the link has a binned CIR and the budget a bit rate: then the power
  arriving after the first bit period is ISI (link_budget.isi_split).
Quantities that do not apply are NaN (null in the document).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from owcsim.engine.results import link_budget as lb
from owcsim.engine.results.illuminance import (
    cylindrical_direct,
    direct_illuminance,
    reflected_illuminance,
    resolve_fluxes,
)
from owcsim.engine.results.result_parts import column
from owcsim.engine.results.uniformity import ERRORS_NOTE, area_figures, replicate_reflected
from owcsim.engine.scene.los import LosGeometry

#: The `channel` of the area figures of every luminaire together (a scene with several channels: cells).
ALL_LUMINAIRES = "all luminaires"


class Lighting:
    """Per-link illuminance and link-budget figures, shared by links, channels and maps."""

    def __init__(self, spec, scene, geometry: LosGeometry, accs: Mapping | None = None):
        self.spec, self.scene, self.accs = spec, scene, accs
        self.n_tx, self.n_rx = len(scene.transmitters), len(scene.receivers)
        self.fluxes = resolve_fluxes(spec, scene)
        flux = self.fluxes.flux_lm
        self.has_light = bool(np.isfinite(flux).any())
        self.direct = direct_illuminance(scene, geometry, flux)  # (n_tx, n_rx) [lx]
        self.reflected = reflected_illuminance(scene, accs, self.fluxes) if accs is not None else None
        refl = self.reflected.mean if self.reflected is not None else np.zeros_like(self.direct)
        self.illuminance = self.direct + refl  # total per link [lx]
        asked = spec.lighting is not None and spec.lighting.cylindrical
        self.cylindrical = cylindrical_direct(scene, geometry, flux) if asked else None
        self.budget = lb.link_budget_from_spec(spec.link_budget) if spec.link_budget is not None else None
        self.area = scene.receivers.area
        self.warnings: list[str] = list(self.fluxes.warnings)

    def _budget_columns(self, received_power: np.ndarray, rms: np.ndarray, area: np.ndarray) -> dict[str, np.ndarray]:
        if self.budget is None:
            return {}
        with np.errstate(divide="ignore", invalid="ignore"):
            snr = lb.snr(self.budget, area, np.nan_to_num(received_power), 0.0)
            snr = np.where(np.isfinite(received_power), snr, np.nan)
            return {"snr_db": lb.to_db(snr), "ber": lb.ber_ook(snr), "max_bit_rate_bps": lb.max_bit_rate(rms)}

    def _light_columns(self, total, direct, stderr, cylindrical, nan) -> dict[str, np.ndarray]:
        out = {
            "illuminance_lx": np.where(nan, np.nan, total),
            "illuminance_direct_lx": np.where(nan, np.nan, direct),
            "illuminance_lx_stderr": np.where(nan, np.nan, stderr),
        }
        if cylindrical is not None:
            out["cylindrical_illuminance_direct_lx"] = np.where(nan, np.nan, cylindrical)
        return out

    def add_link_columns(self, cols: dict, h0: np.ndarray, rms: np.ndarray, masked: np.ndarray) -> None:
        se = self.reflected.stderr if self.reflected is not None else np.zeros_like(self.direct)
        cyl = self.cylindrical.ravel() if self.cylindrical is not None else None
        arrays = self._light_columns(self.illuminance.ravel(), self.direct.ravel(), se.ravel(), cyl, masked)
        power = h0 * np.repeat(self.scene.transmitters.power, self.n_rx)
        arrays.update(self._budget_columns(power, rms, np.tile(self.area, self.n_tx)))
        for key, values in arrays.items():
            cols[key] = column(values)

    def channel_stderr(self, member: np.ndarray, gain_stderr: np.ndarray, group_power: np.ndarray) -> np.ndarray:
        """(G, n_rx) standard error of a group's reflected illuminance sum_i Phi_i H_nlos,i / (A T_s g) [lx].

        Members of one luminous efficacy Phi_i / P_i = k in a grey scene: exactly k P_g se(H_g) / (A T_s g) from
        the channel's error; otherwise the forward parts' variances add (independent paths) and the backward
        parts' errors add (paths shared by the members: an upper bound, Cauchy-Schwarz)."""
        r = self.reflected
        if r is None:
            return np.zeros((len(member), self.n_rx))
        fwd = np.einsum("gi,ir->gr", member, np.nan_to_num(r.var_forward))  # a member without light adds 0
        bwd = np.einsum("gi,ir->gr", member, np.sqrt(np.nan_to_num(r.var_backward))) ** 2
        out = np.sqrt(fwd + bwd)
        k = self.fluxes.flux_lm / self.scene.transmitters.power
        for g in range(len(member)):  # a loop over groups
            ks = k[(member[g] > 0) & np.isfinite(k)]
            if self.scene.spectra is None and len(ks) == (member[g] > 0).sum() and np.ptp(ks) <= 1e-12 * ks.max():
                out[g] = ks[0] * group_power[g] * gain_stderr[g] / self.scene.receivers.gain
        return out

    def add_channel_columns(
        self, cols: dict, weights: np.ndarray, h0: np.ndarray, rms: np.ndarray, group_power: np.ndarray
    ) -> None:
        """weights (G, n_tx); h0, rms (G, n_rx) of the groups' channels; group_power (G,) [W]."""
        member = (weights > 0).astype(float)
        has = np.any((weights > 0) & np.isfinite(self.fluxes.flux_lm)[None, :], axis=1)
        nan = ~(has[:, None] & np.isfinite(h0))

        def total(x: np.ndarray) -> np.ndarray:
            return member @ np.nan_to_num(x)

        gain_se = np.array(cols["dc_gain_stderr"], dtype=float).reshape(h0.shape)
        se = self.channel_stderr(member, np.nan_to_num(gain_se), group_power)
        cyl = total(self.cylindrical) if self.cylindrical is not None else None
        arrays = self._light_columns(total(self.illuminance), total(self.direct), se, cyl, nan)
        arrays.update(self._budget_columns(h0 * group_power[:, None], rms, self.area[None, :]))
        for key, values in arrays.items():
            cols[key] = column(values.ravel())

    def section(self, weights: np.ndarray | None, names: list[str], masked_rx: np.ndarray) -> dict | None:
        """The result's `lighting` section (schemas.lighting.LightingResultPublic) and its warnings in
        `self.warnings`; None when no transmitter gives light."""
        if not self.has_light:
            return None
        tx = self.scene.transmitters
        rows = [
            {
                "transmitter": tx.ids[i],
                "luminous_flux_lm": float(f) if math.isfinite(f) else None,
                "luminous_flux_source": self.fluxes.source[i],
                "candidates_lm": self.fluxes.candidates[i],
            }
            for i, f in enumerate(self.fluxes.flux_lm)
        ]
        member = (weights > 0).astype(float) if weights is not None and weights.size else np.eye(self.n_tx)
        totals = np.where(masked_rx[None, :], np.nan, member @ np.nan_to_num(self.illuminance))
        lit = np.any(member * np.isfinite(self.fluxes.flux_lm)[None, :] > 0, axis=1)
        channels = [(n, member[g], totals[g]) for g, n in enumerate(names) if lit[g]]
        dark = ~np.isfinite(self.fluxes.flux_lm)
        for g, n in enumerate(names):  # a loop over groups: a lit group with dark members counts their light as 0
            unlit = [tx.ids[i] for i in np.flatnonzero((member[g] > 0) & dark)]
            if lit[g] and unlit:
                self.warnings.append(
                    f"lighting: the illuminance of {n} leaves out {', '.join(unlit)}, which give no luminous flux "
                    "(no luminous_output, photometry or spectrum): give them one to count their light"
                )
        if len(names) > 1:  # EN 12464-1 asks of the installation's light: every luminaire together, too
            every = np.isfinite(self.fluxes.flux_lm).astype(float)
            channels.append(
                (ALL_LUMINAIRES, every, np.where(masked_rx, np.nan, every @ np.nan_to_num(self.illuminance)))
            )
        reps = replicate_reflected(self.scene, self.accs, self.fluxes.flux_lm) if self.accs is not None else None
        areas, warns = area_figures(self.spec, self.scene, channels, reps)
        self.warnings += warns + self._fov_warning()
        return {"transmitters": rows, "areas": areas, "errors": ERRORS_NOTE}

    def _fov_warning(self) -> list[str]:
        """Receivers with fov < 90 deg whose illuminance has a reflected part: it is counted inside the FOV only."""
        if self.reflected is None or not np.nan_to_num(self.reflected.mean).any():
            return []
        spec = self.spec
        narrow = [(r.id or f"rx{i}", r.fov_deg) for i, r in enumerate(spec.receivers) if r.fov_deg < 90.0]
        narrow += [(f"grid {g.id_prefix}", g.fov_deg) for g in spec.receiver_grids if g.fov_deg < 90.0]
        if not narrow:
            return []
        fov = min(f for _, f in narrow)
        names = ", ".join(n for n, _ in narrow[:5]) + (" ..." if len(narrow) > 5 else "")
        return [
            f"illuminance_lx of {names} (fov_deg < 90) counts reflected light only inside the field of view (direct "
            f"light over the whole hemisphere, as a cosine photometer): under evenly bright surroundings it misses "
            f"cos^2(FOV) of the reflected part ({math.cos(math.radians(fov)) ** 2:.2%} at {fov:g} deg); for the "
            "photometer's value give those receivers fov_deg = 90"
        ]
