"""Surface reflection models: Lambertian, modified Phong (diffuse + glossy lobe), perfect mirror.

One material is a mixture of three parts, with the reflectance split stated:
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

The three models, each behind one interface (evaluate, density, sample), are in lobes.py; `Materials`
mixes them per face. Arrays are (3, n) component rows (as in the kernel); `d_in` is the arriving ray
direction (pointing into the surface), `normals` face the arriving ray.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.sampling import cosine_about_soa
from owcsim.engine.surfaces.lobes import (
    Lambert,
    Mirror,
    Phong,
    SurfaceModel,
    _dot,
    lambert_brdf,
    lambert_pdf,
    mirror_direction,
    phong_brdf,
    phong_directions,
    phong_pdf,
    phong_weight,
)

__all__ = ["Materials", "MirrorPlane", "mirror_direction", "mirror_planes"]


@dataclass
class Materials(SurfaceModel):
    """Per-face (or per-vertex after `take`) material parameters, each (F,): the albedo-weighted mixture of the
    three models of lobes.py, Lambert(rho_d) + Phong(rho_s, exponent) + Mirror(rho_m) (`parts`)."""

    rho_d: np.ndarray  # diffuse reflectance
    rho_s: np.ndarray  # glossy (Phong) reflectance
    exponent: np.ndarray  # Phong exponent n >= 0
    rho_m: np.ndarray  # perfect-mirror reflectance

    @classmethod
    def lambertian(cls, rho) -> "Materials":
        rho = np.asarray(rho, float)
        z = np.zeros_like(rho)
        return cls(rho.copy(), z, z.copy(), z.copy())

    @property
    def total(self) -> np.ndarray:
        """rho = rho_d + rho_s + rho_m (the directional albedo's upper bound)."""
        return self.rho_d + self.rho_s + self.rho_m

    @property
    def is_lambertian(self) -> bool:
        return not (self.rho_s.any() or self.rho_m.any())

    @property
    def parts(self) -> tuple[Lambert, Phong, Mirror]:
        """The three models this material mixes, each with its own reflectance."""
        return Lambert(self.rho_d), Phong(self.rho_s, self.exponent), Mirror(self.rho_m)

    def take(self, idx) -> "Materials":
        return Materials(self.rho_d.take(idx), self.rho_s.take(idx), self.exponent.take(idx), self.rho_m.take(idx))

    # ------------------------------------------------------------------ evaluation
    def eval(self, d_in: np.ndarray, normals: np.ndarray, w_o: np.ndarray) -> np.ndarray:
        """Non-delta BRDF f(w_i = -d_in, w_o) [1/sr] (0 when w_o is below the surface).

        cos alpha = r . w_o = d_in . w_o + 2 cos th_i cos th_o (r = d_in - 2 (d_in . n) n), so the
        mirror direction itself is never formed.
        """
        cos_i = -_dot(d_in, normals)
        cos_o = _dot(w_o, normals)
        out = lambert_brdf(self.rho_d)
        if self.rho_s.any():  # rho_s = 0 rows add 0 (their lobe is finite)
            cos_a = _dot(d_in, w_o) + 2.0 * cos_i * cos_o
            out = out + phong_brdf(self.rho_s, self.exponent, cos_a, cos_i, cos_o)
        return np.where((cos_o > 0) & (cos_i > 0), out, 0.0)

    def pdf(self, d_in: np.ndarray, normals: np.ndarray, w_o: np.ndarray) -> np.ndarray:
        """Solid-angle density of `sample`'s non-delta directions (without the mirror's point mass)."""
        rho = self.total
        safe = np.where(rho > 0, rho, 1.0)
        cos_o = _dot(w_o, normals)
        p = lambert_pdf(self.rho_d / safe, cos_o)
        cos_a = _dot(d_in, w_o) - 2.0 * _dot(d_in, normals) * cos_o
        p = p + phong_pdf(self.rho_s / safe, self.exponent, cos_a)
        return np.where(rho > 0, p, 0.0)

    # ------------------------------------------------------------------ sampling
    def sample(self, d_in: np.ndarray, normals: np.ndarray, u1: np.ndarray, u2: np.ndarray):
        """(w_o (3, n), weight factor (n,)): lobe chosen by albedo, lobe sampled exactly.

        The weight factor is f cos th_o / (p_lobe pdf_lobe) for the chosen lobe's f:
        rho for the diffuse and mirror lobes, rho cos th_o / max(cos th_i, cos th_o) for
        the glossy lobe (0 below the surface); always <= rho. The cosine sampler runs on every
        vertex (cheaper than gathering the diffuse ones and scattering back); the glossy and
        mirror vertices then overwrite their directions.
        """
        rho = self.total
        safe = np.where(rho > 0, rho, 1.0)
        p_d = self.rho_d / safe
        u1 = np.asarray(u1, float)
        diffuse = u1 < p_d  # (so p_d > 0 there)
        w_o = cosine_about_soa(normals, u1 / np.where(diffuse, p_d, 1.0), u2)  # every vertex; glossy and mirror
        # ones are replaced below
        weight = rho.copy()
        if diffuse.all():  # every vertex diffuse (a Lambertian scene)
            return w_o, weight
        p_s = self.rho_s / safe
        glossy = ~diffuse & (u1 < p_d + p_s)
        idx = np.flatnonzero(glossy)
        if len(idx):
            v = np.clip((u1.take(idx) - p_d.take(idx)) / p_s.take(idx), 0.0, 1.0)
            n_i, d_i = normals.take(idx, axis=1), d_in.take(idx, axis=1)
            w = phong_directions(d_i, n_i, self.exponent.take(idx), v, u2.take(idx))
            for k in range(3):
                w_o[k].put(idx, w[k])
            weight.put(idx, phong_weight(rho.take(idx), d_i, n_i, w))
        idx = np.flatnonzero(~diffuse & ~glossy)
        if len(idx):
            r = mirror_direction(d_in.take(idx, axis=1), normals.take(idx, axis=1))
            for k in range(3):
                w_o[k].put(idx, r[k])
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
