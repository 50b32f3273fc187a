"""Vectorized direction samplers and their solid-angle pdfs.

Conventions: ``u``, ``u1``, ``u2`` are uniform samples in [0, 1); directions
are float64 arrays of shape (n, 3) (any leading shape ``(..., 3)`` works);
local directions have +z along the surface normal; pdfs are solid-angle
densities in 1/sr.  Inversion-method references: Pharr, Jakob & Humphreys,
"Physically Based Rendering", 4th ed., sec. A.5 / 13.6; generalized
Lambertian source model: Gfeller & Bapst, Proc. IEEE 67(11), 1979.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "azimuth",
    "column_norms",
    "orthonormal_basis",
    "to_world",
    "sample_generalized_lambertian",
    "generalized_lambertian_pdf",
    "sample_cosine_cone",
    "cosine_cone_pdf",
    "sample_cosine_hemisphere",
    "sample_cosine_about",
    "sample_uniform_sphere",
    "uniform_sphere_pdf",
]

_TWO_PI = 2.0 * np.pi


def _f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def azimuth(u) -> tuple[np.ndarray, np.ndarray]:
    """(cos phi, sin phi) of phi = 2 pi u, u in [0, 1), float64, from one tangent.

    cos phi by the half-angle (Weierstrass) substitution about phi = pi: with tau = tan(pi (u - 1/2)),
        cos phi = (tau^2 - 1) / (1 + tau^2)   (to ~1e-16; at u = 0, tau ~ -1.6e16 is finite),
    and sin phi = -sign(tau) sqrt((1 - cos phi)(1 + cos phi)), so that cos^2 + sin^2 = 1 to rounding
    (the azimuth is then exact to ~1e-16 / |sin phi|, as from np.cos). numpy's float64 tangent is
    vectorized (~1 ns per value here), its float64 cosine and sine are not (~8 ns each).
    """
    u = _f64(u)
    tau = u.reshape(-1) - 0.5  # an array also for a scalar u (the in-place steps need one)
    tau *= np.pi
    np.tan(tau, out=tau)
    inv = tau * tau
    cos_phi = inv - 1.0
    inv += 1.0
    cos_phi /= inv
    sin_phi = np.subtract(1.0, cos_phi, out=inv)
    sin_phi *= 1.0 + cos_phi
    np.sqrt(sin_phi, out=sin_phi)
    np.negative(tau, out=tau)
    np.copysign(sin_phi, tau, out=sin_phi)
    return cos_phi.reshape(u.shape), sin_phi.reshape(u.shape)


def _from_polar(cos_t, sin_t, u2) -> np.ndarray:
    """(sin t cos phi, sin t sin phi, cos t) with phi = 2 pi u2."""
    cos_phi, sin_phi = azimuth(u2)
    cos_t, sin_t, cos_phi, sin_phi = np.broadcast_arrays(cos_t, sin_t, cos_phi, sin_phi)
    return np.stack((sin_t * cos_phi, sin_t * sin_phi, cos_t), axis=-1)


def polar_about_soa(cos_t, sin_t, u2, n) -> np.ndarray:
    """Directions (3, m) at polar angle t (cos_t, sin_t (m,)) and azimuth phi = 2 pi u2 about one unit normal n (3,).

    d = sin t cos phi s + sin t sin phi t + cos t n, frame (s, t) of `orthonormal_basis`, written on component
    rows (no (m, 3) stacks, no matrix product); cos phi and sin phi from `azimuth` (float64, one tangent).
    """
    a, b = azimuth(u2)
    a *= sin_t
    b *= sin_t
    n = _f64(n)
    s, t = orthonormal_basis(n)
    out = np.empty((3, len(a)))
    for k in range(3):
        out[k] = a * s[k] + b * t[k] + cos_t * n[k]
    return out


def orthonormal_basis(n) -> tuple[np.ndarray, np.ndarray]:
    """Tangents (s, t) such that (s, t, n) is a right-handed orthonormal frame.

    Branchless construction of Duff et al., "Building an Orthonormal Basis,
    Revisited", JCGT 6(1), 2017 (Listing 3):
        sgn = copysign(1, n_z), a = -1/(sgn + n_z), b = n_x n_y a,
        s = (1 + sgn n_x^2 a, sgn b, -sgn n_x),  t = (b, sgn + n_y^2 a, -n_y).
    ``n``: unit normals, shape (..., 3).  Stable for all n, including (0,0,+-1).
    """
    n = _f64(n)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sgn = np.copysign(1.0, z)
    a = -1.0 / (sgn + z)
    b = x * y * a
    s = np.stack((1.0 + sgn * x * x * a, sgn * b, -sgn * x), axis=-1)
    t = np.stack((b, sgn + y * y * a, -y), axis=-1)
    return s, t


def to_world(local, n) -> np.ndarray:
    """Map local directions (z along n) to world: d = l_x s + l_y t + l_z n.

    ``local``: (..., 3); ``n``: unit normals (..., 3) or one normal (3,)
    broadcast against all directions.  Frame from :func:`orthonormal_basis`.
    """
    local, n = _f64(local), _f64(n)
    s, t = orthonormal_basis(n)
    if n.ndim == 1:  # one frame for every direction: a single matrix product
        return local @ np.stack((s, t, n))
    return local[..., 0:1] * s + local[..., 1:2] * t + local[..., 2:3] * n


def sample_generalized_lambertian(m, u1, u2) -> np.ndarray:
    """Local directions with pdf (m+1)/(2 pi) cos^m(theta) on the hemisphere.

    Exact inversion of the cos-theta CDF F(c) = c^(m+1):
        cos theta = u1^(1/(m+1)) = exp(log(u1)/(m+1)),
        sin^2 theta = -expm1(2 log(u1)/(m+1)),  phi = 2 pi u2,
    which stays accurate for m = 0 ... 1000+ and u1 -> 0 or 1 (u1 = 1 -> pole).
    Ref.: Gfeller & Bapst 1979 (radiation model); PBRT 4th ed. A.5.
    """
    return _from_polar(*_lambertian_polar(m, u1), u2)


def _lambertian_polar(m, u1) -> tuple[np.ndarray, np.ndarray]:
    """(cos theta, sin theta) of `sample_generalized_lambertian`."""
    m, u1 = _f64(m), _f64(u1)
    with np.errstate(divide="ignore"):
        e = np.log(u1) / (m + 1.0)  # <= 0; -inf for u1 == 0
    return np.exp(e), np.sqrt(np.maximum(0.0, -np.expm1(2.0 * e)))


def generalized_lambertian_pdf(m, cos_theta) -> np.ndarray:
    """Solid-angle pdf (m+1)/(2 pi) cos^m(theta) for cos theta > 0, else 0."""
    m, c = _f64(m), _f64(cos_theta)
    return np.where(c > 0.0, (m + 1.0) / _TWO_PI * np.maximum(c, 0.0) ** m, 0.0)


def _sin2_from_cos(c):
    """1 - c^2 evaluated as (1 - c)(1 + c) (no cancellation near |c| = 1)."""
    return (1.0 - c) * (1.0 + c)


def sample_cosine_cone(cos_max, u1, u2) -> np.ndarray:
    """Local directions with pdf cos(theta) / (pi sin^2 theta_max), theta <= theta_max.

    Inversion (projected-solid-angle uniform on the cone's disk):
        sin^2 theta = u1 sin^2 theta_max,  sin^2 theta_max = (1 - cos_max)(1 + cos_max),
        cos^2 theta = (1 - u1) + u1 cos_max^2  (no cancellation at pole or rim),
        phi = 2 pi u2.
    Accurate for tiny cones (theta_max = 0.01 deg); cos_max = 0 gives the
    cosine-weighted hemisphere.  Ref.: PBRT 4th ed. sec. A.5.2 / 13.6.
    """
    return _from_polar(*_cone_polar(cos_max, u1), u2)


def _cone_polar(cos_max, u1) -> tuple[np.ndarray, np.ndarray]:
    """(cos theta, sin theta) of `sample_cosine_cone`."""
    cos_max, u1 = _f64(cos_max), _f64(u1)
    sin2 = u1 * _sin2_from_cos(cos_max)
    cos2 = (1.0 - u1) + u1 * (cos_max * cos_max)
    return np.sqrt(cos2), np.sqrt(sin2)


def cosine_cone_pdf(cos_max, cos_theta) -> np.ndarray:
    """Solid-angle pdf cos(theta) / (pi sin^2 theta_max) inside the cone, else 0."""
    cos_max, c = _f64(cos_max), _f64(cos_theta)
    inside = (c >= cos_max) & (c > 0.0)
    return np.where(inside, c / (np.pi * _sin2_from_cos(cos_max)), 0.0)


def sample_cosine_hemisphere(u1, u2) -> np.ndarray:
    """Cosine-weighted hemisphere, pdf cos(theta)/pi: sin^2 theta = u1 (Malley)."""
    return sample_cosine_cone(0.0, u1, u2)


def cosine_about_soa(n, u1, u2) -> np.ndarray:
    """:func:`sample_cosine_about` on component arrays: normals (3, n) -> directions (3, n).

    The azimuth's cosine and sine are evaluated in float32 (numpy vectorizes float32
    trigonometry, about 20x faster than float64 here); the direction is renormalized
    in float64, so its error is ~1e-7 rad, far below Embree's float32 ray precision.
    """
    u1 = _f64(u1)
    phi = (_TWO_PI * _f64(u2)).astype(np.float32)
    r = u1 * (1.0 - u1)
    np.sqrt(r, out=r)
    r *= 2.0
    d = np.empty_like(n)
    np.multiply(r, np.cos(phi), out=d[0])
    d[0] += n[0]
    np.multiply(r, np.sin(phi), out=d[1])
    d[1] += n[1]
    np.multiply(u1, -2.0, out=d[2])  # z = 1 - 2 u1, with n_z
    d[2] += 1.0
    d[2] += n[2]
    norm = column_norms(d)
    bad = norm < 1e-12
    if bad.any():  # s = -n: probability zero, mapped to n
        d[:, bad] = n[:, bad]
        norm[bad] = 1.0
    d *= 1.0 / norm
    return d


def column_norms(d) -> np.ndarray:
    """Euclidean norms of the columns of a (3, n) array (three products summed in place, one square root)."""
    norm = d[0] * d[0]
    norm += d[1] * d[1]
    norm += d[2] * d[2]
    return np.sqrt(norm, out=norm)


def sample_cosine_about(n, u1, u2) -> np.ndarray:
    """World directions with pdf cos(theta)/pi about unit normals n (..., 3), no frame needed.

    d = normalize(n + s), s uniform on the unit sphere: the tip of n + s is uniform on
    the sphere of radius 1 centred at n, which is tangent to the surface at the origin,
    and the direction to a uniform point of that sphere is cosine distributed (the
    sphere projects to the disk uniformly in projected solid angle; Malley's method
    in 3-D). s = -n has probability zero; it is mapped to n.
    """
    d = _f64(n) + sample_uniform_sphere(u1, u2)
    norm = np.sqrt(np.einsum("...i,...i->...", d, d))
    bad = norm < 1e-12
    if np.any(bad):
        d[bad] = _f64(n)[bad]
        norm[bad] = 1.0
    return d / norm[..., None]


def sample_uniform_sphere(u1, u2) -> np.ndarray:
    """Uniform directions on the unit sphere, pdf 1/(4 pi).

    z = 1 - 2 u1, sin theta = sqrt(1 - z^2) = 2 sqrt(u1 (1 - u1)), phi = 2 pi u2
    (Archimedes' hat-box theorem; PBRT 4th ed. sec. A.5.2).
    """
    u1 = _f64(u1)
    return _from_polar(1.0 - 2.0 * u1, 2.0 * np.sqrt(u1 * (1.0 - u1)), u2)


def uniform_sphere_pdf() -> float:
    """Solid-angle pdf of :func:`sample_uniform_sphere`: 1/(4 pi)."""
    return 1.0 / (4.0 * np.pi)


#: Most forward steps of a guide-table lookup before the binary search takes over.
GUIDE_STEPS = 3


class GuideTable:
    """``searchsorted(edges, keys, "right") - 1`` clipped to the segments, in O(1) per key.

    Guide table (Chen & Asau 1974): keys in [lo, hi] fall in equal buckets; each bucket
    stores the segment holding its start, and a key moves on by at most ``GUIDE_STEPS``
    vectorized steps. Keys in buckets spanning more segments (steep parts of a table), and
    any key the steps did not settle, take the binary search, so the answer is always exact.
    """

    def __init__(self, edges: np.ndarray, lo: float, hi: float, per_segment: int = 4):
        self.edges = edges
        self.m = len(edges) - 1  # segments
        self.n = per_segment * self.m  # buckets
        self.lo, self.scale = lo, self.n / (hi - lo)
        starts = lo + np.arange(self.n + 1) / self.scale
        self.start = np.clip(np.searchsorted(edges, starts, side="right") - 1, 0, self.m - 1)
        self.short = np.diff(self.start) <= GUIDE_STEPS

    def find(self, keys: np.ndarray) -> np.ndarray:
        e, m = self.edges, self.m
        k = np.clip(((keys - self.lo) * self.scale).astype(np.intp), 0, self.n - 1)
        i = self.start[k]
        for _ in range(GUIDE_STEPS):  # loop over steps, vectorized over keys
            step = (i < m - 1) & (e[np.minimum(i + 1, m)] <= keys)
            if not step.any():
                break
            i = i + step
        bad = ~self.short[k] | ((i > 0) & (e[i] > keys)) | ((i < m - 1) & (e[np.minimum(i + 1, m)] <= keys))
        if bad.any():
            i[bad] = np.clip(np.searchsorted(e, keys[bad], side="right") - 1, 0, m - 1)
        return i
