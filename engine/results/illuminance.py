"""One luminous flux per transmitter, and the illuminance a lighting designer measures (docs/lighting.md).

Flux precedence: a given `luminous_output` (the user's statement: a dimmed or measured luminaire) > the
photometric file's candela integrated over the sphere (a goniophotometer's measurement of this luminaire) >
the spectrum, P_t x K_m sum_b f_b Vbar_b (derived from the radiometric power the channel uses and a relative
spectrum). Every other value the scene gives is compared with the one used; beyond FLUX_TOLERANCE the result
warns.

Total illuminance of a link (tx i, point j) on the receiver's plane [lx]:
    E = E_dir + E_refl,   E_refl = Phi_v,i (H0 - H_los) / (A T_s g)
E_dir exact over the whole hemisphere (link_budget.illuminance_los), H0 - H_los the Monte Carlo part of the
link's gain (every reflection and scattering order), A T_s g the receiver's area x filter x concentrator gain
(the light inside the FOV at the constant gain g). In a spectral scene H is the luminous channel
H_v = sum_b f_b K_m Vbar_b H_b [lm/W] scaled by Phi_v,i / Phi_spectrum,i. A receiver with fov < 90 deg counts
reflected light only within its FOV: under uniform incident radiance it misses cos^2(FOV) of it (warned).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.scene.los import LosGeometry
from owcsim.engine.scene.scene import Scene
from owcsim.engine.tally.estimates import link_moments
from owcsim.schemas.lighting import FluxSource

#: Relative difference between two luminous fluxes of a transmitter above which the result warns.
FLUX_TOLERANCE = 0.05


@dataclass(frozen=True)
class LuminousFluxes:
    """Per transmitter: the flux used [lm] (NaN: no light), its source, every candidate, and the warnings."""

    flux_lm: FloatArray
    source: list[FluxSource | None]
    candidates: list[dict[FluxSource, float]]
    warnings: list[str]

    def spectrum_ratio(self) -> FloatArray:
        """Phi_v / Phi_spectrum per transmitter (NaN without a spectrum flux): scales the luminous channel."""
        spec = np.array([c.get(FluxSource.SPECTRUM, np.nan) for c in self.candidates])
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(spec > 0, self.flux_lm / spec, np.nan)


def resolve_fluxes(spec, scene: Scene) -> LuminousFluxes:
    """The luminous flux of every transmitter by the precedence luminous_output > photometry > spectrum."""
    tx = scene.transmitters
    n = len(tx)
    r_aim = tx.response(np.arange(n), np.ones(n), tx.normals)  # R(aim) [1/sr]: I0 = Phi R(aim)
    patterns = tx.patterns or [None] * n
    sp = scene.spectra
    spectrum = tx.power * (sp.tx_luminous * sp.tx_fraction).sum(axis=1) if sp is not None else np.zeros(n)
    flux, sources, cands, warns = np.full(n, np.nan), [], [], []
    for i, t in enumerate(spec.transmitters):  # a loop over transmitters
        c: dict[FluxSource, float] = {}
        out = t.luminous_output
        if out is not None and out.luminous_flux is not None:
            c[FluxSource.LUMINOUS_OUTPUT] = float(out.luminous_flux)
        elif out is not None and r_aim[i] > 0:
            c[FluxSource.LUMINOUS_OUTPUT] = float(out.center_luminous_intensity / r_aim[i])
        pattern = patterns[i]
        if pattern is not None:
            c[FluxSource.PHOTOMETRY] = float(pattern.luminous_flux)
        if spectrum[i] > 0:
            c[FluxSource.SPECTRUM] = float(spectrum[i])
        used = next((s for s in FluxSource if s in c), None)  # the enum's order is the precedence
        sources.append(used)
        cands.append(c)
        if used is None:
            continue
        flux[i] = c[used]
        for other, value in c.items():
            if other is not used and abs(value - flux[i]) > FLUX_TOLERANCE * flux[i]:
                warns.append(
                    f"{tx.ids[i]}: {used.value} {flux[i]:.0f} lm differs from the {other.value}'s {value:.0f} lm by "
                    f"{abs(value - flux[i]) / flux[i]:.0%}; {flux[i]:.0f} lm is used"
                )
    return LuminousFluxes(flux, sources, cands, warns)


def direct_illuminance(scene: Scene, geometry: LosGeometry, flux: FloatArray) -> FloatArray:
    """(n_tx, n_rx) direct illuminance on each receiver's plane [lx]: Phi_v R(dir) cos(psi) / d^2 x clear, no FOV
    limit (Komine & Nakagawa 2004); in a spectral scene with a medium varying per band, the clear fraction is the
    luminous transmittance sum_b f_b Vbar_b exp(-tau_b) / sum_b f_b Vbar_b. NaN for transmitters without flux."""
    tx, n_tx, n_rx = scene.transmitters, len(scene.transmitters), len(scene.receivers)
    ti = np.repeat(np.arange(n_tx), n_rx)
    c_rx, d, clear = geometry.cos_rx, geometry.distance, luminous_clear(scene, geometry)
    ok = (c_rx > 0) & (clear > 0)
    with np.errstate(under="ignore", invalid="ignore"):
        e = np.nan_to_num(flux)[ti] * tx.response(ti, geometry.cos_tx, geometry.directions) * c_rx
        e = e / np.where(ok, d, 1.0) ** 2 * clear
    return np.where(np.isfinite(flux)[ti], np.where(ok, e, 0.0), np.nan).reshape(n_tx, n_rx)


def luminous_clear(scene: Scene, geometry: LosGeometry) -> FloatArray:
    """Per link: the direct segment's clear fraction for visible light (the carrier's in a grey scene)."""
    sp, clear = scene.spectra, geometry.clear
    if sp is None or sp.tau_scale is None or scene.medium is None:
        return clear
    idx = np.flatnonzero(clear > 0)
    if not len(idx):
        return clear
    n_rx = len(scene.receivers)
    ti = idx // n_rx
    tau = scene.medium.optical_depth(scene.transmitters.positions[ti], geometry.directions[idx], geometry.distance[idx])
    w = sp.tx_fraction[ti] * sp.tx_luminous[ti]  # (n, B) f_b K_m Vbar_b
    ratio = (w * np.exp(-np.outer(tau, sp.tau_scale))).sum(axis=1) / np.maximum(w.sum(axis=1), 1e-300)
    out = clear.copy()
    out[idx] = clear[idx] * np.where(w.sum(axis=1) > 0, ratio, 1.0)
    return out


def cylindrical_direct(scene: Scene, geometry: LosGeometry, flux: FloatArray) -> FloatArray:
    """(n_tx, n_rx) direct cylindrical illuminance [lx], the mean vertical illuminance over all azimuths:
    E_z = Phi_v R(dir) sin(eps) / (pi d^2) x clear, eps the angle of the light from the vertical (z)
    (EN 12464-1:2021 sec. 3.1; mean over azimuth a of max(0, sin eps cos a) = sin eps / pi). Light from behind
    the receiver's plane is not counted (the line of sight is tested for the receiver)."""
    tx, n_tx, n_rx = scene.transmitters, len(scene.transmitters), len(scene.receivers)
    ti = np.repeat(np.arange(n_tx), n_rx)
    d, clear = geometry.distance, luminous_clear(scene, geometry)
    ok = clear > 0
    sin_eps = np.sqrt(np.maximum(1.0 - geometry.directions[:, 2] ** 2, 0.0))
    with np.errstate(under="ignore", invalid="ignore"):
        e = np.nan_to_num(flux)[ti] * tx.response(ti, geometry.cos_tx, geometry.directions) * sin_eps
        e = e / (np.pi * np.where(ok, d, 1.0) ** 2) * clear
    return np.where(np.isfinite(flux)[ti], np.where(ok, e, 0.0), np.nan).reshape(n_tx, n_rx)


@dataclass(frozen=True)
class Reflected:
    """Per link (n_tx, n_rx): the reflected illuminance [lx], and per direction its variance [lx^2] (the
    forward ones independent between transmitters, the backward ones correlated within a receiver)."""

    mean: FloatArray
    var_forward: FloatArray
    var_backward: FloatArray

    @property
    def stderr(self) -> FloatArray:
        return np.sqrt(self.var_forward + self.var_backward)


def reflected_illuminance(scene: Scene, accs: Mapping, fluxes: LuminousFluxes) -> Reflected:
    """E_refl = Phi_v (H0 - H_los) / (A T_s g) per link from the Monte Carlo tallies (module docstring); in a
    spectral scene the luminous channel scaled to the flux used, where the transmitter's spectrum has light."""
    tx, rx = scene.transmitters, scene.receivers
    n_tx, n_rx, L = len(tx), len(rx), scene.n_links
    shape = (n_tx, n_rx)
    flux = fluxes.flux_lm
    per_watt = np.repeat(np.nan_to_num(flux) / tx.power, n_rx) / np.tile(rx.gain, n_tx)  # [lx] per unit H x P_t
    parts = {}
    for d, acc in accs.items():  # a loop over the (at most two) directions
        mu, cov = acc.moments()
        mean, var = mu[:, 0] * tx.power.repeat(n_rx) * per_watt, cov[:, 0, 0] * (tx.power.repeat(n_rx) * per_watt) ** 2
        sp = scene.spectra
        if sp is not None and acc.spectral is not None:
            lum = sp.n_bands + 2  # the luminous channel's row (engine/results/spectral.py)
            smu, scov = link_moments({d: acc.spectral}, np.zeros((sp.n_channels * L, 3)))
            ratio = np.repeat(fluxes.spectrum_ratio(), n_rx)
            k = tx.power.repeat(n_rx) * ratio / np.tile(rx.gain, n_tx)
            use = np.isfinite(ratio)
            mean = np.where(use, smu[:, 0].reshape(-1, L)[lum] * k, mean)
            var = np.where(use, scov[:, 0, 0].reshape(-1, L)[lum] * k**2, var)
        parts[d.value] = (mean, np.maximum(var, 0.0))
    zero = np.zeros(L)
    mean = sum((m for m, _ in parts.values()), zero)
    nan = ~np.isfinite(np.repeat(flux, n_rx))
    fwd = parts.get("forward", (zero, zero))[1]
    bwd = parts.get("backward", (zero, zero))[1]
    return Reflected(*(np.where(nan, np.nan, x).reshape(shape) for x in (mean, fwd, bwd)))
