"""Time-varying smoke: where a sequence of grid media (frames on one grid, with times) comes from (issue 26).

`FramesSpec` is the union of the sources; each builds an `engine.media.frames.MediumFrames`
(engine/media/frame_sources.py). Today: frames given inline. FDS output (fdsreader) and plain
netCDF / xarray files with dims (time, z, y, x) are the other kinds.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from .base import Point, SpecModel
from .medium import MAX_COEFFICIENT, MAX_GRID_CELLS, IsotropicPhaseSpec, PhaseSpec

#: Most frames a timeline may have.
MAX_FRAMES = 1000


class InlineFramesSpec(SpecModel):
    """Frames given in the document: `times` [s] and per frame `sigma_a`, `sigma_s` [1/m] on one grid.

    The grid is `min`..`max` [m] cut into `shape` = [nx, ny, nz] cells; each frame's coefficients are one
    number (every cell) or nx*ny*nz values in C order, x slowest, z fastest (as the `grid` medium).
    """

    type: Literal["inline"] = "inline"
    times: list[float] = Field(min_length=1, max_length=MAX_FRAMES, description="frame times [s], increasing")
    min: Point
    max: Point
    shape: tuple[int, int, int]
    sigma_a: list[float | list[float]] = Field(description="per frame: absorption [1/m], one or nx*ny*nz values")
    sigma_s: list[float | list[float]] = Field(description="per frame: scattering [1/m], one or nx*ny*nz values")
    phase: PhaseSpec = Field(default_factory=IsotropicPhaseSpec)

    @model_validator(mode="after")
    def _consistent(self) -> "InlineFramesSpec":
        n = math.prod(self.shape)
        if min(self.shape) < 1 or n > MAX_GRID_CELLS:
            raise ValueError(f"`shape` must have entries >= 1 and at most {MAX_GRID_CELLS} cells")
        if any(b <= a for a, b in zip(self.times, self.times[1:])):
            raise ValueError("`times` must be strictly increasing [s]")
        if not all(b > a for a, b in zip(self.min, self.max)):
            raise ValueError("`max` must exceed `min` on every axis")
        for name in ("sigma_a", "sigma_s"):
            frames = getattr(self, name)
            if len(frames) != len(self.times):
                raise ValueError(f"`{name}` has {len(frames)} frames for {len(self.times)} times")
            for f, v in enumerate(frames):
                values = [v] if isinstance(v, (int, float)) else v
                if not isinstance(v, (int, float)) and len(v) != n:
                    raise ValueError(f"`{name}` frame {f}: expected 1 or nx*ny*nz = {n} values, got {len(v)}")
                if not all(0.0 <= x <= MAX_COEFFICIENT for x in values):
                    raise ValueError(f"`{name}` frame {f}: values must be finite, >= 0 and <= {MAX_COEFFICIENT} [1/m]")
        return self


#: The sources of frames (a discriminated union on `type` once there are several kinds).
FramesSpec = InlineFramesSpec
