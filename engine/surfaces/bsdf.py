"""Materials: the per-face mixture of the registered surface models (Lambert, Phong, mirror); mirror planes.

With the built-in models, one material is a mixture of three parts, with the reflectance split stated:
    rho = rho_d + rho_s + rho_m <= 1
(rho_d diffuse, rho_s glossy Phong lobe of exponent n, rho_m perfect mirror). The BRDF is

    f(w_i, w_o) = rho_d / pi
                + rho_s (n + 1) / (2 pi) cos^n(alpha) / max(cos th_i, cos th_o)   (cos alpha > 0)
                + rho_m delta(w_o - r(w_i)) / cos th_o,

alpha the angle between w_o and the mirror direction r(w_i) = 2 (w_i.n) n - w_i, th_i and
th_o the angles of w_i (toward where the light came from) and w_o to the normal n.

The glossy term is the Phong reflection model of optical wireless channel modelling
(Lomba, Valadas & Duarte 1998, IEE Proc. Optoelectron. 145(3); Lee, Park & Barry 2011,
IEEE Commun. Lett. 15(2)), there written as a reflected radiant intensity
    rho [r_d cos(th_o) / pi + (1 - r_d) (n + 1) / (2 pi) cos^n(alpha)]
per incident watt, i.e. a BRDF with 1 / cos th_o in the lobe; here rho_d = r_d rho and
rho_s = (1 - r_d) rho. We replace cos th_o by max(cos th_i, cos th_o) (the two agree on the
mirror direction, and differ less as n grows) so that the BRDF is reciprocal
(f(w_i, w_o) = f(w_o, w_i): cos alpha is symmetric in the pair) and, with the lobe
normalised as a radiant intensity, every sampled weight is bounded by rho (energy is
never created): sampling w_o from (n + 1) / (2 pi) cos^n(alpha) about r gives the weight
rho_s cos th_o / max(cos th_i, cos th_o) <= rho_s, and 0 below the surface.

Sampling: a lobe is chosen with probability rho_part / rho (its albedo), from the same
uniform u1 remapped to [0, 1) for the lobe (so two uniforms per bounce, as for a
Lambertian surface, and a Lambertian material consumes them exactly as before); the
diffuse lobe is cosine sampled, the glossy lobe is cos^n(alpha) about r (exact
inversion), the mirror is r. The path weight is multiplied by rho times the lobe's
weight ratio (1 for the diffuse and mirror lobes, cos th_o / max(cos th_i, cos th_o) for
the glossy one): the one-sample lobe-selection estimator, unbiased because f is the sum
of the lobes (Pharr, Jakob & Humphreys, PBRT 4th ed. sec. 2.4.3).
Next-event estimation evaluates the non-delta part of f for the pair (incoming, toward
the target); the mirror part reaches point devices only through mirror images.

The models, each behind one interface (evaluate, density, sample), are in lobes.py and registered by their wire
`type` in registry.py (`SURFACE_MODELS`: lambertian, phong, mirror); `Materials` mixes the registered models per
face in registry order (sums of their terms; lobe chosen by cumulative albedo shares). Arrays are (3, n) component
rows (as in the kernel); `d_in` is the arriving ray direction (pointing into the surface), `normals` face the
arriving ray.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.surfaces.lobes import Lobe, Pair, Phong, SurfaceModel, _dot, mirror_direction
from owcsim.engine.surfaces.registry import DIFFUSE, SURFACE_MODELS

__all__ = ["Materials", "MirrorPlane", "mirror_direction", "mirror_planes"]


def _weights(surface: Any) -> dict[str, float]:
    """The weights [-] of the models one surface mixes: a number rho is Lambertian; a spec of `type` t is its
    diffuse part r_d rho plus the lobe t of weight rho - r_d rho (a `lambertian` spec: rho, diffuse)."""
    if isinstance(surface, (int, float)):
        return {DIFFUSE: float(surface)}
    if surface.type not in SURFACE_MODELS:
        raise TypeError(f"no surface model {surface.type!r} (engine/surfaces/registry.py: {', '.join(SURFACE_MODELS)})")
    rho = surface.reflectance
    if surface.type == DIFFUSE:
        return {DIFFUSE: rho}
    rd = surface.diffuse_fraction * rho
    return {DIFFUSE: rd, surface.type: rho - rd}


@dataclass
class Materials(SurfaceModel):
    """Per-face (or per-vertex after `take`) materials: one lobe of each registered model (`kinds`, the surface
    types of registry.SURFACE_MODELS, in its order), each holding its weight per face (0 where a face does not use
    it); the mixture's BRDF is the sum of theirs, e.g. Lambert(rho_d) + Phong(rho_s, exponent) + Mirror(rho_m)."""

    lobes: tuple[Lobe, ...]
    kinds: tuple[str, ...]

    @classmethod
    def mix(cls, **given: Lobe | ArrayLike) -> Materials:
        """The registered models with the `given` lobes by surface type (an array: the weight of a model without
        parameters); every other model has weight 0 (and parameters 0), e.g. `mix(lambertian=rho_d,
        phong=Phong(rho_s, n))`."""
        unknown = set(given) - set(SURFACE_MODELS)
        if unknown:
            raise KeyError(f"no surface model {sorted(unknown)} (registered: {', '.join(SURFACE_MODELS)})")
        lobes = {k: v if isinstance(v, Lobe) else SURFACE_MODELS[k](np.asarray(v, float)) for k, v in given.items()}
        count = len(next(iter(lobes.values())).rho)
        zero = np.zeros(count)
        for kind, model in SURFACE_MODELS.items():
            if kind not in lobes:
                lobes[kind] = model(zero.copy(), *(zero.copy() for _ in model.parameters))
        return cls(tuple(lobes[k] for k in SURFACE_MODELS), tuple(SURFACE_MODELS))

    @classmethod
    def lambertian(cls, rho: ArrayLike) -> Materials:
        return cls.mix(**{DIFFUSE: np.asarray(rho, float).copy()})

    @classmethod
    def of_surfaces(cls, surfaces: Sequence[Any]) -> Materials:
        """The materials of per-face surfaces: numbers (Lambertian rho) or surface specs (schemas/surfaces.py)."""
        count = len(surfaces)
        weights = {kind: np.zeros(count) for kind in SURFACE_MODELS}
        params = {kind: np.zeros((len(m.parameters), count)) for kind, m in SURFACE_MODELS.items()}
        for face, surface in enumerate(surfaces):
            for kind, w in _weights(surface).items():
                weights[kind][face] = w
            if not isinstance(surface, (int, float)):
                for j, name in enumerate(SURFACE_MODELS[surface.type].parameters):
                    params[surface.type][j, face] = getattr(surface, name)
        return cls.mix(**{k: m(weights[k], *params[k]) for k, m in SURFACE_MODELS.items()})

    def lobe(self, kind: str) -> Lobe:
        """The lobe of the model registered as surface type `kind`."""
        return self.lobes[self.kinds.index(kind)]

    def weight_of(self, kind: str) -> FloatArray:
        """The weight [-] per face of the model `kind` (e.g. "mirror": rho_m, for mirror planes and images)."""
        return self.lobe(kind).rho

    @property
    def rho_d(self) -> FloatArray:
        """Diffuse reflectance [-] (the `lambertian` model's weight)."""
        return self.weight_of(DIFFUSE)

    @property
    def rho_s(self) -> FloatArray:
        """Glossy (Phong) reflectance [-]."""
        return self.weight_of("phong")

    @property
    def exponent(self) -> FloatArray:
        """Phong exponent n >= 0 [-]."""
        phong = self.lobe("phong")
        assert isinstance(phong, Phong)
        return phong.n

    @property
    def rho_m(self) -> FloatArray:
        """Perfect-mirror reflectance [-]."""
        return self.weight_of("mirror")

    @property
    def total(self) -> FloatArray:
        """rho = the sum of the lobes' weights, in registry order (rho_d + rho_s + rho_m): the albedo's bound."""
        out = self.lobes[0].rho
        for lobe in self.lobes[1:]:
            out = out + lobe.rho
        return out

    @property
    def is_lambertian(self) -> bool:
        """No weight on any model but the diffuse one."""
        return not any(lobe.rho.any() for lobe in self.lobes[1:])

    def take(self, idx: IntArray) -> Materials:
        return Materials(tuple(lobe.take(idx) for lobe in self.lobes), self.kinds)

    def _terms(self) -> list[Lobe]:
        """The non-delta lobes after the first with some weight (a lobe of weight 0 everywhere adds 0)."""
        return [lobe for lobe in self.lobes[1:] if not lobe.delta and lobe.rho.any()]

    # ------------------------------------------------------------------ evaluation
    def eval(self, d_in: FloatArray, normals: FloatArray, w_o: FloatArray) -> FloatArray:
        """Non-delta BRDF f(w_i = -d_in, w_o) [1/sr]: the lobes' terms summed in registry order (0 when w_o or w_i
        is below the surface)."""
        pair = Pair.of(d_in, normals, w_o)
        out = self.lobes[0].brdf(pair)
        for lobe in self._terms():
            out = out + lobe.brdf(pair)
        return np.where(pair.above, out, 0.0)

    def pdf(self, d_in: FloatArray, normals: FloatArray, w_o: FloatArray) -> FloatArray:
        """Solid-angle density [1/sr] of `sample`'s non-delta directions: sum of (rho_k / rho) pdf_k (no point
        masses)."""
        rho = self.total
        safe = np.where(rho > 0, rho, 1.0)
        pair = Pair.of(d_in, normals, w_o)
        first = self.lobes[0]
        p = first.density(first.rho / safe, pair)
        for lobe in self._terms():
            p = p + lobe.density(lobe.rho / safe, pair)
        return np.where(rho > 0, p, 0.0)

    # ------------------------------------------------------------------ sampling
    def sample(
        self, d_in: FloatArray, normals: FloatArray, u1: FloatArray, u2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """(w_o (3, n), weight factor (n,)): lobe k chosen with probability rho_k / rho, then sampled exactly.

        Lobe k takes the vertices with c_(k-1) <= u1 < c_k, c_k = p_1 + ... + p_k (the last lobe the rest), and u1
        remapped to (u1 - c_(k-1)) / p_k. The weight factor is the chosen lobe's sampled weight for the total rho
        (f cos th_o / (p_k pdf_k)): rho for the diffuse and mirror lobes, rho cos th_o / max(cos th_i, cos th_o)
        for the glossy one; always <= rho. The first (diffuse) lobe samples every vertex (cheaper than gathering
        the diffuse ones and scattering back); the others then overwrite their vertices.
        """
        rho = self.total
        safe = np.where(rho > 0, rho, 1.0)
        first, rest = self.lobes[0], self.lobes[1:]
        below = first.rho / safe  # c_1
        u1 = np.asarray(u1, float)
        taken = u1 < below  # (so p_1 > 0 there)
        w_o, weight = first.with_rho(rho).sample(d_in, normals, u1 / np.where(taken, below, 1.0), u2)
        if taken.all():  # every vertex diffuse (a Lambertian scene)
            return w_o, weight
        for k, lobe in enumerate(rest):
            last = k == len(rest) - 1
            if last:  # the rest: u1 >= c_(K-1) (and the vertices of rho = 0, weight 0)
                idx = np.flatnonzero(~taken)
            elif lobe.rho.any():
                share = lobe.rho / safe
                chosen = ~taken & (u1 < below + share)
                idx = np.flatnonzero(chosen)
            else:  # weight 0 everywhere: no vertex has c_(k-1) <= u1 < c_(k-1) + 0
                continue
            if len(idx):
                p_k = lobe.rho.take(idx) / safe.take(idx)
                v = np.clip((u1.take(idx) - below.take(idx)) / np.where(p_k > 0, p_k, 1.0), 0.0, 1.0)
                part = lobe.at(idx, rho.take(idx))
                w, wt = part.sample(d_in.take(idx, axis=1), normals.take(idx, axis=1), v, u2.take(idx))
                for c in range(3):
                    w_o[c].put(idx, w[c])
                weight.put(idx, wt)
            if not last:
                taken, below = taken | chosen, below + share
        return w_o, weight


@dataclass
class MirrorPlane:
    """A plane holding faces with a perfect-mirror part: unit `normal`, a `point` on it, its `faces` (F,) mask."""

    normal: np.ndarray
    point: np.ndarray
    faces: np.ndarray

    def reflect_points(self, p: np.ndarray) -> np.ndarray:
        """Mirror images of points (3, n): p - 2 ((p - p0) . n) n."""
        dist = _dot(p - self.point[:, None], self.normal[:, None])
        return p - 2.0 * dist * self.normal[:, None]

    def reflect_vectors(self, v: np.ndarray) -> np.ndarray:
        """Mirror images of vectors (3, n): v - 2 (v . n) n."""
        return v - 2.0 * _dot(v, self.normal[:, None]) * self.normal[:, None]


def mirror_planes(vertices: np.ndarray, faces: np.ndarray, rho_m: np.ndarray, tol: float) -> list[MirrorPlane]:
    """Group the faces with rho_m > 0 by their plane (normals equal up to sign, offsets within `tol` [m])."""
    idx = np.flatnonzero(rho_m > 0)
    planes: list[MirrorPlane] = []
    if len(idx) == 0:
        return planes
    tri = vertices[faces[idx]]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    for f, n, p in zip(idx, nrm, tri[:, 0]):
        for plane in planes:
            if abs(abs(n @ plane.normal) - 1.0) < 1e-9 and abs((p - plane.point) @ plane.normal) < tol:
                plane.faces[f] = True
                break
        else:
            mask = np.zeros(len(faces), bool)
            mask[f] = True
            planes.append(MirrorPlane(n.copy(), p.copy(), mask))
    return planes
