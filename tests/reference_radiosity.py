"""Independent reference for bright rooms: radiosity of an empty box with one reflectance, all orders.

The box's faces are cut into square-ish patches of constant radiant exitance M_j [W/m^2 per W
emitted], each patch integrated on an n x n grid of sub-points (midpoint rule). With E_j the
direct irradiance of patch j from the point transmitter and F_ji the form factor from patch j
to patch i (F_ji = sum over sub-points cos_j cos_i / (pi d^2) dA_i, averaged over j's
sub-points; each row normalized to 1, the closure of a closed box), the exitance of every
reflection order at once solves (Goral et al. 1984; Cohen & Wallace 1993, ch. 2)
    M = rho (E + F M),   i.e.  (I - rho F) M = rho E,
and the receiver (a point of area A, FOV 90 deg) gets
    H0 = LOS + A sum_j M_j / pi  int_j cos_j cos_psi / d^2 dA.
No part of the engine is used. Its accuracy (patch size halved, quadrature refined, the first
order against tests/reference.py's exact patch integral) is stated in
tests/engine/test_bright_room.py.
"""

from __future__ import annotations

import math

import numpy as np


def _faces(size):
    """(origin, u edge, v edge, inward normal) of the six faces of the box [0, size]."""
    lx, ly, lz = size
    ex, ey, ez = np.eye(3)
    return [
        (np.zeros(3), lx * ex, ly * ey, ez),  # floor
        (lz * ez, lx * ex, ly * ey, -ez),  # ceiling
        (np.zeros(3), lx * ex, lz * ez, ey),  # wall y = 0
        (ly * ey, lx * ex, lz * ez, -ey),  # wall y = ly
        (np.zeros(3), ly * ey, lz * ez, ex),  # wall x = 0
        (lx * ex, ly * ey, lz * ez, -ex),  # wall x = lx
    ]


def _patches(size, patch: float, n_sub: int):
    """Sub-point positions (P, n_sub^2, 3), normals (P, 3), patch areas (P,), sub-point weights dA (P,)."""
    pts, nrm, area = [], [], []
    for o, u, v, n in _faces(size):
        nu = max(1, round(np.linalg.norm(u) / patch))
        nv = max(1, round(np.linalg.norm(v) / patch))
        s = (np.arange(n_sub) + 0.5) / n_sub
        for i in range(nu):
            for j in range(nv):
                a = (i + s[:, None]) / nu
                b = (j + s[None, :]) / nv
                p = o + a[..., None] * u + b[..., None] * v
                pts.append(p.reshape(-1, 3))
                nrm.append(n)
                area.append(np.linalg.norm(u) * np.linalg.norm(v) / (nu * nv))
    area = np.asarray(area)
    return np.asarray(pts), np.asarray(nrm), area, area / n_sub**2


def box_dc_gain(size, rhos, tx, tx_normal, m: float, rx, rx_normal, rx_area: float, patch=0.5, n_sub=3):
    """[(H0, H1)] per reflectance in `rhos`: H0 over all reflection orders and H1 of the first order alone (FOV
    90 deg), for the box [0, size] with that reflectance on every face."""
    pts, nrm, area, d_a = _patches(size, patch, n_sub)
    tx, tx_n, rx, rx_n = (np.asarray(x, float) for x in (tx, tx_normal, rx, rx_normal))
    # direct irradiance E_j (mean over the patch's sub-points)
    d = pts - tx
    r2 = (d * d).sum(-1)
    r = np.sqrt(r2)
    cos_tx = np.clip((d @ tx_n) / r, 0.0, None)
    cos_face = np.clip(-(d * nrm[:, None, :]).sum(-1) / r, 0.0, None)
    e = ((m + 1) / (2 * math.pi) * cos_tx**m * cos_face / r2).mean(axis=1)
    # coupling of each patch to the receiver: int cos_j cos_psi / (pi d^2) dA (times the receiver's area)
    d = rx - pts
    r2 = (d * d).sum(-1)
    r = np.sqrt(r2)
    cos_j = np.clip((d * nrm[:, None, :]).sum(-1) / r, 0.0, None)
    cos_psi = np.clip(-(d @ rx_n) / r, 0.0, None)
    to_rx = rx_area * (cos_j * cos_psi / (math.pi * r2)).sum(axis=1) * d_a
    # form factors F[j, i] from patch j to patch i, by sub-points, a row at a time
    n_p, n_s = pts.shape[:2]
    flat = pts.reshape(-1, 3)
    normals = np.repeat(nrm, n_s, axis=0)[None]
    f = np.zeros((n_p, n_p))
    for j in range(n_p):  # a loop over patches; each row is one array operation over all sub-point pairs
        d = flat[None, :, :] - pts[j][:, None, :]  # (n_s, P n_s, 3)
        r2 = (d * d).sum(-1)
        same = r2 == 0
        r = np.sqrt(np.where(same, 1.0, r2))
        cj = np.clip((d @ nrm[j]) / r, 0.0, None)
        ci = np.clip(-(d * normals).sum(-1) / r, 0.0, None)
        k = np.where(same, 0.0, cj * ci / (math.pi * r * r))
        f[j] = k.mean(axis=0).reshape(n_p, n_s).sum(axis=1) * d_a
    f /= f.sum(axis=1, keepdims=True)  # closure: every ray from a patch of a closed box lands on a patch
    d = rx - tx
    dist = np.linalg.norm(d)
    los = (m + 1) / (2 * math.pi) * max(d @ tx_n / dist, 0.0) ** m * max(-(d @ rx_n) / dist, 0.0) * rx_area / dist**2
    out = []
    for rho in rhos:
        exitance = np.linalg.solve(np.eye(n_p) - rho * f, rho * e)
        out.append((float(los + exitance @ to_rx), float(rho * e @ to_rx)))
    return out
