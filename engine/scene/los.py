"""Line-of-sight term, computed exactly for every link (physics.md section 6, LOS closed form).

H_los = R(phi) * A cos(psi) T_s g rect(psi <= FOV) / d^2 * exp(-sigma_t d_in) * V,
R(phi) = (m+1)/(2 pi) cos^m(phi) (or a luminaire's tabulated I(gamma, C) / Phi), arriving at t = d / c.
It has no variance, so the Monte Carlo kernel never samples it; it is added to every estimate as a constant.
Shadow rays are cast only where the scene has occluders (furniture, meshes) and only for
pairs that face each other: an empty box room is convex.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.constants import SPEED_OF_LIGHT
from owcsim.engine.scene.scene import Scene


@dataclass(frozen=True)
class LosGeometry:
    """Per link (flat, tx * n_rx + rx): cosines at both devices, distance [m], and the clear fraction
    (0 when blocked, the medium's transmittance exp(-sigma_t d_in) otherwise) of the direct segment."""

    cos_tx: np.ndarray
    cos_rx: np.ndarray
    distance: np.ndarray
    clear: np.ndarray
    directions: np.ndarray  # (L, 3) unit vectors from the transmitter toward the receiver

    @property
    def delay(self) -> np.ndarray:
        """Arrival time of the direct light d / c [s]."""
        return self.distance / SPEED_OF_LIGHT


def los_geometry(scene: Scene) -> LosGeometry:
    tx, rx = scene.transmitters, scene.receivers
    ti, ri = np.divmod(np.arange(scene.n_links), len(rx))
    to = rx.positions[ri] - tx.positions[ti]
    d = np.linalg.norm(to, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        wdir = to / d[:, None]
    wdir[d == 0] = 0.0
    cos_tx = np.einsum("ij,ij->i", wdir, tx.normals[ti])
    cos_rx = -np.einsum("ij,ij->i", wdir, rx.normals[ri])
    # A luminaire's photometric table may emit behind its aim: then only the receiver side is tested here.
    clear = (((cos_tx > 0) | (not tx.front_only)) & (cos_rx > 0) & (d > 0)).astype(float)
    idx = np.flatnonzero(clear > 0)
    if len(idx):
        isect = scene.intersector
        if not scene.all_visible:
            # Off both devices along their normals: a receiver on a floor or a desk top is not hidden by the
            # surface it sits on, whatever the incidence (ending the ray short of the receiver along the ray
            # instead dips below that surface past 60 deg from a lamp facing down).
            org = tx.positions[ti[idx]] + isect.offset * tx.normals[ti[idx]]
            end = rx.positions[ri[idx]] + isect.offset * rx.normals[ri[idx]]
            seg = end - org
            length = np.linalg.norm(seg, axis=1)
            blocked = isect.occluded(org, seg / length[:, None], length - isect.offset)
            clear[idx[blocked]] = 0.0
            idx = idx[~blocked]
        if scene.medium is not None and len(idx):
            clear[idx] = scene.medium.transmittance(tx.positions[ti[idx]], wdir[idx], d[idx])
    return LosGeometry(cos_tx, cos_rx, d, clear, wdir)


def line_of_sight(scene: Scene, geometry: LosGeometry | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(gain per watt, delay [s]) per link, flat in link order (tx * n_rx + rx).

    A spectral scene's gain is the whole spectrum's, sum_b f_b H_los,b (engine/spectral/spectra.py)."""
    g = geometry if geometry is not None else los_geometry(scene)
    gain = los_gain_grey(scene, g)
    if scene.spectra is not None:
        gain = los_channels(scene, g, gain)[scene.spectra.n_bands]
    return gain, g.delay


def los_gain_grey(scene: Scene, g: LosGeometry | None) -> np.ndarray:
    """Per link: the line-of-sight gain of the grey scene (a spectral scene's carrier band)."""
    if g is None:
        return np.zeros(scene.n_links)
    tx, rx = scene.transmitters, scene.receivers
    ti, ri = np.divmod(np.arange(scene.n_links), len(rx))
    ok = g.clear > 0
    d = np.where(ok, g.distance, 1.0)
    return np.where(ok, tx.response(ti, g.cos_tx, g.directions) * rx.response(ri, g.cos_rx) / (d * d) * g.clear, 0.0)


def los_channels(scene: Scene, g: LosGeometry, grey: np.ndarray) -> np.ndarray:
    """(V, L) line-of-sight gain of every channel of a spectral scene from the carrier's LOS gain `grey` (L,) and
    geometry `g`: band b is grey times T_b / T_c = exp(-tau_c (sigma_t,b / sigma_t,c - 1)) of the path."""
    sp = scene.spectra
    assert sp is not None
    B = sp.n_bands
    bands = np.repeat(grey[None, :], B, axis=0)
    if sp.tau_scale is not None and scene.medium is not None:
        idx = np.flatnonzero(grey > 0)
        if len(idx):
            tx = scene.transmitters.positions[np.arange(sp.n_links) // len(scene.receivers)]
            tau = scene.medium.optical_depth(tx[idx], g.directions[idx], g.distance[idx])
            bands[:, idx] *= np.exp(-sp.tau_scale[:, None] * tau[None, :])
    ti, ri = np.divmod(np.arange(sp.n_links), len(scene.receivers))
    _, ch = sp.channel_power(np.ones(sp.n_links), bands / np.where(grey > 0, grey, 1.0), ti, ri)
    return ch * grey[None, :]
