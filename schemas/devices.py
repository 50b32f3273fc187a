"""Transmitters and receivers (physics.md section 2)."""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import BeforeValidator, ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

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


class PlaneArea(SpecModel):
    """An area of a grid's plane, in plane coordinates (a, b) [m]: a = offset along `u`, b = along `v`, from
    the grid's `origin`. Either a rectangle (`min`, `max`) or a `polygon` (at least 3 vertices, in order).
    Closed: a point on the edge (within 1e-9 m) is inside."""

    min: tuple[float, float] | None = Field(None, description="rectangle corner (a, b) [m] with the smaller offsets")
    max: tuple[float, float] | None = Field(None, description="rectangle corner (a, b) [m] with the larger offsets")
    polygon: list[tuple[float, float]] | None = Field(
        None, min_length=3, max_length=1000, description="vertices (a, b) [m] of a simple polygon, in order"
    )

    @model_validator(mode="after")
    def _one_shape(self) -> "PlaneArea":
        rect = self.min is not None or self.max is not None
        if rect == (self.polygon is not None):
            raise ValueError("give a rectangle (`min` and `max`) or a `polygon`, not both or neither")
        if rect:
            if self.min is None or self.max is None:
                raise ValueError("a rectangle needs both `min` and `max` (plane coordinates [m])")
            if not all(a < b for a, b in zip(self.min, self.max)):
                raise ValueError(f"rectangle `max` {self.max} must exceed `min` {self.min} along both axes")
        return self

    def vertices(self) -> list[tuple[float, float]]:
        """The outline, in order (a rectangle's 4 corners)."""
        if self.polygon is not None:
            return list(self.polygon)
        assert self.min is not None and self.max is not None
        (a0, b0), (a1, b1) = self.min, self.max
        return [(a0, b0), (a1, b0), (a1, b1), (a0, b1)]


def _spacing(x: Any) -> Any:
    """One step or two [m], each a finite positive number (one located message, not one per union member)."""
    items = list(x) if isinstance(x, (list, tuple)) else [x]
    if len(items) != 2 and isinstance(x, (list, tuple)):
        raise PydanticCustomError("spacing", "give one step or two, [s_u, s_v] [m]")
    for c in items:
        if isinstance(c, bool) or not isinstance(c, (int, float)):
            raise PydanticCustomError("float_type", "Input should be a valid number")
        if not math.isfinite(c):
            raise PydanticCustomError("finite_number", "Input should be a finite number")
        if c <= 0:
            raise PydanticCustomError("greater_than", "Input should be greater than 0")
    return tuple(float(c) for c in items) if isinstance(x, (list, tuple)) else float(x)


#: A grid step [m], or one per axis [s_u, s_v].
Spacing = Annotated[float | tuple[float, float], BeforeValidator(_spacing)]

#: Most receivers one grid may hold.
MAX_GRID_RECEIVERS = 100_000


class ReceiverGridSpec(SpecModel):
    """Receivers on a rectangle of any plane: point (i, j) at `origin` + i s_u `u` + j s_v `v`.

    `u` and `v` are orthogonal directions spanning the plane (normalised when built), `size` the extent
    along each [m]. The steps (s_u, s_v) [m] come from exactly one of `spacing` (one step, or [s_u, s_v]:
    points at 0, s, 2 s, ... up to and including `size`, within 1e-9) and `shape` ([n_u, n_v] points
    spread over `size`, both ends included: s = size / (n - 1)). `normal` defaults to the plane's normal
    u x v, turned to face up (z >= 0) unless the plane is vertical; a normal in the plane is an error.
    `exclude` and `include` mask points (reported as masked, not simulated). Every receiver shares the
    receiver fields. Ids are `{id_prefix}[i,j]`.
    """

    # `shape` in the document is the field `counts` here: `shape` is always the grid's (n_u, n_v), also when
    # `spacing` gives it
    model_config = ConfigDict(serialize_by_alias=True)

    id_prefix: str = "grid"
    origin: Point
    u: Direction = (1.0, 0.0, 0.0)
    v: Direction = (0.0, 1.0, 0.0)
    size: tuple[float, float] = Field(description="extent along u and v [m]")
    spacing: Spacing | None = Field(
        None, description="step between neighbouring points [m]: one for both axes, or [s_u, s_v]"
    )
    counts: tuple[int, int] | None = Field(
        None,
        validation_alias="shape",
        serialization_alias="shape",
        description="[n_u, n_v] points along u and v, spread over `size` with both ends included",
    )
    exclude: list[PlaneArea] = Field(
        default_factory=list, description="areas of the plane whose points are masked (plane coordinates [m])"
    )
    include: list[PlaneArea] = Field(
        default_factory=list,
        description="when given, only points inside one of these areas are simulated (plane coordinates [m])",
    )
    normal: Direction | None = Field(
        None, description="receiver normal (default: u x v, facing up unless the plane is vertical)"
    )
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
        u, v = _unit(self.u), _unit(self.v)
        if abs(sum(a * b for a, b in zip(u, v))) > 1e-6:
            raise ValueError("grid directions `u` and `v` must be orthogonal")
        if any(not math.isfinite(s) or s < 0 for s in self.size):
            raise ValueError("grid size must be two non-negative lengths [m]")
        if (self.spacing is None) == (self.counts is None):
            raise ValueError("give the grid's `spacing` (one step or [s_u, s_v], in m) or its `shape` [n_u, n_v]")
        if self.counts is not None:
            for n, s, ax in zip(self.counts, self.size, "uv"):
                if n < 1:
                    raise ValueError(f"grid shape must be at least 1 point along {ax}, got {n}")
                if n == 1 and s > 0:
                    raise ValueError(f"one point along {ax} spans no extent: give size 0 along {ax}, or 2+ points")
                if n > 1 and s == 0:
                    raise ValueError(f"{n} points along {ax} need a positive size along {ax} [m]")
            if self.counts[0] * self.counts[1] > MAX_GRID_RECEIVERS:
                raise ValueError(f"grid has {self.counts[0] * self.counts[1]} receivers, more than the 100000 allowed")
        else:
            steps = self.steps
            if any(not s > 0 for s in steps):
                raise ValueError("grid spacing must be positive [m]")
            counts = [s / d for s, d in zip(self.size, steps)]
            if any(not math.isfinite(x) or x > 1e6 for x in counts) or (counts[0] + 1) * (counts[1] + 1) > 200_000:
                raise ValueError(
                    f"a spacing of {self.spacing} m over {self.size} m gives more than the 100000 receivers allowed"
                )
            if self.count > MAX_GRID_RECEIVERS:
                raise ValueError(f"grid has {self.count} receivers, more than the 100000 allowed")
        plane = _cross(u, v)
        if self.normal is None:  # the frozen model's field set once, here: readers always find a direction
            object.__setattr__(self, "normal", _default_normal(plane))
        else:
            given = _unit(self.normal)
            if abs(sum(a * b for a, b in zip(given, plane))) < 1e-6:
                raise ValueError(
                    f"grid normal {self.normal} lies in the grid's plane (spanned by u and v): the receivers would "
                    "see the plane edge-on; give a normal out of the plane, or leave it out for u x v"
                )
        return self

    @property
    def receiver_normal(self) -> tuple[float, float, float]:
        """The receivers' normal, as given or by default (see the class docstring); not normalised."""
        assert self.normal is not None  # filled by the validator
        return self.normal

    @property
    def steps(self) -> tuple[float, float]:
        """(s_u, s_v): the step between neighbouring points along u and v [m] (0 along an axis of one point)."""
        if self.counts is not None:
            return tuple(s / (n - 1) if n > 1 else 0.0 for s, n in zip(self.size, self.counts))  # type: ignore[return-value]
        assert self.spacing is not None  # the validator asks for one form
        if isinstance(self.spacing, tuple):
            return self.spacing
        return (self.spacing, self.spacing)

    @property
    def shape(self) -> tuple[int, int]:
        """(n_u, n_v): points along u and v (the document's `shape`, or what `spacing` gives)."""
        if self.counts is not None:
            return self.counts
        return tuple(int(math.floor(s / d + 1e-9)) + 1 for s, d in zip(self.size, self.steps))  # type: ignore[return-value]

    @property
    def count(self) -> int:
        nu, nv = self.shape
        return nu * nv

    def ids(self) -> list[str]:
        """`{id_prefix}[i,j]` of every point, row-major."""
        nu, nv = self.shape
        return [f"{self.id_prefix}[{i},{j}]" for i in range(nu) for j in range(nv)]

    def offsets(self, i: int, j: int) -> tuple[float, float]:
        """Plane coordinates (a, b) [m] of point (i, j): i s_u, j s_v."""
        su, sv = self.steps
        return (i * su, j * sv)

    def point(self, i: int, j: int) -> ReceiverSpec:
        """The receiver at grid index (i, j) (u and v normalised here: the document keeps them as given)."""
        u, v = _unit(self.u), _unit(self.v)
        su, sv = self.steps
        if su == sv:  # one step: the formula of the square grid (the same bits as before rectangular grids)
            p = tuple(o + su * (i * a + j * b) for o, a, b in zip(self.origin, u, v))
        else:
            p = tuple(o + i * su * a + j * sv * b for o, a, b in zip(self.origin, u, v))
        return ReceiverSpec(
            id=f"{self.id_prefix}[{i},{j}]",
            position=p,
            normal=self.receiver_normal,
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


def _cross(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _default_normal(plane: tuple[float, float, float]) -> tuple[float, float, float]:
    """The plane's unit normal u x v, turned to face up (z > 0) unless the plane is vertical; exactly +z for a
    horizontal plane (the default of grids before tilted planes: the same bits)."""
    if abs(plane[0]) < 1e-12 and abs(plane[1]) < 1e-12:
        return (0.0, 0.0, 1.0)
    n = _unit(plane)
    return tuple(-c for c in n) if n[2] < -1e-12 else n  # type: ignore[return-value]
