"""Deterministic single-scattering reference in an unbounded homogeneous medium (no surfaces).

Independent of the engine (plain numpy, its own phase function). Transmitter at the
origin facing +x (generalized Lambertian of order m), receiver at (D, 0, 0) facing -x
with FOV 90 deg, so the scattering volume is the slab 0 < x < D:

    H1 = int_V R(phi) / r1^2 e^{-sigma_t r1} sigma_s p(cos theta) A cos(psi) / r2^2 e^{-sigma_t r2} dV

with cos theta = (p - Tx)/r1 . (Rx - p)/r2 (propagation directions before and after
the scattering event). The 1/r^2 singularities sit at the two devices; the slab is
split by the plane x = D/2 and each half is integrated in spherical coordinates
centred on its own device (dV = r^2 dr dOmega cancels that device's 1/r^2; the other
device is at least D/2 away), with Gauss-Legendre nodes in cos(alpha), the radius and
the azimuth. Every node carries a delay (r1 + r2)/c, so the same nodes give the CIR.
"""

from __future__ import annotations

import numpy as np

SPEED_OF_LIGHT = 299_792_458.0


def hg(cos, g):
    return (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * cos) ** 1.5)


def _half(D, m, area, sigma_s, sigma_t, g, n, from_tx: bool):
    """Nodes (weights, delays) of one half: spherical coordinates about the Tx (or the Rx)."""
    ca, wa = np.polynomial.legendre.leggauss(n)
    ca, wa = 0.5 * (ca + 1), 0.5 * wa  # cos(alpha) in (0, 1) about the axis toward the other device
    beta = (np.arange(2 * n) + 0.5) * np.pi / n  # azimuth, periodic: midpoint rule is spectral
    wb = np.full(2 * n, np.pi / n)
    xr, wr = np.polynomial.legendre.leggauss(n)
    xr, wr = 0.5 * (xr + 1), 0.5 * wr
    CA, B, XR = np.meshgrid(ca, beta, xr, indexing="ij")
    W = wa[:, None, None] * wb[None, :, None] * wr[None, None, :]
    sa = np.sqrt(1 - CA * CA)
    r_max = 0.5 * D / CA  # up to the bisector plane
    r = XR * r_max
    W = W * r_max  # dr
    local = np.stack([CA * r, sa * np.cos(B) * r, sa * np.sin(B) * r])  # x along the axis
    if from_tx:
        p = local
    else:
        p = np.stack([D - local[0], local[1], local[2]])
    v1 = p
    r1 = np.sqrt((v1**2).sum(0))
    v2 = np.array([D, 0, 0])[:, None, None, None] - p
    r2 = np.sqrt((v2**2).sum(0))
    cos_tx = v1[0] / r1
    cos_rx = v2[0] / r2
    cos_th = (v1 * v2).sum(0) / (r1 * r2)
    f = (
        (m + 1)
        / (2 * np.pi)
        * np.clip(cos_tx, 0, None) ** m
        * np.exp(-sigma_t * (r1 + r2))
        * sigma_s
        * hg(cos_th, g)
        * area
        * np.clip(cos_rx, 0, None)
    )
    # dV = r^2 dr dOmega about the chosen device; its own 1/r^2 cancels.
    f = f / (r2**2) if from_tx else f / (r1**2)
    return (f * W).ravel(), ((r1 + r2) / SPEED_OF_LIGHT).ravel()


def single_scattering(D, m, area, sigma_s, sigma_t, g, n=96, t_edges=None):
    """(H1, histogram over t_edges or None) of the single-scattering gain [per watt]."""
    parts = [_half(D, m, area, sigma_s, sigma_t, g, n, side) for side in (True, False)]
    w = np.concatenate([p[0] for p in parts])
    t = np.concatenate([p[1] for p in parts])
    hist = None if t_edges is None else np.histogram(t, bins=t_edges, weights=w)[0]
    return float(w.sum()), hist
