"""Line-of-sight term, computed exactly for every link (physics.md section 6, LOS closed form).

H_los = R(phi) * A cos(psi) T_s g rect(psi <= FOV) / d^2 * exp(-sigma_t d_in) * V,
R(phi) = (m+1)/(2 pi) cos^m(phi) (or a luminaire's tabulated I(gamma, C) / Phi), arriving at t = d / c. It has no variance, so the
Monte Carlo kernel never samples it; it is added to every estimate as a constant.
"""
from __future__ import annotations

import numpy as np

from .constants import SPEED_OF_LIGHT
from .scene import Scene


def line_of_sight(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(gain per watt, delay [s]) per link, flat in link order (tx * n_rx + rx)."""
    tx, rx = scene.transmitters, scene.receivers
    ti, ri = np.divmod(np.arange(scene.n_links), len(rx))
    to = rx.positions[ri] - tx.positions[ti]
    d = np.linalg.norm(to, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        wdir = to / d[:, None]
    coincident = d == 0
    wdir[coincident] = 0.0
    cos_tx = np.einsum("ij,ij->i", wdir, tx.normals[ti])
    cos_rx = -np.einsum("ij,ij->i", wdir, rx.normals[ri])
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(coincident, 0.0, tx.response(ti, cos_tx, wdir) * rx.response(ri, cos_rx) / np.where(coincident, 1.0, d * d))
    idx = np.flatnonzero(gain > 0)
    if len(idx):
        isect = scene.intersector
        org = tx.positions[ti[idx]] + isect.offset * tx.normals[ti[idx]]
        blocked = isect.occluded(org, wdir[idx], d[idx] - 2.0 * isect.offset)
        gain[idx[blocked]] = 0.0
        if scene.medium is not None:
            gain[idx] *= scene.medium.transmittance(tx.positions[ti[idx]], wdir[idx], d[idx])
    return gain, d / SPEED_OF_LIGHT
