"""Independent double-scattering reference in an unbounded homogeneous medium (no surfaces).

Plain numpy, its own samplers and phase function; nothing from the engine. Transmitter
at the origin facing +x (generalized Lambertian of order m), receiver at (D, 0, 0)
facing -x with area A and FOV 90 deg. The s = 2 gain is a volume integral over two
points p1, p2:

    H2 = int int R(phi) / r1^2 e^{-st r1} ss p(cos th1) e^{-st r12} / r12^2 ss p(cos th2)
                 A cos(psi) / r2^2 e^{-st r2} dV1 dV2,

cos th1 = (p1 - Tx)/r1 . (p2 - p1)/r12, cos th2 = (p2 - p1)/r12 . (Rx - p2)/r2.
Its integrand is singular at p1 = Tx, p2 = Rx and p1 = p2. It is estimated by plain Monte
Carlo with three sampling strategies (N points each), combined by the balance heuristic
(Veach 1997):
  1. p1 from the transmitter (direction ~ R, distance ~ Exp(st)), p2 = p1 + Exp(st) x uniform direction;
  2. p2 from the receiver (cosine direction, Exp(st)), p1 = p2 + Exp(st) x uniform direction;
  3. p1 from the transmitter and p2 from the receiver, independently.
Each pair gets f / (q1 + q2 + q3) with q_i the volume densities of the three strategies;
since r1 + r12 + r2 >= D, one of the three densities always matches the integrand's
singular factor, so every sample is bounded: the estimate has finite variance and an
honest standard error.
"""

from __future__ import annotations

import numpy as np

SPEED_OF_LIGHT = 299_792_458.0


def hg(cos, g):
    return (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * cos) ** 1.5)


def _uniform_dirs(rng, n):
    z = 2 * rng.random(n) - 1
    phi = 2 * np.pi * rng.random(n)
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z])


def _cone_dirs(rng, n, m, axis_sign):
    """Directions about +-x with pdf (m+1)/(2 pi) cos^m (m = 1 for the cosine-weighted receiver)."""
    c = rng.random(n) ** (1.0 / (m + 1))
    s = np.sqrt(np.maximum(0.0, 1 - c * c))
    phi = 2 * np.pi * rng.random(n)
    return np.stack([axis_sign * c, s * np.cos(phi), s * np.sin(phi)])


def double_scattering(D, m, area, sigma_s, sigma_t, g, n=200_000, seed=0, t_edges=None):
    """(H2, its standard error, histogram over t_edges or None) [per watt]."""
    rng = np.random.default_rng(seed)
    tx, rx = np.zeros((3, 1)), np.array([[D], [0.0], [0.0]])

    def from_tx(k):
        return tx + _cone_dirs(rng, k, m, 1.0) * rng.exponential(1 / sigma_t, k)

    def from_rx(k):
        return rx + _cone_dirs(rng, k, 1.0, -1.0) * rng.exponential(1 / sigma_t, k)

    p1a = from_tx(n)
    p2a = p1a + _uniform_dirs(rng, n) * rng.exponential(1 / sigma_t, n)
    p2b = from_rx(n)
    p1b = p2b + _uniform_dirs(rng, n) * rng.exponential(1 / sigma_t, n)
    p1c, p2c = from_tx(n), from_rx(n)
    values, delays = [], []
    for p1, p2 in ((p1a, p2a), (p1b, p2b), (p1c, p2c)):
        v1, v12, v2 = p1 - tx, p2 - p1, rx - p2
        r1, r12, r2 = (np.sqrt((v * v).sum(0)) for v in (v1, v12, v2))
        cos_tx = v1[0] / r1
        cos_rx = v2[0] / r2  # receiver faces -x: light arriving along +x
        r_tx = np.where(cos_tx > 0, (m + 1) / (2 * np.pi) * np.clip(cos_tx, 0, None) ** m, 0.0)
        r_rx = np.where(cos_rx > 0, cos_rx, 0.0)
        e1, e12, e2 = np.exp(-sigma_t * r1), np.exp(-sigma_t * r12), np.exp(-sigma_t * r2)
        c1 = (v1 * v12).sum(0) / (r1 * r12)
        c2 = (v12 * v2).sum(0) / (r12 * r2)
        f = r_tx / r1**2 * e1 * sigma_s * hg(c1, g) * e12 / r12**2 * sigma_s * hg(c2, g) * area * r_rx / r2**2 * e2
        q_tx = r_tx / r1**2 * sigma_t * e1
        q_rx = r_rx / np.pi / r2**2 * sigma_t * e2
        q_link = sigma_t * e12 / (4 * np.pi * r12**2)
        q = q_tx * q_link + q_rx * q_link + q_tx * q_rx
        values.append(np.where(q > 0, f / np.where(q > 0, q, 1.0), 0.0))
        delays.append((r1 + r12 + r2) / SPEED_OF_LIGHT)
    h2 = sum(v.mean() for v in values)
    se = float(np.sqrt(sum(v.var(ddof=1) / n for v in values)))
    hist = None
    if t_edges is not None:
        hist = sum(np.histogram(t, bins=t_edges, weights=v)[0] for v, t in zip(values, delays)) / n
    return float(h2), se, hist
