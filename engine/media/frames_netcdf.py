"""Frames from a netCDF file with dims (time, z, y, x): any source of smoke fields (issue 26; docs/fds-input.md).

Read with xarray (netCDF-3 through scipy; netCDF-4 files need the netCDF4 or h5netcdf package).
Coordinates `time` [s] and `x`, `y`, `z` [m] are cell centres, uniformly spaced on each axis (relative
tolerance 1e-6); the grid box reaches half a cell beyond the first and last centres, moved by `origin`.
An axis of one cell has no spacing to read: it is refused. The variables are transposed to our layout
(time, x, y, z) (GridMedium's C order, x slowest). Extinction with the albedo given or Mie's, or sigma_a and
sigma_s directly. NaN or negative values are refused with the first bad cell named.
"""

from __future__ import annotations

import base64
import binascii
import io
from pathlib import Path

import numpy as np

from owcsim.engine.core.errors import SceneError
from owcsim.engine.core.lazy import LazyModule
from owcsim.engine.media.frames import MediumFrames, scattering_optics, select_frame_indices, split_extinction
from owcsim.schemas.frames import FramesReportPublic, NetcdfFramesSpec
from owcsim.schemas.medium import MAX_COEFFICIENT, MAX_GRID_CELLS, IsotropicPhaseSpec

xarray = LazyModule("xarray")

#: Relative tolerance on the spacing of the coordinates.
SPACING_RTOL = 1e-6
DIMS = ("time", "z", "y", "x")


def _axis(ds, name: str) -> tuple[float, float]:
    """(low, high) edges [m] of the cells whose centres are coordinate `name`."""
    if name not in ds.coords:
        raise SceneError(f"frames: the netCDF file has no coordinate {name!r} (cell centres [m])")
    c = np.asarray(ds.coords[name].values, np.float64)
    if c.ndim != 1 or len(c) < 2:
        raise SceneError(f"frames: netCDF coordinate {name!r} needs at least 2 cell centres")
    step = np.diff(c)
    if step.min() <= 0 or np.ptp(step) > SPACING_RTOL * step.mean():
        raise SceneError(f"frames: netCDF coordinate {name!r} must be increasing with uniform spacing")
    h = float(step.mean())
    return float(c[0] - h / 2), float(c[-1] + h / 2)


def _variable(ds, name: str) -> np.ndarray:
    if name not in ds.data_vars:
        raise SceneError(f"frames: the netCDF file has no variable {name!r} (variables: {', '.join(ds.data_vars)})")
    v = ds[name]
    if set(v.dims) != set(DIMS):
        raise SceneError(f"frames: netCDF variable {name!r} has dims {v.dims}; expected {DIMS}")
    a = np.asarray(v.transpose("time", "x", "y", "z").values, np.float64)
    bad = np.argwhere(~(np.isfinite(a) & (a >= 0) & (a <= MAX_COEFFICIENT)))
    if len(bad):
        f, i, j, k = (int(n) for n in bad[0])
        raise SceneError(
            f"frames: netCDF variable {name!r} at time index {f}, x {i}, y {j}, z {k} is {a[f, i, j, k]}: "
            f"values must be finite, >= 0 and <= {MAX_COEFFICIENT:g} [1/m]"
        )
    return a


def _open(spec: NetcdfFramesSpec, base_dir: str | Path | None):
    """(dataset, name for messages) of the file at `path`, or of the bytes in `data_base64`."""
    if spec.data_base64 is not None:
        try:
            source: Path | io.BytesIO = io.BytesIO(base64.b64decode(spec.data_base64, validate=True))
        except binascii.Error as err:
            raise SceneError(f"frames: `data_base64` is not valid base64 ({err})") from err
        name = "data_base64"
    else:
        assert spec.path is not None  # the schema asks for one of the two
        path = Path(spec.path)
        source = Path(base_dir) / path if not path.is_absolute() and base_dir is not None else path
        if not source.is_file():
            raise SceneError(f"frames: netCDF file {str(source)!r} not found")
        name = str(source)
    try:
        return xarray.open_dataset(source), name
    except (ValueError, OSError, TypeError) as err:
        raise SceneError(
            f"frames: could not read {name!r} as netCDF ({err}); netCDF-4 files need the netCDF4 or h5netcdf package"
        ) from err


def netcdf_frames(spec: NetcdfFramesSpec, base_dir: str | Path | None = None) -> MediumFrames:
    """The frames of a netCDF file (see the module's docstring)."""
    ds, name = _open(spec, base_dir)
    with ds:
        edges = [_axis(ds, a) for a in "xyz"]
        if "time" not in ds.coords:
            raise SceneError("frames: the netCDF file has no coordinate 'time' [s]")
        times = np.asarray(ds.coords["time"].values, np.float64)
        if times.ndim != 1 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise SceneError("frames: netCDF coordinate 'time' must be finite and strictly increasing [s]")
        idx = select_frame_indices(times, spec.times_s, spec.t_min, spec.t_max, spec.every)
        if spec.variable is not None:
            sigma_t = _variable(ds, spec.variable)[idx]
            albedo, phase, albedo_from = scattering_optics(spec.albedo, spec.phase, spec.particles)
            sigma_a, sigma_s = split_extinction(sigma_t, albedo)
            data_id, quantity, alb = spec.variable, "extinction sigma_t [1/m]", albedo
        else:
            assert spec.sigma_a_variable is not None and spec.sigma_s_variable is not None  # (the schema)
            sigma_a = _variable(ds, spec.sigma_a_variable)[idx]
            sigma_s = _variable(ds, spec.sigma_s_variable)[idx]
            phase, albedo_from, alb = spec.phase or IsotropicPhaseSpec(), "file", None
            data_id = f"{spec.sigma_a_variable}, {spec.sigma_s_variable}"
            quantity = "sigma_a, sigma_s [1/m]"
    if int(np.prod(sigma_a.shape[1:])) > MAX_GRID_CELLS:
        raise SceneError(f"frames: {sigma_a.shape[1:]} cells exceed the limit of {MAX_GRID_CELLS}")
    origin = np.asarray(spec.origin, np.float64)
    lo = np.array([e[0] for e in edges]) + origin
    hi = np.array([e[1] for e in edges]) + origin
    report = FramesReportPublic(
        kind="netcdf",
        file=name,
        quantity=quantity,
        data_id=data_id,
        cell_values="cell-centred values of the file, transposed (time, z, y, x) -> (time, x, y, z)",
        albedo=alb,
        albedo_from=albedo_from,
        phase=str(getattr(phase, "type", "")),
        origin=tuple(float(v) for v in origin),
        grid_min=tuple(float(v) for v in lo),
        grid_max=tuple(float(v) for v in hi),
        grid_shape=tuple(int(n) for n in sigma_a.shape[1:]),
        meshes=1,
        times_s=[float(t) for t in times[idx]],
        max_sigma_t=float((sigma_a + sigma_s).max(initial=0.0)),
    )
    return MediumFrames(times[idx], lo, hi, sigma_a, sigma_s, phase, report.text(), report)
