"""Participating medium (smoke): coefficients, phase function, region (physics.md section 3)."""
from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from .base import Point, SpecModel

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
    phase: Annotated[Union[IsotropicPhaseSpec, HenyeyGreensteinPhaseSpec, SchlickPhaseSpec,
                           RayleighPhaseSpec], Field(discriminator="type")]


class MixturePhaseSpec(SpecModel):
    """Weighted mixture (report eq. 3.3), e.g. two-term HG; weights are normalised."""

    type: Literal["mixture"] = "mixture"
    components: list[MixtureComponent] = Field(min_length=1)


PhaseSpec = Annotated[
    Union[IsotropicPhaseSpec, HenyeyGreensteinPhaseSpec, SchlickPhaseSpec, RayleighPhaseSpec,
          MixturePhaseSpec],
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


RegionSpec = Annotated[Union[SceneRegionSpec, BoxRegionSpec], Field(discriminator="type")]


class HomogeneousMediumSpec(SpecModel):
    """Homogeneous smoke: `sigma_a`, `sigma_s` [1/m], or `visibility_m` [m] with `albedo`.

    With visibility V, sigma_t = 3.912 / V (Koschmieder), sigma_s = albedo sigma_t.
    Emission is reserved (must be 0 for now).
    """

    type: Literal["homogeneous"] = "homogeneous"
    sigma_a: float | None = Field(None, ge=0.0, le=1e4, description="absorption coefficient [1/m]")
    sigma_s: float | None = Field(None, ge=0.0, le=1e4, description="scattering coefficient [1/m]")
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
        return self.sigma_a + self.sigma_s

    @property
    def coefficients(self) -> tuple[float, float]:
        """(sigma_a, sigma_s) [1/m] from either input form."""
        if self.visibility_m is not None:
            st = self.sigma_t
            return (1.0 - self.albedo) * st, self.albedo * st
        return self.sigma_a, self.sigma_s


MediumSpec = Annotated[Union[HomogeneousMediumSpec], Field(discriminator="type")]
