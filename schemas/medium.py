"""Participating medium (smoke): coefficients, phase function, region (physics.md section 3)."""

from __future__ import annotations

import math
from collections import Counter
from typing import Annotated, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from .base import Point, SpecModel

#: Largest coefficient a medium may have [1/m] (optical depth 1e4 per metre: opaque).
MAX_COEFFICIENT = 1e4
#: Most cells a grid medium may have (two float64 arrays of this size are ~320 MB).
MAX_GRID_CELLS = 20_000_000
#: Most cells along one axis of a grid: a segment's traversal costs one array step per plane crossed.
MAX_GRID_CELLS_PER_AXIS = 1000

#: Koschmieder's relation: sigma_t = KOSCHMIEDER / visibility [1/m] (2 % contrast threshold).
KOSCHMIEDER = 3.912


class IsotropicPhaseSpec(SpecModel):
    """p = 1 / (4 pi)."""

    type: Literal["isotropic"] = "isotropic"


class HenyeyGreensteinPhaseSpec(SpecModel):
    """Henyey-Greenstein, mean cosine g in (-1, 1); g > 0 is forward scattering."""

    type: Literal["hg"] = "hg"
    g: float = Field(gt=-1.0, lt=1.0)


class SchlickPhaseSpec(SpecModel):
    """Schlick, p = (1 - k^2) / (4 pi (1 - k cos)^2); give `k` in (-1, 1) or `g` (mapped)."""

    type: Literal["schlick"] = "schlick"
    k: float | None = Field(None, gt=-1.0, lt=1.0)
    g: float | None = Field(None, gt=-1.0, lt=1.0)

    @model_validator(mode="after")
    def _one(self) -> "SchlickPhaseSpec":
        if (self.k is None) == (self.g is None):
            raise ValueError("give exactly one of `k` and `g`")
        return self


class RayleighPhaseSpec(SpecModel):
    """p = 3 (1 + cos^2) / (16 pi)."""

    type: Literal["rayleigh"] = "rayleigh"


class MixtureComponent(SpecModel):
    weight: float = Field(gt=0.0)
    phase: Annotated[
        IsotropicPhaseSpec | HenyeyGreensteinPhaseSpec | SchlickPhaseSpec | RayleighPhaseSpec,
        Field(discriminator="type"),
    ]


class MixturePhaseSpec(SpecModel):
    """Weighted mixture (report eq. 3.3), e.g. two-term HG; weights are normalised."""

    type: Literal["mixture"] = "mixture"
    components: list[MixtureComponent] = Field(min_length=1)


#: Most points a tabulated phase function may have.
MAX_PHASE_TABLE_POINTS = 100_000


def _first_bad(values, ok) -> int | None:
    return next((i for i, v in enumerate(values) if not ok(v)), None)


class TabulatedPhaseSpec(SpecModel):
    """A phase function from a table: `values` of p at the points of `cos_theta` or of `angle_deg`.

    Give `cos_theta` strictly increasing from exactly -1 to exactly 1, or `angle_deg` (the
    scattering angle theta) strictly increasing from exactly 0 to exactly 180. Between two
    points p is linear in cos(theta) (also with `angle_deg`). `values` >= 0 [1/sr] may carry
    any common factor, values up to the float max (about 1.8e308) included: the engine divides them
    by their integral 2 pi int p dcos(theta) (computed after scaling the largest value to [0.5, 1),
    so it does not overflow) and reports that normalisation (None when it exceeds the float max)
    and the mean cosine. Sampling inverts the CDF of this
    piecewise-linear function exactly.
    """

    type: Literal["tabulated"] = "tabulated"
    cos_theta: list[float] | None = Field(None, description="cos(theta), increasing from -1 to 1")
    angle_deg: list[float] | None = Field(None, description="scattering angle [deg], increasing from 0 to 180")
    values: list[float] = Field(
        min_length=2,
        max_length=MAX_PHASE_TABLE_POINTS,
        description="phase function at the points [1/sr, up to a common factor]",
    )

    @model_validator(mode="after")
    def _table(self) -> "TabulatedPhaseSpec":
        if (self.cos_theta is None) == (self.angle_deg is None):
            raise ValueError("give exactly one of `cos_theta` and `angle_deg`")
        grid: list[float]
        name, grid, ends = (
            ("cos_theta", self.cos_theta, (-1.0, 1.0))
            if self.cos_theta is not None
            else ("angle_deg", self.angle_deg or [], (0.0, 180.0))
        )
        if len(grid) != len(self.values):
            raise ValueError(
                f"`{name}` has {len(grid)} points but `values` has {len(self.values)}: give one value per point"
            )
        if grid[0] != ends[0] or grid[-1] != ends[1]:
            raise ValueError(
                f"`{name}` must run from exactly {ends[0]:g} to exactly {ends[1]:g}, got {grid[0]!r} .. {grid[-1]!r}"
            )
        bad = next((i for i in range(1, len(grid)) if not grid[i] > grid[i - 1]), None)
        if bad is not None:
            raise ValueError(
                f"`{name}` must be strictly increasing: entry {bad} ({grid[bad]!r}) does not exceed "
                f"entry {bad - 1} ({grid[bad - 1]!r})"
            )
        if self.angle_deg is not None:
            cos = [math.cos(math.radians(a)) for a in self.angle_deg[1:-1]]
            cos = [1.0] + cos + [-1.0]
            bad = next((i for i in range(1, len(cos)) if not cos[i] < cos[i - 1]), None)
            if bad is not None:
                raise ValueError(
                    f"`angle_deg` entries {bad - 1} and {bad} ({self.angle_deg[bad - 1]!r}, "
                    f"{self.angle_deg[bad]!r}) give the same cos(theta) in double precision"
                )
        bad = _first_bad(self.values, lambda v: v >= 0.0)
        if bad is not None:
            raise ValueError(f"`values` must be >= 0: entry {bad} is {self.values[bad]!r}")
        if not any(a > 0 or b > 0 for a, b in zip(self.values[:-1], self.values[1:])):
            raise ValueError("`values` are all zero: a phase function needs a positive integral")
        return self


class ComplexIndexSpec(SpecModel):
    """Complex refractive index m = real + i imag; imag >= 0 is absorption (e.g. soot 1.57 + 0.56 i)."""

    real: float = Field(gt=0.0, le=100.0)
    imag: float = Field(0.0, ge=0.0, le=100.0)


#: Largest Mie size parameter pi D n_medium / wavelength the size averaging may reach (its cost grows with it).
MAX_SIZE_PARAMETER = 500.0
#: Upper end of the size window the engine integrates over: D_g exp(2 ln^2 sigma_g + 5.7 ln sigma_g)
#: (the cross-section-weighted distribution, D^2 n(D), has a tail below 1e-8 beyond it).
SIZE_WINDOW_SIGMAS = 5.7


class ParticlesSpec(SpecModel):
    """Spherical particles with a log-normal number distribution of diameters, seen at one wavelength.

    dN/dlnD = N exp(-(ln D - ln D_g)^2 / (2 ln^2 sigma_g)) / (sqrt(2 pi) ln sigma_g), with D_g the
    geometric mean (count median) diameter and sigma_g >= 1 the geometric standard deviation
    (1: all particles of diameter D_g). The engine computes their Mie optics (engine/media/mie.py).
    """

    distribution: Literal["lognormal"] = "lognormal"
    geometric_mean_diameter: float = Field(gt=0.0, le=1e-3, description="count median diameter D_g [m]")
    geometric_std: float = Field(1.0, ge=1.0, le=4.0, description="geometric standard deviation sigma_g [-]")
    refractive_index: ComplexIndexSpec = Field(description="of the particle material, m = real + i imag")
    wavelength: float = Field(gt=1e-8, le=1e-3, description="vacuum wavelength [m]")
    medium_index: float = Field(1.0, ge=1.0, le=3.0, description="real refractive index of the surrounding gas")

    @model_validator(mode="after")
    def _size_parameter(self) -> "ParticlesSpec":
        s = math.log(self.geometric_std)
        d_max = self.geometric_mean_diameter * math.exp(2 * s * s + SIZE_WINDOW_SIGMAS * s)
        x = math.pi * d_max * self.medium_index / self.wavelength
        if x > MAX_SIZE_PARAMETER:
            raise ValueError(
                f"the size distribution reaches size parameter pi D n / wavelength = {x:.4g} (at D = "
                f"{d_max:.3g} m, where its cross-section-weighted tail ends), above the limit of "
                f"{MAX_SIZE_PARAMETER:g}: smaller particles, a narrower distribution or a longer "
                "wavelength"
            )
        return self


class MiePhaseSpec(SpecModel):
    """The Mie phase function of `particles`, averaged over their size distribution (a fine table)."""

    type: Literal["mie"] = "mie"
    particles: ParticlesSpec


PhaseSpec = Annotated[
    IsotropicPhaseSpec
    | HenyeyGreensteinPhaseSpec
    | SchlickPhaseSpec
    | RayleighPhaseSpec
    | MixturePhaseSpec
    | TabulatedPhaseSpec
    | MiePhaseSpec,
    Field(discriminator="type"),
]


class SceneRegionSpec(SpecModel):
    """The medium fills the whole scene."""

    type: Literal["scene"] = "scene"


class BoxRegionSpec(SpecModel):
    """The medium fills an axis-aligned box (e.g. a smoke layer under the ceiling)."""

    type: Literal["box"] = "box"
    min: Point
    max: Point

    @model_validator(mode="after")
    def _ordered(self) -> "BoxRegionSpec":
        if not all(b > a for a, b in zip(self.min, self.max)):
            raise ValueError("region `max` must exceed `min` on every axis")
        return self


class MeshRegionSpec(SpecModel):
    """The medium fills the inside of a closed triangle mesh (inline `vertices` [m], `faces`).

    Inside is where a ray from the point crosses the boundary an odd number of times
    (nested closed shells make hollows). The mesh must be closed: every edge (vertices
    identified by their coordinates) is shared by exactly two triangles. Winding order
    does not matter: the engine orients each shell itself.
    """

    type: Literal["mesh"] = "mesh"
    vertices: list[Point] = Field(min_length=4)
    faces: list[tuple[int, int, int]] = Field(min_length=4)

    @model_validator(mode="after")
    def _closed(self) -> "MeshRegionSpec":
        n = len(self.vertices)
        bad = [i for i, f in enumerate(self.faces) if min(f) < 0 or max(f) >= n]
        if bad:
            raise ValueError(f"faces {bad[:5]} index vertices outside 0..{n - 1}")
        key = [tuple(v) for v in self.vertices]  # identify duplicated vertices by position
        faces = [tuple(key[i] for i in f) for f in self.faces]
        bad = [i for i, f in enumerate(faces) if len(set(f)) < 3]
        if bad:
            raise ValueError(f"faces {bad[:5]} repeat a vertex (degenerate triangles)")
        edges = Counter(frozenset(e) for a, b, c in faces for e in ((a, b), (b, c), (c, a)))
        open_edges = [tuple(e) for e, k in edges.items() if k != 2]
        if open_edges:
            raise ValueError(
                f"the mesh region is not closed: {len(open_edges)} edges are not shared by exactly "
                f"two triangles, e.g. between {list(open_edges[0])}"
            )
        return self


RegionSpec = Annotated[SceneRegionSpec | BoxRegionSpec | MeshRegionSpec, Field(discriminator="type")]


class HomogeneousMediumSpec(SpecModel):
    """Homogeneous smoke: `sigma_a`, `sigma_s` [1/m], or `visibility_m` [m] with `albedo`.

    With visibility V, sigma_t = 3.912 / V (Koschmieder), sigma_s = albedo sigma_t.
    Emission is reserved (must be 0 for now).
    """

    type: Literal["homogeneous"] = "homogeneous"
    sigma_a: float | None = Field(None, ge=0.0, le=MAX_COEFFICIENT, description="absorption coefficient [1/m]")
    sigma_s: float | None = Field(None, ge=0.0, le=MAX_COEFFICIENT, description="scattering coefficient [1/m]")
    visibility_m: float | None = Field(None, gt=0.0, description="visibility [m]")
    albedo: float | None = Field(None, ge=0.0, le=1.0, description="sigma_s / sigma_t, with visibility_m")
    phase: PhaseSpec = Field(default_factory=IsotropicPhaseSpec)
    region: RegionSpec = Field(default_factory=SceneRegionSpec)
    emission: float = Field(0.0, ge=0.0, le=0.0, description="volume emission L_ve (reserved, 0)")

    @model_validator(mode="after")
    def _one_form(self) -> "HomogeneousMediumSpec":
        coeffs = self.sigma_a is not None or self.sigma_s is not None
        vis = self.visibility_m is not None or self.albedo is not None
        if coeffs == vis:
            raise ValueError("give either `sigma_a` and `sigma_s`, or `visibility_m` and `albedo`")
        if coeffs and (self.sigma_a is None or self.sigma_s is None):
            raise ValueError("give both `sigma_a` and `sigma_s` [1/m]")
        if vis and (self.visibility_m is None or self.albedo is None):
            raise ValueError("`visibility_m` needs `albedo` (sigma_s / sigma_t)")
        return self

    @property
    def sigma_t(self) -> float:
        """Extinction coefficient [1/m]."""
        if self.visibility_m is not None:
            return KOSCHMIEDER / self.visibility_m
        assert self.sigma_a is not None and self.sigma_s is not None  # the validator asks for one form
        return self.sigma_a + self.sigma_s

    @property
    def coefficients(self) -> tuple[float, float]:
        """(sigma_a, sigma_s) [1/m] from either input form."""
        if self.visibility_m is not None:
            assert self.albedo is not None  # the validator asks for it with visibility_m
            st = self.sigma_t
            return (1.0 - self.albedo) * st, self.albedo * st
        assert self.sigma_a is not None and self.sigma_s is not None
        return self.sigma_a, self.sigma_s


class GridMediumSpec(SpecModel):
    """Heterogeneous smoke: a 3-D grid of homogeneous cells filling the box `min`..`max` [m].

    `shape` = [nx, ny, nz] cells of equal size. `sigma_a`, `sigma_s` [1/m] are each one
    number (every cell) or a flat list of nx*ny*nz values in C order, x slowest, z fastest:
    cell (i, j, k) is entry (i * ny + j) * nz + k (numpy `reshape(nx, ny, nz)`).
    Outside the grid box there is no medium. One phase function for every cell.
    """

    type: Literal["grid"] = "grid"
    min: Point
    max: Point
    shape: tuple[int, int, int]
    sigma_a: float | list[float] = Field(description="absorption coefficient [1/m], one or nx*ny*nz values")
    sigma_s: float | list[float] = Field(description="scattering coefficient [1/m], one or nx*ny*nz values")
    phase: PhaseSpec = Field(default_factory=IsotropicPhaseSpec)
    emission: float = Field(0.0, ge=0.0, le=0.0, description="volume emission L_ve (reserved, 0)")

    @field_validator("shape")
    @classmethod
    def _shape(cls, v: tuple[int, int, int]) -> tuple[int, int, int]:
        if min(v) < 1:
            raise ValueError("every entry of `shape` must be >= 1")
        if math.prod(v) > MAX_GRID_CELLS:
            raise ValueError(f"{math.prod(v)} cells exceed the limit of {MAX_GRID_CELLS}")
        if max(v) > MAX_GRID_CELLS_PER_AXIS:
            raise ValueError(
                f"{max(v)} cells along one axis exceed the limit of {MAX_GRID_CELLS_PER_AXIS} "
                "(the exact traversal costs one step per cell plane a segment crosses)"
            )
        return v

    @field_validator("sigma_a", "sigma_s")
    @classmethod
    def _coefficients(cls, v: float | list[float], info: ValidationInfo) -> float | list[float]:
        values = [v] if isinstance(v, (int, float)) else v
        shape = info.data.get("shape")
        if not isinstance(v, (int, float)) and shape is not None and len(v) != math.prod(shape):
            raise ValueError(f"expected 1 or nx*ny*nz = {math.prod(shape)} values (C order, x slowest), got {len(v)}")
        bad = next((i for i, x in enumerate(values) if not (0.0 <= x <= MAX_COEFFICIENT)), None)
        if bad is not None:
            where = "" if isinstance(v, (int, float)) else f" at flat index {bad}"
            if shape is not None and where:
                where += f" (cell {bad // (shape[1] * shape[2])}, {bad // shape[2] % shape[1]}, {bad % shape[2]})"
            raise ValueError(f"value {values[bad]}{where} must be finite, >= 0 and <= {MAX_COEFFICIENT} [1/m]")
        return v

    @model_validator(mode="after")
    def _ordered(self) -> "GridMediumSpec":
        if not all(b > a for a, b in zip(self.min, self.max)):
            raise ValueError("grid `max` must exceed `min` on every axis")
        return self


class ParticleMediumSpec(SpecModel):
    """Homogeneous smoke given by its particles: concentration, size distribution, refractive index, wavelength.

    Give `mass_concentration` [kg/m^3] with `particle_density` [kg/m^3] (the material density,
    e.g. about 1800 for soot), or `number_concentration` [1/m^3]. The engine derives
    sigma_a, sigma_s [1/m] and a tabulated phase function by Mie theory averaged over the
    size distribution (engine/media/mie.py) and reports them with albedo, g and the Koschmieder
    visibility 3.912 / sigma_t.
    """

    type: Literal["particles"] = "particles"
    particles: ParticlesSpec
    mass_concentration: float | None = Field(None, ge=0.0, le=10.0, description="particle mass per volume [kg/m^3]")
    particle_density: float | None = Field(None, gt=0.0, le=30_000.0, description="material density [kg/m^3]")
    number_concentration: float | None = Field(None, ge=0.0, le=1e25, description="particles per volume [1/m^3]")
    region: RegionSpec = Field(default_factory=SceneRegionSpec)
    emission: float = Field(0.0, ge=0.0, le=0.0, description="volume emission L_ve (reserved, 0)")

    @model_validator(mode="after")
    def _one_concentration(self) -> "ParticleMediumSpec":
        if (self.mass_concentration is None) == (self.number_concentration is None):
            raise ValueError(
                "give exactly one of `mass_concentration` (with `particle_density`) and `number_concentration`"
            )
        if self.mass_concentration is not None and self.particle_density is None:
            raise ValueError("`mass_concentration` needs `particle_density` [kg/m^3] (soot: about 1800)")
        if self.number_concentration is not None and self.particle_density is not None:
            raise ValueError("`particle_density` is used only with `mass_concentration`")
        return self

    @property
    def phase(self) -> MiePhaseSpec:
        """The phase function the particles imply (Mie, size-averaged)."""
        return MiePhaseSpec(particles=self.particles)


MediumSpec = Annotated[HomogeneousMediumSpec | GridMediumSpec | ParticleMediumSpec, Field(discriminator="type")]
