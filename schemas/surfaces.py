"""Surface materials beyond Lambertian: modified Phong (diffuse + glossy lobe) and mirror.

Wherever a surface takes a `reflectance` (room faces, furniture, meshes and their groups)
it takes either a number, the Lambertian reflectance rho (BRDF rho/pi, the default), or
one of these materials. Each states its split of the total reflectance rho:

- `lambertian`: rho_d = rho.
- `phong`: diffuse rho_d = r_d rho plus a glossy lobe rho_s = (1 - r_d) rho of exponent n
  about the mirror direction (Lomba, Valadas & Duarte 1998; Lee, Park & Barry 2011),
  made reciprocal and energy-conserving (see engine/surfaces/bsdf.py). n = 0 is a broad lobe,
  n of a few hundred a polished floor; as n grows the lobe tends to a mirror.
- `mirror`: diffuse rho_d = r_d rho plus a perfect mirror rho_m = (1 - r_d) rho
  (glass, metal, whiteboards). Mirror faces must be planar groups (room faces, box faces,
  flat mesh parts): point devices are reached through their mirror images.
- `spectral`: Lambertian with a reflectance per wavelength band (schemas/spectra.py); the scene
  must define its bands (`spectral`).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, Discriminator, Field, Tag, WrapValidator

from .base import SpecModel
from .spectra import SpectralSurfaceSpec

Rho = Annotated[float, Field(ge=0.0, le=1.0, description="total reflectance rho, in [0, 1]")]
DiffuseFraction = Annotated[float, Field(ge=0.0, le=1.0, description="diffuse fraction r_d: rho_d = r_d rho")]


class LambertianSurfaceSpec(SpecModel):
    """Lambertian reflector: BRDF rho / pi (the same as giving the number rho)."""

    type: Literal["lambertian"] = "lambertian"
    reflectance: Rho


class PhongSurfaceSpec(SpecModel):
    """Diffuse part r_d rho plus a Phong lobe (1 - r_d) rho of exponent n about the mirror direction.

    `reflectance` rho = rho_d + rho_s weighs the two parts of the BRDF (engine/surfaces/bsdf.py); it is not the
    albedo: the glossy lobe reflects less than rho_s (its part below the surface is lost), e.g. at normal
    incidence the albedo is rho_d + rho_s (n + 1) / (n + 2) (docs/luminaires-surfaces.md).
    """

    type: Literal["phong"] = "phong"
    reflectance: float = Field(
        ge=0.0,
        le=1.0,
        description="rho = rho_d + rho_s, the weights of the diffuse part and the glossy lobe, in [0, 1]; not the "
        "albedo (at normal incidence rho_d + rho_s (n + 1) / (n + 2))",
    )
    diffuse_fraction: DiffuseFraction
    exponent: float = Field(ge=0.0, le=1e5, description="Phong exponent n of the glossy lobe")


class MirrorSurfaceSpec(SpecModel):
    """Diffuse part r_d rho plus a perfect (specular) mirror (1 - r_d) rho."""

    type: Literal["mirror"] = "mirror"
    reflectance: Rho
    diffuse_fraction: DiffuseFraction = 0.0


SurfaceSpec = Annotated[LambertianSurfaceSpec | PhongSurfaceSpec | MirrorSurfaceSpec, Field(discriminator="type")]

_SURFACE_HELP = (
    "a reflectance is a number in [0, 1] or a material with `type` lambertian, phong or mirror (or "
    "spectral, with the scene's bands)"
)


def _surface_kind(value) -> str | None:
    if isinstance(value, dict):
        return value.get("type")
    if isinstance(value, BaseModel):
        return getattr(value, "type", None)
    return "number"


def _number_first(value, handler):
    """Numbers are checked here, so that a wrong one is reported at the field itself."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) and not 0.0 <= value <= 1.0:
        raise ValueError(f"a Lambertian reflectance must lie in [0, 1], found {value:g}")
    return handler(value)


#: A Lambertian reflectance (a number) or a material: what a surface's `reflectance` takes.
Surface = Annotated[
    Annotated[Rho, Tag("number")]
    | Annotated[LambertianSurfaceSpec, Tag("lambertian")]
    | Annotated[PhongSurfaceSpec, Tag("phong")]
    | Annotated[MirrorSurfaceSpec, Tag("mirror")]
    | Annotated[SpectralSurfaceSpec, Tag("spectral")],
    Discriminator(_surface_kind, custom_error_type="invalid_surface", custom_error_message=_SURFACE_HELP),
    WrapValidator(_number_first),
]
