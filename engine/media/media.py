"""Homogeneous media (physics.md section 3): constant coefficients in a region, and the `homogeneous` kind's builder.

`HomogeneousMedium` implements the `Medium` interface (medium.py) for the whole scene, a box
or a closed mesh; `homogeneous_from_spec` builds the `homogeneous` kind from its document, particle
smoke is a homogeneous medium with its Mie coefficients (particles.py). registry.py's
`medium_from_spec` builds any medium kind from its document (grid media: grid.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from owcsim.engine.core.arrays import BoolArray, FloatArray, IntArray
from owcsim.engine.media.medium import Medium
from owcsim.engine.media.regions import BoxRegion, MeshRegion, WholeRegion, as_rows
from owcsim.schemas.medium import (
    BoxRegionSpec,
    HomogeneousMediumSpec,
    IsotropicPhaseSpec,
    MeshRegionSpec,
    ParticleMediumSpec,
    PhaseSpec,
    SceneRegionSpec,
)

__all__ = ["HomogeneousMedium", "Medium", "homogeneous_from_spec", "homogeneous_medium", "region_from_spec"]


def _count(rays: list[IntArray]) -> int:
    """Number of distinct segments in a list of index arrays."""
    if len(rays) <= 1:
        return len(rays[0]) if rays else 0
    return len(np.unique(np.concatenate(rays)))


@dataclass
class HomogeneousMedium(Medium):
    """Constant `sigma_a`, `sigma_s` [1/m] inside a region: the whole scene, a box lo..hi, or a closed mesh.

    `box` is the box region (lo, hi) or None; a closed-mesh region is `region` (a
    `MeshRegion`), and then `box` is None. `bounds` is None only for the whole scene.
    """

    sigma_a: float
    sigma_s: float
    box: tuple[FloatArray, FloatArray] | None = None
    #: number of segments that crossed the region in the kernel-facing methods (see the module docstring)
    evaluations: int = 0
    region: MeshRegion | None = None
    phase_spec: PhaseSpec = field(default_factory=IsotropicPhaseSpec)

    def __post_init__(self):
        if self.box is not None and self.region is not None:
            raise ValueError("give a box or a mesh region, not both")
        self._region: BoxRegion | MeshRegion | WholeRegion
        if self.box is not None:
            self.box = (np.asarray(self.box[0], np.float64), np.asarray(self.box[1], np.float64))
            self._region = BoxRegion(*self.box)
        else:
            self._region = self.region if self.region is not None else WholeRegion()
        self.bounds = self._region.bounds

    @property
    def sigma_t(self) -> float:
        return self.sigma_a + self.sigma_s

    @property
    def sigma_t_max(self) -> float:
        return self.sigma_t

    @property
    def sigma_t_min(self) -> float:
        return self.sigma_t

    @property
    def albedo(self) -> float:
        """sigma_s / sigma_t [-], 0 for an empty medium."""
        return self.sigma_s / self.sigma_t if self.sigma_t > 0 else 0.0

    @property
    def scatters(self) -> bool:
        return self.sigma_s > 0

    @property
    def max_albedo(self) -> float:
        return self.albedo

    def length_inside(self, origins: ArrayLike, directions: ArrayLike, lengths: ArrayLike) -> FloatArray:
        """Length [m] of each segment inside the region (not counted in `evaluations`)."""
        o, d, L = self._inputs(origins, directions, lengths)
        if isinstance(self._region, WholeRegion):
            return L
        out = np.zeros(len(L))
        for ray, a, b in self._region.intervals(o, d, L):
            out[ray] += b - a
        return out

    def _optical_depth(self, o: FloatArray, d: FloatArray, L: FloatArray) -> tuple[FloatArray, int]:
        if isinstance(self._region, WholeRegion):  # (sigma_t = 0 with an infinite L: 0, not NaN)
            return (self.sigma_t * L if self.sigma_t > 0 else np.zeros(len(L))), len(L)
        tau = np.zeros(len(L))
        crossed = []
        for ray, a, b in self._region.intervals(o, d, L):
            tau[ray] += self.sigma_t * (b - a)
            crossed.append(ray)
        return tau, _count(crossed)

    def _regular(
        self, o: FloatArray, d: FloatArray, L: FloatArray, need: FloatArray
    ) -> tuple[FloatArray, BoolArray, int]:
        """Exact inversion interval by interval: the collision is where the accumulated depth reaches `need`."""
        if self.sigma_t == 0.0:
            return L.copy(), np.zeros(len(L), bool), 0
        if isinstance(self._region, WholeRegion):  # one interval [0, L] per segment: no index arrays
            scattered = self.sigma_t * L > need  # (need >= 0: segments of length 0 never scatter)
            return np.where(scattered, need / self.sigma_t, L), scattered, int(np.count_nonzero(L > 0))
        t, scattered, acc = L.copy(), np.zeros(len(L), bool), np.zeros(len(L))
        crossed = []
        for ray, a, b in self._region.intervals(o, d, L):
            dtau = self.sigma_t * (b - a)
            rem = need[ray] - acc[ray]
            hit = ~scattered[ray] & (dtau > rem)  # dtau > rem >= 0 implies sigma_t > 0: no division by zero
            r = ray[hit]
            t[r] = a[hit] + rem[hit] / self.sigma_t
            scattered[r] = True
            acc[ray] += dtau
            crossed.append(ray)
        return t, scattered, _count(crossed)

    @property
    def uniform_coefficients(self) -> tuple[float, float] | None:
        return (self.sigma_t, self.sigma_s) if isinstance(self._region, WholeRegion) else None

    def albedo_at(self, points: ArrayLike) -> FloatArray:
        if isinstance(self._region, WholeRegion):  # the same everywhere
            return np.full(len(as_rows(points)), self.albedo)
        return super().albedo_at(points)

    def _coefficients_at(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        if isinstance(self._region, WholeRegion):
            return np.full(len(p), self.sigma_t), np.full(len(p), self.sigma_s)
        inside = self._region.contains(p)
        return np.where(inside, self.sigma_t, 0.0), np.where(inside, self.sigma_s, 0.0)


def homogeneous_medium(
    sigma_a: float, sigma_s: float, spec: HomogeneousMediumSpec | ParticleMediumSpec
) -> HomogeneousMedium | None:
    """The homogeneous medium of `sigma_a`, `sigma_s` [1/m] in the region and with the phase of `spec`; None when
    sigma_t = 0 (nothing to attenuate)."""
    if sigma_a + sigma_s == 0.0:
        return None
    box, region = region_from_spec(spec.region)
    return HomogeneousMedium(sigma_a, sigma_s, box, region=region, phase_spec=spec.phase)


def homogeneous_from_spec(spec: HomogeneousMediumSpec) -> HomogeneousMedium | None:
    """The `homogeneous` kind (registry.py): constant coefficients from the document."""
    sigma_a, sigma_s = spec.coefficients
    return homogeneous_medium(sigma_a, sigma_s, spec)


def region_from_spec(
    region: SceneRegionSpec | BoxRegionSpec | MeshRegionSpec,
) -> tuple[tuple[FloatArray, FloatArray] | None, MeshRegion | None]:
    """(box (lo, hi) [m] or None, closed-mesh region or None) of a homogeneous medium's region document."""
    box = mesh = None
    if region.type == "box":
        box = (np.asarray(region.min, float), np.asarray(region.max, float))
    elif region.type == "mesh":
        mesh = MeshRegion(region.vertices, region.faces, label="medium.region")
    return box, mesh
