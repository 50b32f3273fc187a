"""The `spectral` section of a result: the bands, per-band smoke, and per link every channel's figures.

Channels of a spectral scene (engine/spectral/spectra.py, V = B + 3 per link): the B bands' gain H_b, then
the optical H = sum_b f_b H_b [-], electrical G = sum_b f_b T_b R_b H_b [A/W] and luminous
H_v = sum_b f_b K_m Vbar_b H_b [lm/W] combinations; illuminance E_v = P_t H_v / (A T_s g) [lx] x Phi_v / Phi_spectrum
(the transmitter's one luminous flux, engine/results/illuminance.py, against its spectrum's). Their means
and errors come from the channel tallies (engine/tally/spectral.py) plus the line of sight of every channel.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from owcsim.engine.results import metrics
from owcsim.engine.results.illuminance import resolve_fluxes
from owcsim.engine.results.result_parts import column
from owcsim.engine.scene.los import LosGeometry, los_channels
from owcsim.engine.scene.scene import Scene
from owcsim.engine.spectral.spectra import SceneSpectra
from owcsim.engine.tally.estimates import link_moments, los_moments
from owcsim.engine.tally.spectral import ChannelAccumulator
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas.algorithms import Direction


def result_block(
    spec,
    scene: Scene,
    accs: Mapping[Direction, Accumulator],
    los_geometry: LosGeometry | None,
    los_grey: np.ndarray,
    los_delay: np.ndarray,
) -> dict | None:
    """The `spectral` section of the result (None for a grey scene)."""
    sp = scene.spectra
    if sp is None:
        return None
    V, L = sp.n_channels, scene.n_links
    los = los_channels(scene, los_geometry, los_grey) if los_geometry is not None else np.zeros((V, L))
    los_abc = los_moments(los.ravel(), np.tile(los_delay, V))
    chan: dict[Direction, ChannelAccumulator] = {d: a.spectral for d, a in accs.items() if a.spectral is not None}
    mean, cov = link_moments(chan, los_abc)
    return {
        "bands": _bands(sp),
        "carried_ratios": sp.carry,
        "transmitters": _transmitters(scene, sp),
        "receivers": _receivers(spec, scene, sp),
        "medium_bands": sp.medium_bands or None,
        "links": _links(spec, scene, sp, los, mean, cov),
        "model": "bands traced together: carrier = largest reflectance / least-attenuated band, per-band ratios "
        "(engine/spectral/spectra.py); curves averaged over each band",
    }


def _links(spec, scene: Scene, sp: SceneSpectra, los: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> list[dict]:
    """Per link (rows of the document): every channel's gain, delays and errors, photocurrent, illuminance (in the
    receiver's FOV, at the transmitter's one luminous flux)."""
    V, B, L = sp.n_channels, sp.n_bands, scene.n_links
    d = metrics.delay_metrics_from_moments(mean, cov)
    n_rx = len(scene.receivers)
    ti, ri = np.divmod(np.arange(L), n_rx)
    masked = np.tile(scene.masked != "", len(scene.transmitters))

    def ch(key):
        return np.where(masked[None, :], np.nan, np.asarray(d[key], float).reshape(V, L))

    h, h_se = ch("dc_gain"), ch("dc_gain_stderr")
    h_se[:B] = np.where(masked[None, :], np.nan, np.sqrt(np.maximum(cov[:, 0, 0], 0.0)).reshape(V, L)[:B])
    mean_d, rms, rms_se = ch("mean_delay_s"), ch("rms_delay_spread_s"), ch("rms_delay_spread_s_stderr")
    ob, el, lu = B, B + 1, B + 2
    gain = scene.receivers.gain.take(ri)  # A T_s g [m^2]
    power = scene.transmitters.power.take(ti)
    # the luminous figures at the transmitter's one luminous flux (illuminance.resolve_fluxes): x Phi_v / Phi_spectrum
    lum_power = power * np.nan_to_num(resolve_fluxes(spec, scene).spectrum_ratio(), nan=1.0).take(ti)
    has_e = sp.rx_responsive.take(ri)
    lux_ok = sp.has_luminous
    links = []
    for k in range(L):  # rows of the document
        row = {
            "transmitter": scene.transmitters.ids[ti[k]],
            "receiver": scene.receivers.ids[ri[k]],
            "dc_gain_by_band": column(h[:B, k]),
            "dc_gain_by_band_stderr": column(h_se[:B, k]),
            "mean_delay_s_by_band": column(mean_d[:B, k]),
            "rms_delay_spread_s_by_band": column(rms[:B, k]),
            "optical_gain": column(h[ob, k : k + 1])[0],
            "optical_gain_stderr": column(h_se[ob, k : k + 1])[0],
            "electrical_gain_a_per_w": column(h[el, k : k + 1])[0] if has_e[k] else None,
            "electrical_gain_a_per_w_stderr": column(h_se[el, k : k + 1])[0] if has_e[k] else None,
            "electrical_rms_delay_spread_s": column(rms[el, k : k + 1])[0] if has_e[k] else None,
            "electrical_rms_delay_spread_s_stderr": column(rms_se[el, k : k + 1])[0] if has_e[k] else None,
            "photocurrent_a": column(h[el, k : k + 1] * power[k])[0] if has_e[k] else None,
            "electrical_gain_by_band_a_per_w": column(sp.tx_fraction[ti[k]] * sp.rx_electrical[ri[k]] * h[:B, k])
            if has_e[k]
            else None,
            "illuminance_by_band_lx": column(
                lum_power[k] / gain[k] * sp.tx_fraction[ti[k]] * sp.tx_luminous[ti[k]] * h[:B, k]
            )
            if lux_ok
            else None,
            "illuminance_lx": column(h[lu, k : k + 1] * lum_power[k] / gain[k])[0] if lux_ok else None,
            "illuminance_lx_stderr": column(h_se[lu, k : k + 1] * lum_power[k] / gain[k])[0] if lux_ok else None,
            "illuminance_direct_lx": float(los[lu, k] * lum_power[k] / gain[k]) if lux_ok and not masked[k] else None,
        }
        links.append(row)
    return links


def _bands(sp: SceneSpectra) -> list[dict]:
    """Per band: its edges and centre [m] and the range of the surfaces' reflectance in it."""
    return [
        {
            "index": b,
            "lower_m": float(sp.edges[b]),
            "upper_m": float(sp.edges[b + 1]),
            "centre_m": float(sp.centres[b]),
            "reflectance_range": [float(sp.face_rho[b].min()), float(sp.face_rho[b].max())]
            if sp.face_rho.shape[1]
            else None,
        }
        for b in range(sp.n_bands)
    ]


def _transmitters(scene: Scene, sp: SceneSpectra) -> list[dict]:
    """Per transmitter: power fraction and luminous efficacy per band [lm/W], its efficacy and flux [lm]."""
    return [
        {
            "id": scene.transmitters.ids[i],
            "band_power_fraction": sp.tx_fraction[i].tolist(),
            "luminous_efficacy_by_band_lm_per_w": sp.tx_luminous[i].tolist(),
            "luminous_efficacy_lm_per_w": float(sp.tx_luminous[i] @ sp.tx_fraction[i]),
            "luminous_flux_lm": float(scene.transmitters.power[i] * sp.tx_luminous[i] @ sp.tx_fraction[i]),
        }
        for i in range(len(scene.transmitters))
    ]


def _receivers(spec, scene: Scene, sp: SceneSpectra) -> list[dict]:
    """Per explicit receiver and per grid (its first point): the electrical weight T_b R_b per band [A/W]."""
    rx_rows = [(r.id or f"rx{j}", j) for j, r in enumerate(spec.receivers)]
    for g, (start, _shape) in zip(spec.receiver_grids, scene.grid_slices or []):
        rx_rows.append((g.id_prefix, start))
    return [
        {"id": name, "electrical_weight_a_per_w": sp.rx_electrical[j].tolist() if sp.rx_responsive[j] else None}
        for name, j in rx_rows
    ]
