"""Transmitters and receivers (physics.md section 2)."""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import Field, model_validator

from .base import Direction, Point, SpecModel
from .link_budget import LuminousOutputSpec
from .orientation import OrientationSpec
from .photometry import PhotometrySpec
from .spectra import Curve

Fov = Annotated[
    float,
    Field(
        ge=1e-6,
        le=90.0,
        description=(
            "field of view, half-angle [deg], in (0, 90] (at least 1e-6 deg: below it a concentrator's gain overflows; "
            "under 2 deg the result warns: radians meant?)"
        ),
    ),
]


class TransmitterSpec(SpecModel):
    """Point emitter, generalized Lambertian of order m: R(phi) = (m+1)/(2 pi) cos^m(phi).

    Give exactly one of `lambertian_order` (m >= 0) and `half_power_semi_angle_deg`
    (then m = -ln 2 / ln cos(Phi_half)), or instead of both a `photometry` file
    (a luminaire's tabulated intensity, aimed along `normal`; see PhotometrySpec).
    """

    id: str | None = None
    position: Point
    normal: Direction
    power: float = Field(1.0, gt=0.0, description="optical power P_t [W]")
    lambertian_order: float | None = Field(None, ge=0.0, le=1e4, description="Lambertian order m")
    half_power_semi_angle_deg: float | None = Field(
        None, gt=0.0, lt=90.0, description="Phi_1/2 [deg] (under 2 deg the result warns: radians meant?)"
    )
    luminous_output: LuminousOutputSpec | None = Field(
        None,
        description="luminous flux [lm] or centre luminous intensity [cd] of the source: gives the "
        "illuminance on the receivers (the optical power stays `power`); a `photometry` file's own candela "
        "give it without this field, and this field, when given, wins",
    )
    photometry: PhotometrySpec | None = Field(None, description="tabulated emission from an IES / EULUMDAT file")
    spectrum: Curve | None = Field(
        None,
        description="relative spectral power distribution over the scene's bands "
        "(a spectral curve, any scale; default flat); `power` is the total",
    )

    @model_validator(mode="after")
    def _one_pattern(self) -> "TransmitterSpec":
        if self.photometry is not None:
            if self.lambertian_order is not None or self.half_power_semi_angle_deg is not None:
                raise ValueError(
                    "give `photometry` or a Lambertian pattern (`lambertian_order` / "
                    "`half_power_semi_angle_deg`), not both"
                )
            return self
        if (self.lambertian_order is None) == (self.half_power_semi_angle_deg is None):
            raise ValueError("give exactly one of `lambertian_order` and `half_power_semi_angle_deg`")
        if self.half_power_semi_angle_deg is not None:
            log_cos = math.log(math.cos(math.radians(self.half_power_semi_angle_deg)))
            if log_cos == 0.0 or -math.log(2.0) / log_cos > 1e4:
                raise ValueError(
                    f"half_power_semi_angle_deg = {self.half_power_semi_angle_deg:g} means a Lambertian "
                    "order above 10000: give at least 0.68 deg"
                )
        return self

    @property
    def m(self) -> float:
        """Lambertian order, from either input form (0 for a photometric file: unused)."""
        if self.photometry is not None:
            return 0.0
        if self.lambertian_order is not None:
            return self.lambertian_order
        assert self.half_power_semi_angle_deg is not None  # the validator asks for one form
        return -math.log(2.0) / math.log(math.cos(math.radians(self.half_power_semi_angle_deg)))


class ReceiverSpec(SpecModel):
    """Photodiode: area A [m^2], FOV half-angle, optional filter gain and concentrator.

    Collects A cos(psi) T_s g(psi) for psi <= FOV, with g = n_c^2 / sin^2(FOV) when
    `concentrator_index` n_c is given (ideal non-imaging concentrator), else 1.
    Treated as a point for visibility and distance (valid while sqrt(A) << distances).
    """

    id: str | None = None
    position: Point
    normal: Direction
    area: float = Field(gt=0.0, le=1.0, description="detector area A [m^2]")
    fov_deg: Fov = 90.0
    filter_gain: float = Field(1.0, gt=0.0, le=1.0, description="optical filter gain T_s")
    concentrator_index: float | None = Field(None, ge=1.0, le=4.0, description="concentrator refractive index n_c")
    responsivity: Curve | None = Field(
        None,
        description="photodiode responsivity per band [A/W] (a spectral curve): "
        "gives the electrical gain of spectral scenes",
    )
    filter_transmission: Curve | None = Field(
        None,
        description="optical filter transmission per band, in [0, 1] "
        "(a spectral curve; applies to the electrical gain)",
    )
    orientation: OrientationSpec | None = Field(
        None, description="random orientation of a handheld device: statistics over tilted copies (docs/orientation.md)"
    )


def _unit(d: tuple[float, float, float]) -> tuple[float, float, float]:
    """d / |d| (a Direction is validated non-zero and finite, not normalised)."""
    norm = math.sqrt(sum(c * c for c in d))
    return tuple(c / norm for c in d)  # type: ignore[return-value]


class ReceiverGridSpec(SpecModel):
    """Receivers on a rectangle: `origin` + i * spacing * `u` + j * spacing * `v`.

    `u` and `v` are unit directions spanning the plane (orthogonal), `size` the extent
    along each [m]; points at 0, spacing, ... up to and including `size` (within 1e-9).
    Every receiver shares `normal`, `area`, `fov_deg`, filter and concentrator.
    Ids are `{id_prefix}[i,j]`.
    """

    id_prefix: str = "grid"
    origin: Point
    u: Direction = (1.0, 0.0, 0.0)
    v: Direction = (0.0, 1.0, 0.0)
    size: tuple[float, float] = Field(description="extent along u and v [m]")
    spacing: float = Field(gt=0.0, description="grid step [m]")
    normal: Direction = (0.0, 0.0, 1.0)
    area: float = Field(gt=0.0, le=1.0)
    fov_deg: Fov = 90.0
    filter_gain: float = Field(1.0, gt=0.0, le=1.0)
    concentrator_index: float | None = Field(None, ge=1.0, le=4.0)
    responsivity: Curve | None = Field(None, description="photodiode responsivity per band [A/W] (spectral scenes)")
    filter_transmission: Curve | None = Field(None, description="optical filter transmission per band (spectral)")
    orientation: OrientationSpec | None = Field(
        None, description="random orientation of a handheld device at every point (docs/orientation.md)"
    )

    @model_validator(mode="after")
    def _sane(self) -> "ReceiverGridSpec":
        if abs(sum(a * b for a, b in zip(_unit(self.u), _unit(self.v)))) > 1e-6:
            raise ValueError("grid directions `u` and `v` must be orthogonal")
        if any(not math.isfinite(s) or s < 0 for s in self.size):
            raise ValueError("grid size must be two non-negative lengths [m]")
        steps = [s / self.spacing for s in self.size]
        if any(not math.isfinite(x) or x > 1e6 for x in steps) or (steps[0] + 1) * (steps[1] + 1) > 200_000:
            raise ValueError(
                f"a spacing of {self.spacing:g} m over {self.size} m gives more than the 100000 receivers allowed"
            )
        if self.count > 100_000:
            raise ValueError(f"grid has {self.count} receivers, more than the 100000 allowed")
        return self

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(int(math.floor(s / self.spacing + 1e-9)) + 1 for s in self.size)  # type: ignore[return-value]

    @property
    def count(self) -> int:
        nu, nv = self.shape
        return nu * nv

    def ids(self) -> list[str]:
        """`{id_prefix}[i,j]` of every point, row-major."""
        nu, nv = self.shape
        return [f"{self.id_prefix}[{i},{j}]" for i in range(nu) for j in range(nv)]

    def point(self, i: int, j: int) -> ReceiverSpec:
        """The receiver at grid index (i, j) (u and v normalised here: the document keeps them as given)."""
        u, v = _unit(self.u), _unit(self.v)
        p = tuple(o + self.spacing * (i * a + j * b) for o, a, b in zip(self.origin, u, v))
        return ReceiverSpec(
            id=f"{self.id_prefix}[{i},{j}]",
            position=p,
            normal=self.normal,
            area=self.area,
            fov_deg=self.fov_deg,
            filter_gain=self.filter_gain,
            concentrator_index=self.concentrator_index,
            responsivity=self.responsivity,
            filter_transmission=self.filter_transmission,
        )

    def expand(self) -> list[ReceiverSpec]:
        """The grid as individual receivers, row-major in (i along u, j along v)."""
        nu, nv = self.shape
        return [self.point(i, j) for i in range(nu) for j in range(nv)]
