"""What a lighting designer asks of a scene and reads in its result (docs/lighting.md).

- `LightingSpec` (the scene's `lighting`): EN 12464-1 task areas on receiver grids and the width of their
  immediate surround, and whether to map the cylindrical illuminance.
- `LightingResultPublic` (the result's `lighting`): the luminous flux each transmitter lights with and where
  it comes from, and per task area (or per whole grid) the average and minimum illuminance and the
  uniformity U0 = E_min / E_avg with their standard errors.
"""

from __future__ import annotations

from collections import Counter
from enum import StrEnum

from pydantic import BaseModel, ConfigDict, Field, model_validator

from .base import Point, SpecModel

#: EN 12464-1:2021 sec. 4.3.2: the immediate surround is a band of at least 0.5 m around the task area [m].
SURROUND_WIDTH = 0.5


class TaskAreaSpec(SpecModel):
    """A task area on one receiver grid: the grid's points inside the box `min`..`max` (room coordinates [m]).

    For a horizontal grid at z = 0.85 m a desk is e.g. min = (1.0, 1.5, 0.85), max = (2.6, 2.3, 0.85): the box
    may be flat along the grid's normal (points within 1e-6 m of it count).
    """

    name: str = Field(min_length=1, max_length=200, description="the task area's name")
    grid: str = Field(description="`id_prefix` of the receiver grid it lies on")
    min: Point = Field(description="lowest corner of the area's box in room coordinates [m]")
    max: Point = Field(description="highest corner of the area's box in room coordinates [m]")

    @model_validator(mode="after")
    def _ordered(self) -> TaskAreaSpec:
        if any(a > b for a, b in zip(self.min, self.max)):
            raise ValueError(f"task area {self.name!r}: `min` {self.min} must not exceed `max` {self.max} on any axis")
        return self


class LightingSpec(SpecModel):
    """EN 12464-1 figures asked of the result: per task area (or per grid without one) E_avg, E_min and U0, for
    the area, its immediate surround and its background; optionally the cylindrical illuminance on every map."""

    task_areas: list[TaskAreaSpec] = Field(
        default_factory=list,
        description="task areas on receiver grids; without any, the figures are given over each whole grid",
    )
    surround_width: float = Field(
        SURROUND_WIDTH,
        ge=0.0,
        le=10.0,
        description="width of the immediate surround band around each task area [m] (EN 12464-1: at least 0.5 m; "
        "0: no surround)",
    )
    background_width: float = Field(
        0.0,
        ge=0.0,
        le=100.0,
        description="width of the background band beyond the immediate surround [m] (EN 12464-1: at least 3 m, "
        "within the room; 0: none)",
    )
    cylindrical: bool = Field(
        False,
        description="add `cylindrical_illuminance_direct_lx` [lx] to links, channels and maps: the mean vertical "
        "illuminance over all azimuths at each point, direct light only",
    )

    @model_validator(mode="after")
    def _unique(self) -> LightingSpec:
        dup = sorted(n for n, c in Counter(a.name for a in self.task_areas).items() if c > 1)
        if dup:
            raise ValueError(f"task_areas: duplicate names {dup}")
        return self


def check_lighting(lighting: LightingSpec | None, grid_ids: list[str]) -> None:
    """ValueError when a task area names a grid the scene does not have."""
    if lighting is None:
        return
    for k, area in enumerate(lighting.task_areas):
        if area.grid not in grid_ids:
            raise ValueError(
                f"lighting.task_areas[{k}] ({area.name}): no receiver grid with id_prefix {area.grid!r}; "
                f"the grids are {grid_ids}"
            )


class FluxSource(StrEnum):
    """Where a transmitter's luminous flux comes from, in the order of precedence."""

    LUMINOUS_OUTPUT = "luminous_output"  # given in the document (flux, or centre intensity x the pattern)
    PHOTOMETRY = "photometry"  # the integral of the photometric file's candela
    SPECTRUM = "spectrum"  # P_t x 683 lm/W x the spectrum's V(lambda)-weighted fraction


class PublicModel(BaseModel):
    model_config = ConfigDict(extra="ignore")


class TransmitterFluxPublic(PublicModel):
    """The luminous flux a transmitter lights with, and every value the scene gives for it."""

    transmitter: str = Field(description="transmitter id")
    luminous_flux_lm: float | None = Field(description="the flux every illuminance uses [lm]; null: gives no light")
    luminous_flux_source: FluxSource | None = Field(
        description="where it comes from (precedence: luminous_output, photometry, spectrum)"
    )
    candidates_lm: dict[FluxSource, float] = Field(
        default_factory=dict, description="every flux the scene gives for it, by source [lm]"
    )


class AreaFiguresPublic(PublicModel):
    """Illuminance figures over a set of grid points (null when it holds no simulated point)."""

    points: list[tuple[int, int]] = Field(description="the grid indices (i, j) of the points used")
    illuminance_avg_lx: float | None = Field(description="E_avg: mean total illuminance of the points [lx]")
    illuminance_avg_lx_stderr: float | None = Field(description="standard error of E_avg [lx]")
    illuminance_min_lx: float | None = Field(description="E_min: the smallest total illuminance [lx]")
    illuminance_min_lx_stderr: float | None = Field(description="standard error of E_min [lx]")
    uniformity_u0: float | None = Field(description="U0 = E_min / E_avg [-]")
    uniformity_u0_stderr: float | None = Field(description="standard error of U0 [-]")


class TaskAreaPublic(PublicModel):
    """EN 12464-1 figures of one task area (or of a whole grid) for one channel."""

    name: str = Field(description="the task area's name (the grid's id_prefix when no task area was given)")
    grid: str = Field(description="the grid's id_prefix")
    channel: str = Field(
        description="transmitter group name, or transmitter id when the scene has no group; `all luminaires` "
        "for the light of every transmitter together (scenes with several channels)"
    )
    task: AreaFiguresPublic = Field(description="the points of the task area")
    surround: AreaFiguresPublic | None = Field(
        None, description="the points of the immediate surround band (null without task area or with width 0)"
    )
    background: AreaFiguresPublic | None = Field(
        None, description="the points of the background band beyond the surround (null without background_width)"
    )


class LightingResultPublic(PublicModel):
    """The result's lighting section (docs/lighting.md)."""

    transmitters: list[TransmitterFluxPublic] = Field(default_factory=list)
    areas: list[TaskAreaPublic] = Field(default_factory=list)
    errors: str = Field(
        "",
        description="how the standard errors of the area figures are computed",
    )
