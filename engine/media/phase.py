"""Phase functions of the smoke medium (physics.md section 3; report section 3, eq. 3.3).

Sign convention (the only place it is defined): ``cos_theta`` is the cosine between the
propagation direction BEFORE a scattering event and the propagation direction AFTER it;
g > 0 (or Schlick k > 0) is forward scattering (cos_theta near +1 most likely).
Every phase function is a pdf on the sphere: integral of p d(omega) = 1, p in 1/sr, so
the cos_theta density is 2 pi p(cos_theta).  Every ``sample_cos`` is the exact inverse of
the cos_theta CDF F(c) = 2 pi int_{-1}^{c} p, hence the pdf of ``sample`` equals ``eval``.
Directions are component arrays of shape (3, n) (rows x, y, z); all float64, vectorized.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import ArrayLike
from pydantic import TypeAdapter

from owcsim.engine.core.arrays import FloatArray
from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.sampling import GuideTable, azimuth, column_norms
from owcsim.engine.media.mie import particle_optics
from owcsim.schemas.medium import PhaseSpec

__all__ = [
    "PhaseFunction",
    "Isotropic",
    "HenyeyGreenstein",
    "Schlick",
    "Rayleigh",
    "Mixture",
    "Tabulated",
    "MiePhase",
    "schlick_mean_cosine",
    "SCHLICK_BLASI_G_MAX",
    "phase_functions",
    "phase_from_spec",
    "describe_phase",
]

_INV_4PI = 1.0 / (4.0 * np.pi)
_BELOW_ONE = np.nextafter(1.0, 0.0)
#: |g| above which Blasi's k = 1.55 g - 0.55 g^3 reaches |k| = 1: root of 0.55 g^2 + 0.55 g - 1.
SCHLICK_BLASI_G_MAX = (-0.55 + np.sqrt(0.55**2 + 4 * 0.55)) / 1.1  # 0.938121...


def _f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _open_unit(name: str, x) -> float:
    x = float(x)
    if not -1.0 < x < 1.0:  # also rejects NaN
        raise ValueError(f"{name} must lie in the open interval (-1, 1), got {x!r}")
    return x


def _from_sides(a, b):
    """cos from a = 1 - cos and b = 1 + cos (both >= 0), using the smaller (cancellation-free) one; in [-1, 1]
    without clipping (1 - a <= 1 and b - 1 >= -1 for a, b >= 0)."""
    return np.where(a <= b, 1.0 - a, b - 1.0)


class PhaseFunction(ABC):
    """The interface of every phase function: ``eval`` and ``sample_cos`` (each subclass), ``pdf`` and ``sample``
    (shared), ``mean_cosine``."""

    mean_cosine: float  #: g = <cos_theta> = 2 pi int c p(c) dc (a property in every subclass)

    @abstractmethod
    def eval(self, cos_theta: ArrayLike) -> FloatArray:
        """p(cos_theta) [1/sr]."""

    @abstractmethod
    def sample_cos(self, u: ArrayLike) -> FloatArray:
        """cos_theta = F^{-1}(u), u uniform in [0, 1) (the exact inverse of the cos_theta CDF)."""

    def pdf(self, cos_theta: ArrayLike) -> FloatArray:
        """Solid-angle pdf of :meth:`sample` [1/sr]; equals :meth:`eval` (exact sampling)."""
        return self.eval(cos_theta)

    def sample(self, directions: ArrayLike, u1: ArrayLike, u2: ArrayLike) -> FloatArray:
        """New unit directions (3, n) around ``directions`` (3, n): cos = sample_cos(u1), phi = 2 pi u2.

        d' = sin(t) cos(phi) s + sin(t) sin(phi) t + cos(t) d, with (s, t, d) the frame of
        :func:`engine.core.sampling.orthonormal_basis` (Duff et al. 2017, stable for d = (0, 0, +-1)),
        written out on the component rows (no (n, 3) stacks and transposes). float64 throughout: the
        azimuth is exact to 1e-8 rad (tests/engine/test_phase.py), unlike sampling.cosine_about_soa's
        float32 trigonometry.
        """
        d = _f64(directions)
        if d.ndim != 2 or d.shape[0] != 3:
            raise ValueError(f"directions must have shape (3, n), got {d.shape}")
        c, sin_t = self._sample_cos_sin(u1)
        if np.shape(c) != d.shape[1:]:
            c, sin_t = np.broadcast_to(c, d.shape[1:]), np.broadcast_to(sin_t, d.shape[1:])
        # azimuth phi = 2 pi u2 (sampling.azimuth: cos and sin from one vectorized tangent)
        cos_phi, sin_phi = azimuth(np.broadcast_to(_f64(u2), d.shape[1:]))
        along_s = np.multiply(sin_t, cos_phi, out=cos_phi)  # sin(theta) cos(phi)
        along_t = np.multiply(sin_t, sin_phi, out=sin_phi)  # sin(theta) sin(phi)
        x, y, z = d
        sgn = np.copysign(1.0, z)
        a = sgn + z
        np.divide(-1.0, a, out=a)
        b = x * y
        b *= a
        # s = (1 + sgn x^2 a, sgn b, -sgn x), t = (b, sgn + y^2 a, -y)
        out = np.empty_like(d)
        o0, o1, o2 = out
        np.multiply(x, x, out=o0)
        o0 *= a
        o0 *= sgn
        o0 += 1.0
        o0 *= along_s
        tmp = b * along_t
        o0 += tmp
        np.multiply(c, x, out=tmp)
        o0 += tmp
        np.multiply(y, y, out=o1)
        o1 *= a
        o1 += sgn
        o1 *= along_t
        np.multiply(sgn, b, out=tmp)
        tmp *= along_s
        o1 += tmp
        np.multiply(c, y, out=tmp)
        o1 += tmp
        np.multiply(c, z, out=o2)
        along_s *= sgn
        along_s *= x
        o2 -= along_s
        along_t *= y
        o2 -= along_t
        out /= column_norms(out)
        return out

    def _sample_cos_sin(self, u):
        """(cos, sin) of the sampled angle: sample_cos(u) and sqrt((1 - cos)(1 + cos)) (subclasses with
        the two sides of the cosine at hand give the sine more cheaply and more accurately)."""
        c = self.sample_cos(u)
        return c, np.sqrt(np.maximum(0.0, (1.0 - c) * (1.0 + c)))

    @classmethod
    def from_spec(cls, spec) -> "PhaseFunction":
        return cls()

    def __repr__(self):
        args = ", ".join(f"{k}={v!r}" for k, v in vars(self).items() if not k.startswith("_"))
        return f"{type(self).__name__}({args})"


class Isotropic(PhaseFunction):
    """p = 1 / (4 pi); cos = 2u - 1; g = 0."""

    def eval(self, cos_theta):
        return np.full(np.shape(cos_theta), _INV_4PI)

    def sample_cos(self, u):
        return 2.0 * _f64(u) - 1.0

    mean_cosine = property(lambda self: 0.0)


class HenyeyGreenstein(PhaseFunction):
    """p = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2)), -1 < g < 1, mean cosine g.

    Henyey & Greenstein, Astrophys. J. 93, 70 (1941); inversion: PBRT 4th ed. sec. 11.3.1.
    """

    def __init__(self, g: float):
        self.g = _open_unit("Henyey-Greenstein g", g)

    def eval(self, cos_theta):
        g = self.g
        c = _f64(cos_theta)
        if c.ndim == 0:
            c = c.reshape(1)
            return self.eval(c)[0]
        # 1 + g^2 - 2 g c as a sum of non-negative terms (exact for |g| -> 1 near the peak): |1 -+ c| reflects
        # a cosine rounded past +-1 back (p changes there as by one rounding of c); in place, one array besides
        # the result
        if g >= 0:
            q = np.subtract(1.0, c)
            k2, k0 = 2 * g, (1 - g) ** 2
        else:
            q = np.add(1.0, c)
            k2, k0 = -2 * g, (1 + g) ** 2
        np.abs(q, out=q)
        q *= k2
        q += k0
        r = np.sqrt(q)
        r *= q
        return np.divide((1 - g) * (1 + g) * _INV_4PI, r, out=r)

    def _sides(self, u):
        """(1 - cos, 1 + cos) of sample_cos(u), each from the closed form without cancellation (below)."""
        g, u = self.g, _f64(u)
        v = 1.0 - u  # exact for u >= 1/2
        if g >= 0:  # w = 1 - g + 2 g u, gu = 1 + g u, gv = 1 - g + g u
            w, gu, gv = u * (2 * g), u * g, u * g
            w += 1 - g
            gu += 1
            gv += 1 - g
        else:  # the same with u -> 1 - v
            w, gu, gv = v * (-2 * g), v * (-g), v * (-g)
            w += 1 + g
            gu += 1 + g
            gv += 1
        w *= w
        a = v * gu
        a /= w
        a *= 2 * (1 - g) ** 2
        b = u * gv
        b /= w
        b *= 2 * (1 + g) ** 2
        return a, b

    def sample_cos(self, u):
        """Closed-form inversion cos = (1 + g^2 - ((1 - g^2)/(1 - g + 2 g u))^2) / (2 g), rewritten:

        with w = 1 - g + 2 g u,
            1 - cos = 2 (1 - g)^2 (1 - u) (1 + g u) / w^2,
            1 + cos = 2 (1 + g)^2 u (1 - g (1 - u)) / w^2.
        No division by g (g = 0 gives cos = 2u - 1 exactly, so no isotropic branch is
        needed for tiny |g|) and no cancellation, also for |g| -> 1.
        """
        return _from_sides(*self._sides(u))

    def _sample_cos_sin(self, u):
        """sin = sqrt((1 - cos)(1 + cos)) from the two sides themselves (exact to rounding at cos -> +-1)."""
        a, b = self._sides(u)
        return _from_sides(a, b), np.sqrt(a * b)

    mean_cosine = property(lambda self: self.g)

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.g)


def schlick_mean_cosine(k) -> np.ndarray:
    """Exact mean cosine of Schlick(k): <cos> = 1/k - (1 - k^2) artanh(k) / k^2.

    For |k| < 1e-2 the series sum_{n>=1} 2 k^(2n-1) / (4 n^2 - 1) = 2k/3 + 2k^3/15 + ...
    avoids the cancellation.  Note <cos> != k (and != g of the HG it approximates).
    """
    k = _f64(k)
    ks = np.where(np.abs(k) < 1e-2, 0.5, k)  # keep the closed form finite on masked entries
    closed = 1.0 / ks - (1.0 - ks * ks) * np.arctanh(ks) / (ks * ks)
    k2 = k * k
    series = k * (2 / 3 + k2 * (2 / 15 + k2 * (2 / 35 + k2 * 2 / 63)))
    return np.where(np.abs(k) < 1e-2, series, closed)


class Schlick(PhaseFunction):
    """p = (1 - k^2) / (4 pi (1 - k cos)^2), -1 < k < 1; k > 0 forward.

    Blasi, Le Saec & Schlick, Computer Graphics Forum 12(3) (Eurographics '93), 201-212.
    CDF F(c) = (1 - k)(1 + c) / (2 (1 - k c)); inversion cos = (2u + k - 1) / (2 k u - k + 1).
    """

    def __init__(self, k: float):
        self.k = _open_unit("Schlick k", k)

    @classmethod
    def from_g(cls, g: float, method: str = "blasi") -> "Schlick":
        """Schlick approximating HG(g).

        ``"blasi"``: k = 1.55 g - 0.55 g^3 (Blasi et al. 1993; odd in g, so the report's
        "g^2" is a typo).  It is a fit, not a moment match: the mean cosine is off by up
        to 0.075 (at |g| = 0.85), and it gives |k| >= 1 for |g| >= SCHLICK_BLASI_G_MAX
        = 0.9381, which is rejected.  ``"exact"``: k such that the mean cosine is exactly g (bisection
        on :func:`schlick_mean_cosine`, monotone in k), valid on all of (-1, 1).
        """
        g = _open_unit("Schlick g", g)
        if method == "blasi":
            if abs(g) >= SCHLICK_BLASI_G_MAX:
                raise ValueError(
                    f"Blasi's k = 1.55 g - 0.55 g^3 gives |k| >= 1 for |g| >= "
                    f"{SCHLICK_BLASI_G_MAX:.4f} (got g = {g}); give k, or method='exact'"
                )
            return cls(1.55 * g - 0.55 * g**3)
        if method != "exact":
            raise ValueError(f"unknown Schlick mapping {method!r} (use 'blasi' or 'exact')")
        lo, hi = -1.0, 1.0
        for _ in range(64):  # interval 2^-63: below the spacing of doubles near +-1
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if schlick_mean_cosine(mid) < g else (lo, mid)
        return cls(min(max(0.5 * (lo + hi), -_BELOW_ONE), _BELOW_ONE))

    def eval(self, cos_theta):
        k, c = self.k, np.clip(_f64(cos_theta), -1.0, 1.0)
        q = (1 - k) + k * (1 - c) if k >= 0 else (1 + k) - k * (1 + c)  # 1 - k c, no cancellation
        return (1 - k) * (1 + k) * _INV_4PI / (q * q)

    def sample_cos(self, u):
        """With D = 2 k u - k + 1:  1 - cos = 2 (1 - k)(1 - u) / D,  1 + cos = 2 (1 + k) u / D."""
        k, u = self.k, _f64(u)
        d = (1 - k) + 2 * k * u if k >= 0 else (1 + k) - 2 * k * (1.0 - u)
        return _from_sides(2 * (1 - k) * (1.0 - u) / d, 2 * (1 + k) * u / d)

    mean_cosine = property(lambda self: float(schlick_mean_cosine(self.k)))

    @classmethod
    def from_spec(cls, spec):
        """A spec's `g` maps to the k whose mean cosine is exactly g: the user asked for an
        asymmetry g, and Blasi's polynomial misses it by up to 0.075 (at |g| = 0.85) and
        has no valid k above |g| = 0.938."""
        return cls(spec.k) if spec.k is not None else cls.from_g(spec.g, method="exact")


class Rayleigh(PhaseFunction):
    """p = 3 (1 + cos^2) / (16 pi); g = 0.  Rayleigh, Phil. Mag. 41 (1871); Chandrasekhar 1950.

    CDF F(c) = (c^3 + 3c + 4) / 8.  F(c) = u is the depressed cubic c^3 + 3c + (4 - 8u) = 0
    (one real root); Cardano gives c = A - 1/A with A = cbrt(z + sqrt(z^2 + 1)), z = 4u - 2,
    and since z + sqrt(z^2 + 1) = exp(asinh z):  cos = 2 sinh(asinh(4u - 2) / 3)  (exact, stable).
    """

    def eval(self, cos_theta):
        c = np.clip(_f64(cos_theta), -1.0, 1.0)
        return 3.0 / (16.0 * np.pi) * (1.0 + c * c)

    def sample_cos(self, u):
        return np.clip(2.0 * np.sinh(np.arcsinh(4.0 * _f64(u) - 2.0) / 3.0), -1.0, 1.0)

    mean_cosine = property(lambda self: 0.0)


class Mixture(PhaseFunction):
    """p = sum_i w_i p_i with sum_i w_i = 1 (report eq. 3.3), e.g. two-term HG; g = sum w_i g_i.

    Sampling uses one uniform: u in [W_{i-1}, W_i) (W the cumulative weights) selects
    component i, and (u - W_{i-1}) / w_i is passed to its sample_cos.
    """

    def __init__(self, components):
        if not (comps := list(components)):
            raise ValueError("a mixture needs at least one (weight, phase) component")
        for w, p in comps:
            if not isinstance(p, PhaseFunction):
                raise TypeError(f"mixture component {p!r} is not a PhaseFunction")
            if not (np.isfinite(w) and w >= 0):
                raise ValueError(f"mixture weights must be finite and >= 0, got {w!r}")
        if (largest := max(float(w) for w, _ in comps)) <= 0:
            raise ValueError("mixture weights are all zero")
        comps = [(float(w) / largest, p) for w, p in comps if w > 0]  # scaled first: the sum cannot overflow
        total = sum(w for w, _ in comps)
        comps = [(w / total, p) for w, p in comps]
        self.weights = np.array([w for w, _ in comps])
        self.components = tuple(p for _, p in comps)
        self._edges = np.concatenate(([0.0], np.cumsum(self.weights)))

    def eval(self, cos_theta):
        return sum(w * p.eval(cos_theta) for w, p in self._pairs())

    def sample_cos(self, u):
        u = _f64(u)
        flat = u.reshape(-1)  # u in [W_{i-1}, W_i) -> component i, rescaled to [0, 1)
        idx = np.clip(np.searchsorted(self._edges, flat, side="right") - 1, 0, len(self.weights) - 1)
        v = np.clip((flat - self._edges[idx]) / self.weights[idx], 0.0, _BELOW_ONE)
        out = np.empty_like(flat)
        for i, p in enumerate(self.components):  # loop over components, not samples
            m = idx == i
            out[m] = p.sample_cos(v[m])
        return out.reshape(u.shape)

    mean_cosine = property(lambda self: float(sum(w * p.mean_cosine for w, p in self._pairs())))

    def _pairs(self):
        return zip(self.weights, self.components)

    @classmethod
    def from_spec(cls, spec):
        return cls([(c.weight, phase_from_spec(c.phase)) for c in spec.components])

    def __repr__(self):
        return f"Mixture({[(float(w), p) for w, p in self._pairs()]!r})"


def _ldexp_or_inf(x: float, exponent: int) -> float:
    """x 2^exponent, inf when it exceeds the float max (math.ldexp raises instead)."""
    try:
        return math.ldexp(x, exponent)
    except OverflowError:
        return math.inf


class Tabulated(PhaseFunction):
    """A phase function given at points of cos(theta), linear in cos(theta) between them.

    ``cos_theta`` (n,) strictly increasing from -1 to 1; ``values`` (n,) >= 0 [1/sr up to a
    common factor]. The phase function is p(c) = v(c) / normalisation with v the linear
    interpolant and normalisation = 2 pi int_{-1}^{1} v dc (trapezoid rule, exact for it);
    ``normalisation`` is reported (1 for a table that was normalised already). The values are first
    divided by the power of two of their largest (exact), so any common factor works, up to values
    at the float max (whose normalisation, past it, is inf and reported as None).
    Mean cosine, exact for the interpolant: on [a, b] of width h,
    int c v dc = h (v_a (2a + b) + v_b (a + 2b)) / 6.
    Sampling inverts the CDF exactly: segment i by its cumulative mass, then within it
    int_0^x (v_a + s t) dt = r with s = (v_b - v_a)/h gives the root
    x = 2 r / (v_a + sqrt(v_a^2 + 2 s r)) (no cancellation; v_a^2 + 2 s r >= v_b^2 >= 0).
    """

    def __init__(self, cos_theta, values):
        c, v = _f64(cos_theta), _f64(values)
        if c.ndim != 1 or v.ndim != 1 or len(c) != len(v):
            raise ValueError(
                f"a tabulated phase function needs cos_theta and values of one length, got shapes "
                f"{c.shape} and {v.shape}"
            )
        if len(c) < 2:
            raise ValueError("a tabulated phase function needs at least 2 points")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(v))):
            raise ValueError("tabulated phase function: cos_theta and values must be finite")
        if c[0] != -1.0 or c[-1] != 1.0:
            raise ValueError(
                f"tabulated phase function: cos_theta must run from exactly -1 to exactly 1, "
                f"got {float(c[0])!r} .. {float(c[-1])!r}"
            )
        if np.any(bad := np.diff(c) <= 0):
            i = int(np.argmax(bad)) + 1
            raise ValueError(
                f"tabulated phase function: cos_theta must be strictly increasing (entry {i}, "
                f"{float(c[i])!r}, does not exceed entry {i - 1}, {float(c[i - 1])!r})"
            )
        if np.any(v < 0):
            i = int(np.argmax(v < 0))
            raise ValueError(f"tabulated phase function: values must be >= 0 (entry {i} is {float(v[i])!r})")
        h = np.diff(c)
        # the common factor first: v = w 2^e with max w in [0.5, 1) (exact), so that sums of values up to
        # the float max do not overflow and a table already normalised gives the same bits as without
        exponent = int(np.frexp(v.max())[1])
        w = np.ldexp(v, -exponent)
        mass = 0.5 * (w[:-1] + w[1:]) * h  # int w dc per segment
        total = float(mass.sum())
        if not total > 0:
            raise ValueError("tabulated phase function: values are all zero (no positive integral)")
        self.cos_theta = c
        self.values = w / (2.0 * np.pi * total)  #: p at the points [1/sr], normalised over the sphere
        #: 2 pi int v dc of the values as given [-] (inf past the float max: values near 1e308)
        self.normalisation = _ldexp_or_inf(2.0 * np.pi * total, exponent)
        self._h = h
        self._slope = np.diff(self.values) / h
        cdf = np.concatenate(([0.0], np.cumsum(mass))) / total
        cdf[-1] = 1.0
        self._cdf = cdf
        self._mass = np.diff(cdf) / (2.0 * np.pi)  # int p dc per segment
        self._by_u = GuideTable(cdf, 0.0, 1.0)
        self._by_cos = GuideTable(c, -1.0, 1.0)
        a, b = c[:-1], c[1:]
        self._mean = float(
            2.0 * np.pi * np.sum(h * (self.values[:-1] * (2 * a + b) + self.values[1:] * (a + 2 * b))) / 6.0
        )

    def eval(self, cos_theta):
        """Linear interpolation (as np.interp), the segment found by a guide table."""
        c = np.clip(_f64(cos_theta), -1.0, 1.0)
        flat = c.reshape(-1)
        i = self._by_cos.find(flat)
        out = self.values[i] + self._slope[i] * (flat - self.cos_theta[i])
        return np.maximum(out, 0.0).reshape(c.shape)

    def sample_cos(self, u):
        u = _f64(u)
        flat = u.reshape(-1)
        i = self._by_u.find(flat)
        r = np.clip((flat - self._cdf[i]) / (2.0 * np.pi), 0.0, self._mass[i])  # int_a^c p dc still to cover
        va, s = self.values[i], self._slope[i]
        den = va + np.sqrt(np.maximum(va * va + 2.0 * s * r, 0.0))
        x = np.where(den > 0, 2.0 * r / np.where(den > 0, den, 1.0), 0.0)
        out = np.minimum(self.cos_theta[i] + np.minimum(x, self._h[i]), self.cos_theta[i + 1])
        return out.reshape(u.shape)

    mean_cosine = property(lambda self: self._mean)

    @classmethod
    def from_spec(cls, spec):
        if spec.cos_theta is not None:
            return cls(spec.cos_theta, spec.values)
        # angles increase from 0 to 180 deg: cos decreases from 1 to -1; reversed, with exact end points
        theta = np.deg2rad(_f64(spec.angle_deg))[::-1]
        c = np.cos(theta)
        c[0], c[-1] = -1.0, 1.0
        if np.any(np.diff(c) <= 0):
            raise SceneError("medium.phase.angle_deg: two angles are too close to give distinct cos(theta)")
        return cls(c, _f64(spec.values)[::-1])

    def describe(self) -> dict:
        """Type, points, mean cosine and `normalisation` (None when it exceeds the float max)."""
        return {
            "type": "tabulated",
            "points": len(self.cos_theta),
            "mean_cosine": self.mean_cosine,
            "normalisation": self.normalisation if math.isfinite(self.normalisation) else None,
        }

    def __repr__(self):
        return f"Tabulated(points={len(self.cos_theta)}, mean_cosine={self.mean_cosine:.6g})"


class MiePhase(Tabulated):
    """The size-averaged Mie phase function of a particle spec, as a fine table (engine/media/mie.py)."""

    @classmethod
    def from_spec(cls, spec):
        optics = particle_optics(spec.particles)
        return cls(optics.cos_theta, optics.phase)

    def describe(self) -> dict:
        return {**super().describe(), "type": "mie"}

    def __repr__(self):
        return f"MiePhase(points={len(self.cos_theta)}, mean_cosine={self.mean_cosine:.6g})"


#: Phase-function classes keyed by the ``type`` literal of schemas.medium's phase specs.
phase_functions: dict[str, type[PhaseFunction]] = {
    "isotropic": Isotropic,
    "hg": HenyeyGreenstein,
    "schlick": Schlick,
    "rayleigh": Rayleigh,
    "mixture": Mixture,
    "tabulated": Tabulated,
    "mie": MiePhase,
}


def describe_phase(phase: PhaseFunction) -> dict:
    """What a result reports about a phase function: its type, mean cosine and (tables) normalisation."""
    if hasattr(phase, "describe"):
        return phase.describe()
    kind = next((k for k, v in phase_functions.items() if type(phase) is v), type(phase).__name__)
    return {"type": kind, "mean_cosine": float(phase.mean_cosine)}


def phase_from_spec(spec) -> PhaseFunction:
    """Build a phase function from a schemas.medium phase spec (or its dict form)."""
    if isinstance(spec, dict):
        spec = TypeAdapter(PhaseSpec).validate_python(spec)
    kind = getattr(spec, "type", None)
    if kind not in phase_functions:
        raise ValueError(f"unknown phase function type {kind!r}; known: {sorted(phase_functions)}")
    return phase_functions[kind].from_spec(spec)
