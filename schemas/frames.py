"""Time-varying smoke: where a sequence of grid media (frames on one grid, with times) comes from (issue 26).

`FramesSpec` is the union of the sources; each builds an `engine.media.frames.MediumFrames`
(engine/media/frame_sources.py): frames given inline, FDS output (read with fdsreader) and plain netCDF
files with dims (time, z, y, x). `FramesReportPublic` is the printed mapping of a source to sigma_a, sigma_s
(docs/fds-input.md).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, model_validator

from .base import Point, SpecModel
from .medium import MAX_COEFFICIENT, MAX_GRID_CELLS, IsotropicPhaseSpec, ParticlesSpec, PhaseSpec

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


#: Wavelength [nm] at which FDS's default mass-specific extinction coefficient of soot is given (He-Ne laser).
REFERENCE_WAVELENGTH_NM = 632.8
#: FDS's default mass-specific extinction coefficient of soot at 632.8 nm [m^2/kg] (Mulholland & Croarkin 2000).
FDS_MASS_EXTINCTION = 8700.0


class _FileFramesSpec(SpecModel):
    """What file-based frame sources share: which frames, the placement in the room and the optics.

    Frames: all by default; `times_s` picks the frame nearest each given time (duplicates dropped),
    `t_min` / `t_max` [s] keep a time window, `every` keeps every n-th frame of what remains.
    Optics: the file gives the extinction sigma_t [1/m]; sigma_s = albedo sigma_t, sigma_a = sigma_t - sigma_s,
    with `albedo` and `phase` given, or both from the Mie model of `particles` (albedo = <C_sca>/<C_ext>,
    the size-averaged Mie phase function; engine/media/mie.py).
    """

    path: str | None = Field(
        None, min_length=1, description="the file (or folder) to read; relative to the document's folder"
    )
    data_base64: str | None = Field(
        None, min_length=1, description="the input in the document instead of `path` (base64; see the kind)"
    )
    origin: Point = Field(description="room coordinates [m] of the file's point (0, 0, 0): room = file + origin")
    times_s: list[float] | None = Field(
        None, min_length=1, max_length=MAX_FRAMES, description="times [s]: the frame nearest each is taken"
    )
    t_min: float | None = Field(None, description="earliest frame time kept [s]")
    t_max: float | None = Field(None, description="latest frame time kept [s]")
    every: int = Field(1, ge=1, le=100_000, description="keep every n-th frame (after the time window)")
    albedo: float | None = Field(None, ge=0.0, le=1.0, description="single-scattering albedo sigma_s / sigma_t")
    phase: PhaseSpec | None = Field(None, description="phase function with `albedo` (isotropic if omitted)")
    particles: ParticlesSpec | None = Field(None, description="soot particles: albedo and phase by Mie theory")

    @model_validator(mode="after")
    def _optics_and_times(self) -> "_FileFramesSpec":
        if (self.path is None) == (self.data_base64 is None):
            raise ValueError("give exactly one of `path` and `data_base64`")
        self._check_source()
        if not self._gives_extinction():
            if self.albedo is not None or self.particles is not None:
                raise ValueError("the file gives sigma_a and sigma_s: no `albedo` or `particles` (only `phase`)")
        elif (self.albedo is None) == (self.particles is None):
            raise ValueError(
                "give the scattering of the smoke: either `albedo` (sigma_s / sigma_t, with an optional `phase`) "
                "or `particles` (albedo and phase from the Mie model)"
            )
        if self.particles is not None and self.phase is not None:
            raise ValueError("`phase` goes with `albedo`; with `particles` the phase function is Mie's")
        if self.times_s is not None and (self.t_min is not None or self.t_max is not None or self.every != 1):
            raise ValueError("choose frames either by `times_s` or by `t_min` / `t_max` / `every`, not both")
        if self.t_min is not None and self.t_max is not None and self.t_max < self.t_min:
            raise ValueError("`t_max` must not be below `t_min` [s]")
        return self

    def _check_source(self) -> None:
        """The kind's own checks of what to read, before the optics (raise ValueError)."""

    def _gives_extinction(self) -> bool:
        """True when the file holds the extinction only (then the albedo is given or Mie's)."""
        return True


class FdsFramesSpec(_FileFramesSpec):
    """Frames from FDS (NIST Fire Dynamics Simulator) output, read with `fdsreader` (pip install 'owcsim[fire]').

    `path`: the folder holding the case's .smv file, or the .smv file; or `data_base64`: a zip archive of the
    case (one .smv and the files it names; over HTTP, where server paths are refused). `quantity`:
    - "extinction": FDS's SOOT EXTINCTION COEFFICIENT K [1/m] (= FDS's K_m rho_soot), from a 3D slice
      (a cell-centred one, `CELL_CENTERED=.TRUE.`, is preferred: it holds FDS's exact cell values);
    - "soot_density": SOOT DENSITY rho_soot [kg/m^3] from a 3D slice (`source` "slice") or from the SMOKE3D
      file (`source` "smoke3d", decoded by fdsreader's to_physical), K = `mass_extinction_m2_per_kg` rho_soot.
    At the wavelength lambda = `wavelength_nm`, sigma_t = K (632.8 nm / lambda)^x with x = `wavelength_exponent`
    (docs/fds-input.md). `slice_id`: the slice's ID; by default the 3D slice of the quantity (cell-centred first).
    Node-based data (node slices, SMOKE3D) become cells by the mean of each cell's 8 corner nodes that lie
    outside obstructions; cells inside obstructions get 0. Meshes are joined onto one grid (equal cell sizes).
    """

    type: Literal["fds"] = "fds"
    quantity: Literal["extinction", "soot_density"] = "extinction"
    source: Literal["slice", "smoke3d"] = Field("slice", description="slice file, or SMOKE3D (soot density only)")
    slice_id: str | None = Field(None, min_length=1, description="the slice's ID (SLCF ID=...)")
    mass_extinction_m2_per_kg: float = Field(
        FDS_MASS_EXTINCTION, gt=0.0, le=1e5, description="soot K_m at 632.8 nm [m^2/kg] (FDS default 8700)"
    )
    wavelength_nm: float = Field(REFERENCE_WAVELENGTH_NM, ge=200.0, le=20_000.0, description="optical wavelength [nm]")
    wavelength_exponent: float = Field(
        1.0, ge=0.0, le=3.0, description="x in K_m(lambda) = K_m(632.8 nm) (632.8 nm / lambda)^x"
    )

    @model_validator(mode="after")
    def _fds_choices(self) -> "FdsFramesSpec":
        if self.source == "smoke3d" and self.quantity != "soot_density":
            raise ValueError("SMOKE3D holds soot density: use `quantity` 'soot_density' with `source` 'smoke3d'")
        if self.source == "smoke3d" and self.slice_id is not None:
            raise ValueError("`slice_id` is for `source` 'slice'")
        if self.particles is not None and not math.isclose(
            self.particles.wavelength, self.wavelength_nm * 1e-9, rel_tol=1e-6
        ):
            raise ValueError(
                f"`particles.wavelength` ({self.particles.wavelength:g} m) differs from `wavelength_nm` "
                f"({self.wavelength_nm:g} nm): the Mie albedo and the extinction must be at one wavelength"
            )
        return self


class NetcdfFramesSpec(_FileFramesSpec):
    """Frames from a netCDF file (any source): variables with dims (time, z, y, x) and coordinates.

    The file at `path`, or its bytes in `data_base64`. Coordinates `time` [s] and `x`, `y`, `z` [m] hold cell
    centres, uniformly spaced on each axis; the grid's box reaches half a cell beyond the first and last centre.
    Either one `variable` of extinction sigma_t [1/m] (with `albedo`/`phase` or `particles`), or
    `sigma_a_variable` and `sigma_s_variable` [1/m] (then the albedo comes from the file and only `phase` is
    given). NaN is refused.
    """

    type: Literal["netcdf"] = "netcdf"
    variable: str | None = Field(None, description="extinction sigma_t [1/m], dims (time, z, y, x)")
    sigma_a_variable: str | None = Field(None, description="absorption sigma_a [1/m], dims (time, z, y, x)")
    sigma_s_variable: str | None = Field(None, description="scattering sigma_s [1/m], dims (time, z, y, x)")

    def _check_source(self) -> None:
        if (self.sigma_a_variable is None) != (self.sigma_s_variable is None):
            raise ValueError("give both `sigma_a_variable` and `sigma_s_variable`")
        if (self.variable is None) == (self.sigma_a_variable is None):
            raise ValueError("give either `variable` (extinction) or `sigma_a_variable` and `sigma_s_variable`")

    def _gives_extinction(self) -> bool:
        return self.variable is not None


def _frames_kind(value: object) -> str:
    """The `type` of a frames document; "inline" when it has none (documents written before the file kinds)."""
    if isinstance(value, dict):
        return str(value.get("type", "inline"))
    return str(getattr(value, "type", "inline"))


#: The sources of frames, told apart by `type` (default "inline").
FramesSpec = Annotated[
    Annotated[InlineFramesSpec, Tag("inline")]
    | Annotated[FdsFramesSpec, Tag("fds")]
    | Annotated[NetcdfFramesSpec, Tag("netcdf")],
    Discriminator(
        _frames_kind,
        custom_error_type="frames_type",
        custom_error_message="frames `type` must be 'inline', 'fds' or 'netcdf'",
    ),
]


class FramesReportPublic(BaseModel):
    """Where the frames of a time-varying medium come from and how their quantities became sigma_a, sigma_s."""

    model_config = ConfigDict(extra="ignore")

    kind: Literal["inline", "fds", "netcdf"] = Field(description="the kind of source")
    file: str | None = Field(None, description="the file read (the .smv file for FDS)")
    quantity: str = Field(description="what the file holds, e.g. 'SOOT EXTINCTION COEFFICIENT [1/m]'")
    data_id: str | None = Field(None, description="the FDS slice ID, 'SMOKE3D', or the netCDF variable(s)")
    cell_values: str = Field(description="how the file's values became cell values (cell-centred, 8-node mean)")
    mass_extinction_m2_per_kg: float | None = Field(None, description="K_m at 632.8 nm with soot density [m^2/kg]")
    wavelength_nm: float | None = Field(None, description="optical wavelength [nm]")
    wavelength_factor: float = Field(1.0, description="(632.8 nm / lambda)^x applied to the extinction")
    albedo: float | None = Field(None, description="sigma_s / sigma_t in every cell (None: per cell from the file)")
    albedo_from: str = Field(description="'given', 'mie' or 'file'")
    phase: str = Field(description="the phase function's type")
    origin: Point = Field((0.0, 0.0, 0.0), description="room coordinates of the file's (0, 0, 0) [m]")
    grid_min: Point = Field(description="the grid box's low corner in the room [m]")
    grid_max: Point = Field(description="the grid box's high corner in the room [m]")
    grid_shape: tuple[int, int, int] = Field(description="cells (nx, ny, nz)")
    meshes: int = Field(1, description="FDS meshes joined")
    masked_cells: int = Field(0, description="cells inside obstructions, set to 0")
    times_s: list[float] = Field(description="the frames' times [s]")
    max_sigma_t: float = Field(description="largest extinction over all frames and cells [1/m]")

    def text(self) -> str:
        """One line for logs and result headers."""
        km = f", K_m {self.mass_extinction_m2_per_kg:g} m^2/kg" if self.mass_extinction_m2_per_kg else ""
        wl = f", {self.wavelength_nm:g} nm (factor {self.wavelength_factor:.4g})" if self.wavelength_nm else ""
        alb = f"albedo {self.albedo:.4g} ({self.albedo_from})" if self.albedo is not None else "albedo per cell"
        return (
            f"{self.kind} {self.file or ''} {self.data_id or ''}: {self.quantity}{km}{wl}; {self.cell_values}; "
            f"{alb}, phase {self.phase}; grid {list(self.grid_min)}..{list(self.grid_max)} m, shape "
            f"{list(self.grid_shape)}, origin {list(self.origin)} m; {len(self.times_s)} frames "
            f"{self.times_s[0]:g}..{self.times_s[-1]:g} s"
        ).replace("  ", " ")
