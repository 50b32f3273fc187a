"""The surface reflection models, each behind one interface (`SurfaceModel`; `Lobe` for the mixable ones).

- `Lambert(rho)`: f = rho / pi; cosine-weighted sampling, density cos th_o / pi, weight rho.
- `Phong(rho, n)`: f = rho (n + 1) / (2 pi) cos^n(alpha) / max(cos th_i, cos th_o) (cos alpha > 0, alpha the
  angle of w_o to the mirror direction); sampling cos^n(alpha) about the mirror direction (exact inversion),
  density (n + 1) / (2 pi) cos^n(alpha), weight rho cos th_o / max(cos th_i, cos th_o) <= rho.
- `Mirror(rho)`: a delta lobe: f and the density of non-delta directions are 0; sampling returns the mirror
  direction with weight rho (point devices are reached through mirror images, bsdf.MirrorPlane).

A surface's material mixes the registered models (registry.py `SURFACE_MODELS`; bsdf.Materials, the kernel's
model: one lobe chosen by albedo per vertex); the formulas and references are in bsdf.py's docstring. A `Lobe`
gives the mixture its unmasked BRDF term `brdf(pair)` and its weighted density `density(share, pair)` on the
vertex pairs `Pair` (the cosines computed once for every model). Arrays are (3, n) component rows;
`d_in` is the arriving direction (into the surface), `normals` face the arriving ray, `w_o` leaves it.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import ClassVar, Protocol, Self

import numpy as np

from owcsim.engine.core.arrays import BoolArray, FloatArray, IntArray
from owcsim.engine.core.sampling import cosine_about_soa

__all__ = ["Lambert", "Lobe", "Mirror", "Pair", "Phong", "SurfaceModel", "mirror_direction"]


class SurfaceModel(Protocol):
    """A reflection model on a batch of n vertices (one interface for every kind of surface)."""

    def eval(self, d_in: FloatArray, normals: FloatArray, w_o: FloatArray) -> FloatArray:
        """Evaluate: the non-delta BRDF f(w_i = -d_in, w_o) [1/sr] (n,), 0 when w_o or w_i is below."""
        ...

    def pdf(self, d_in: FloatArray, normals: FloatArray, w_o: FloatArray) -> FloatArray:
        """Density: the solid-angle pdf [1/sr] (n,) of `sample`'s non-delta directions."""
        ...

    def sample(
        self, d_in: FloatArray, normals: FloatArray, u1: FloatArray, u2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Sample: (w_o (3, n), weight f cos th_o / pdf (n,)) from uniforms u1, u2 (n,)."""
        ...


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def mirror_direction(d_in: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """r = d_in - 2 (d_in . n) n: the specular reflection of the arriving direction, (3, n)."""
    return d_in - 2.0 * _dot(d_in, normals) * normals


# --- the models' formulas (shared with the mixture, bsdf.Materials) ---------------------------------------------------
def lambert_brdf(rho: np.ndarray) -> np.ndarray:
    """rho / pi [1/sr]."""
    return rho * (1.0 / np.pi)


def lambert_pdf(weight: np.ndarray, cos_o: np.ndarray) -> np.ndarray:
    """`weight` times the cosine density max(cos th_o, 0) / pi [1/sr]."""
    return weight * np.maximum(cos_o, 0.0) / np.pi


def phong_brdf(rho: np.ndarray, n: np.ndarray, cos_a: np.ndarray, cos_i: np.ndarray, cos_o: np.ndarray) -> np.ndarray:
    """rho (n + 1) / (2 pi) cos^n(alpha) / max(cos th_i, cos th_o) [1/sr] (0 where cos alpha <= 0)."""
    return rho * _phong_lobe(n, cos_a) / np.maximum(np.maximum(cos_i, cos_o), 1e-300)


def phong_pdf(weight: np.ndarray, n: np.ndarray, cos_a: np.ndarray) -> np.ndarray:
    """`weight` times the lobe density (n + 1) / (2 pi) cos^n(alpha) [1/sr]."""
    return weight * _phong_lobe(n, cos_a)


def phong_directions(d_in: np.ndarray, normals: np.ndarray, n: np.ndarray, u1: np.ndarray, u2: np.ndarray):
    """Directions (3, m) drawn from cos^n(alpha) about the mirror direction of `d_in`."""
    return _lobe_about_soa(mirror_direction(d_in, normals), n, u1, u2)


def phong_weight(rho: np.ndarray, d_in: np.ndarray, normals: np.ndarray, w_o: np.ndarray) -> np.ndarray:
    """The sampled glossy direction's weight rho cos th_o / max(cos th_i, cos th_o) (0 below the surface)."""
    cos_o = _dot(w_o, normals)
    cos_i = -_dot(d_in, normals)
    return np.where(cos_o > 0, rho * cos_o / np.maximum(np.maximum(cos_i, cos_o), 1e-300), 0.0)


def _lobe_about_soa(axis: np.ndarray, n: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Directions (3, m) with pdf (n+1)/(2 pi) cos^n(angle to `axis` (3, m)), exact inversion.

    cos t = u1^(1/(n+1)), sin^2 t = -expm1(2 log(u1)/(n+1)), phi = 2 pi u2 (as
    sampling.sample_generalized_lambertian), in the frame of Duff et al. 2017 about the
    axis, on component arrays; the azimuth's cosine and sine in float32 (as
    sampling.cosine_about_soa: ~1e-7 rad, below Embree's float32 precision).
    """
    with np.errstate(divide="ignore"):
        e = np.log(u1) / (n + 1.0)
    cos_t = np.exp(e)
    sin_t = np.sqrt(np.maximum(0.0, -np.expm1(2.0 * e)))
    phi = (2.0 * np.pi * u2).astype(np.float32)
    a_c, a_s = sin_t * np.cos(phi), sin_t * np.sin(phi)
    x, y, z = axis
    sgn = np.copysign(1.0, z)
    a = -1.0 / (sgn + z)
    b = x * y * a
    out = np.empty_like(axis)
    out[0] = a_c * (1.0 + sgn * x * x * a) + a_s * b + cos_t * x
    out[1] = a_c * (sgn * b) + a_s * (sgn + y * y * a) + cos_t * y
    out[2] = a_c * (-sgn * x) + a_s * (-y) + cos_t * z
    return out


def _phong_lobe(n: np.ndarray, cos_a: np.ndarray) -> np.ndarray:
    """(n + 1) / (2 pi) cos^n(alpha) for cos alpha > 0, else 0 (normalised over the sphere of w_o)."""
    safe = np.where(cos_a > 0, cos_a, 1.0)
    return np.where(cos_a > 0, (n + 1.0) / (2 * np.pi) * np.exp(n * np.log(safe)), 0.0)


# --- the models -------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Pair:
    """A batch of vertex pairs (incoming, outgoing): `d_in` (3, n) arriving (into the surface), `normals` (3, n)
    facing the arriving ray, `w_o` (3, n) leaving; cos th_i = -d_in . n and cos th_o = w_o . n, computed once."""

    d_in: FloatArray
    normals: FloatArray
    w_o: FloatArray
    cos_i: FloatArray
    cos_o: FloatArray

    @classmethod
    def of(cls, d_in: FloatArray, normals: FloatArray, w_o: FloatArray) -> Pair:
        return cls(d_in, normals, w_o, -_dot(d_in, normals), _dot(w_o, normals))

    @property
    def above(self) -> BoolArray:
        """Both directions above the surface (cos th_i > 0 and cos th_o > 0)."""
        return (self.cos_o > 0) & (self.cos_i > 0)


@dataclass(frozen=True)
class Lobe(SurfaceModel):
    """A reflection model a material mixes (registry.py): its weight `rho` (n,) [-] per vertex, then its own
    per-vertex parameters (the dataclass fields after `rho`, read from the surface spec's fields `parameters`).

    A subclass gives `brdf` and `density` (or sets `delta`: a point mass, no non-delta BRDF nor density) and
    `sample`; `eval`, `pdf`, `take` and `with_rho` follow.
    """

    rho: FloatArray
    #: a delta lobe (perfect mirror): f and the density of non-delta directions are 0, the mixture skips it
    delta: ClassVar[bool] = False
    #: the surface spec's fields holding the per-vertex parameters, in the order of the fields after `rho`
    parameters: ClassVar[tuple[str, ...]] = ()

    def brdf(self, pair: Pair) -> FloatArray:
        """The BRDF term f(w_i, w_o) [1/sr] (n,) of weight `rho`, before the mixture's below-surface mask."""
        raise NotImplementedError(f"{type(self).__name__} is a delta lobe")

    def density(self, share: FloatArray, pair: Pair) -> FloatArray:
        """`share` (n,) times the solid-angle pdf [1/sr] of `sample`'s directions."""
        raise NotImplementedError(f"{type(self).__name__} is a delta lobe")

    def eval(self, d_in: FloatArray, normals: FloatArray, w_o: FloatArray) -> FloatArray:
        if self.delta:
            return np.zeros(len(self.rho))
        pair = Pair.of(d_in, normals, w_o)
        return np.where(pair.above, self.brdf(pair), 0.0)

    def pdf(self, d_in: FloatArray, normals: FloatArray, w_o: FloatArray) -> FloatArray:
        if self.delta:
            return np.zeros(len(self.rho))
        return self.density(np.ones(len(self.rho)), Pair.of(d_in, normals, w_o))

    def take(self, idx: IntArray) -> Self:
        """The lobe on the vertices `idx` (every per-vertex field taken)."""
        return type(self)(*(np.take(getattr(self, f.name), idx) for f in fields(self)))

    def at(self, idx: IntArray, rho: FloatArray) -> Self:
        """The lobe on the vertices `idx` with weight `rho` (len(idx),): its parameters taken, `rho` given."""
        return type(self)(rho, *(np.take(getattr(self, f.name), idx) for f in fields(self)[1:]))

    def with_rho(self, rho: FloatArray) -> Self:
        """The same lobe with weight `rho` (the mixture samples a chosen lobe with the material's total rho)."""
        return replace(self, rho=rho)


@dataclass(frozen=True)
class Lambert(Lobe):
    """Ideal diffuse reflection of reflectance `rho` (n,)."""

    def brdf(self, pair: Pair) -> FloatArray:
        return lambert_brdf(self.rho)

    def density(self, share: FloatArray, pair: Pair) -> FloatArray:
        return lambert_pdf(share, pair.cos_o)

    def sample(
        self, d_in: FloatArray, normals: FloatArray, u1: FloatArray, u2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        return cosine_about_soa(normals, u1, u2), self.rho.copy()


@dataclass(frozen=True)
class Phong(Lobe):
    """The reciprocal modified-Phong glossy lobe of reflectance `rho` (n,) and exponent `n` (n,) >= 0."""

    n: FloatArray
    parameters: ClassVar[tuple[str, ...]] = ("exponent",)

    def brdf(self, pair: Pair) -> FloatArray:
        """cos alpha = r . w_o = d_in . w_o + 2 cos th_i cos th_o (the mirror direction r is never formed)."""
        cos_a = _dot(pair.d_in, pair.w_o) + 2.0 * pair.cos_i * pair.cos_o
        return phong_brdf(self.rho, self.n, cos_a, pair.cos_i, pair.cos_o)

    def density(self, share: FloatArray, pair: Pair) -> FloatArray:
        cos_a = _dot(pair.d_in, pair.w_o) - 2.0 * _dot(pair.d_in, pair.normals) * pair.cos_o
        return phong_pdf(share, self.n, cos_a)

    def sample(
        self, d_in: FloatArray, normals: FloatArray, u1: FloatArray, u2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        w_o = phong_directions(d_in, normals, self.n, u1, u2)
        return w_o, phong_weight(self.rho, d_in, normals, w_o)


@dataclass(frozen=True)
class Mirror(Lobe):
    """Perfect specular reflection of reflectance `rho` (n,): a delta lobe."""

    delta: ClassVar[bool] = True

    def sample(
        self, d_in: FloatArray, normals: FloatArray, u1: FloatArray, u2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        return mirror_direction(d_in, normals), self.rho.copy()
