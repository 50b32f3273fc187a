"""Coverage-map files: an xarray Dataset and netCDF per grid, one MATLAB .mat file, a pandas table;
`write_map_files` writes a folder of them with the heatmaps (heatmap.py).

netCDF3 (64-bit offset) written directly with scipy.io.netcdf_file in the layout xarray writes and reads
(`to_netcdf`; the `h5netcdf` / `netcdf4` engines go through xarray). It needs no HDF5 library and
scipy is already an engine dependency; a map of 1e5 points x a few quantities is a few MB, far from
any netCDF3 limit, and netCDF3 files open in every netCDF reader (xarray, MATLAB `ncread`, ncview,
Panoply). Pass `engine="h5netcdf"` to `to_netcdf` for netCDF4 if that package is installed.
xarray, scipy and pandas are imported when a function needs them (optional.need).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from owcsim.formats.heatmap import heatmap_png
from owcsim.formats.maps import GridMap, MapDecor, PlaneFrame
from owcsim.formats.optional import need

if TYPE_CHECKING:  # pragma: no cover
    import xarray

__all__ = ["from_xarray", "to_dataframe", "to_netcdf", "to_xarray", "write_map_files"]


def _one_grid(maps: Sequence[GridMap]) -> GridMap:
    if not maps:
        raise ValueError("no maps given")
    first = maps[0]
    for m in maps[1:]:
        same = (
            m.grid == first.grid
            and m.shape == first.shape
            and np.allclose(m.origin, first.origin)
            and np.allclose(m.u, first.u)
            and np.allclose(m.v, first.v)
            and np.allclose(m.x, first.x)
            and np.allclose(m.y, first.y)
        )
        if not same:
            raise ValueError(
                f"maps of different grids ({first.grid!r} and {m.grid!r}, or the same name with "
                "other points): give one grid's maps, or use write_map_files"
            )
    channels = [m.channel for m in maps]
    dup = sorted({c for c in channels if channels.count(c) > 1})
    if dup:
        raise ValueError(f"grid {first.grid!r}: channels {dup} given more than once")
    return first


def _stacked(maps: Sequence[GridMap]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, str]]:
    """Values and stderr per quantity as (channel, nu, nv), NaN for a channel that lacks it; units checked."""
    units: dict[str, str] = {}
    for m in maps:
        for q, un in m.units.items():
            if units.setdefault(q, un) != un:
                raise ValueError(f"grid {m.grid!r}: quantity {q!r} in {units[q]!r} and {un!r}")
    nan = np.full(maps[0].shape, np.nan)
    values = {q: np.stack([m.values.get(q, nan) for m in maps]) for q in units}
    with_se = [q for q in units if any(q in m.stderr for m in maps)]
    stderr = {q: np.stack([m.stderr.get(q, nan) for m in maps]) for q in with_se}
    return values, stderr, units


#: A Dataset's parts: name -> (dims, values, attributes), for its data variables and its coordinates.
Parts = dict[str, tuple[tuple[str, ...], Any, dict[str, Any]]]


def to_xarray(maps: Sequence[GridMap]) -> xarray.Dataset:
    """The maps of ONE grid (several channels) as a Dataset, in room coordinates.

    An axis-aligned grid has dims (channel, <later room axis>, <earlier room axis>): ("channel", "y", "x") on
    a horizontal plane, ("channel", "z", "x") on a wall at y = const, with coordinates in room metres,
    increasing, so that `ds.illuminance_lx.plot()` (one channel) draws x across and y up the page; a tilted
    grid has dims (channel, "v", "u"), coordinates the offsets along v and u [m]. Every layout also has the
    coordinates u, v (offsets along the grid's directions [m]), i, j (grid indices, as in the ids
    `{grid}[i,j]`) and position_x/y/z [m]; a variable per quantity and `<q>_stderr`, each with a `units`
    attribute; `mask_reason` over the two plane dims when every channel has the same mask (masks come from
    the geometry), else with the channel too; attributes grid, origin, u, v, normal. netCDF3 does not
    compress: one string per point and channel would be the largest variable of a big grid.
    """
    xr = need("xarray", "a map Dataset")
    data, coords, attrs = _dataset_parts(maps)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _dataset_parts(maps: Sequence[GridMap]) -> tuple[Parts, Parts, dict[str, Any]]:
    """(data variables, coordinates, attributes) of `to_xarray`'s Dataset, without xarray."""
    first = _one_grid(maps)
    values, stderr, units = _stacked(maps)
    frame = PlaneFrame.of(first)
    plane = (frame.names[1], frame.names[0])  # (rows, columns): plot() draws the columns across
    dims = ("channel", *plane)
    data: dict[str, Any] = {}
    for q, a in values.items():
        data[q] = (dims, frame.arrange(a), {"units": units[q]})
        if q in stderr:
            data[f"{q}_stderr"] = (
                dims,
                frame.arrange(stderr[q]),
                {"units": units[q], "long_name": f"standard error of {q}"},
            )
    reasons = np.stack([m.reasons for m in maps]).astype(str)
    same = bool(np.all(reasons == reasons[:1]))
    data["mask_reason"] = (
        plane if same else dims,
        frame.arrange(reasons[0] if same else reasons),
        {"long_name": "why the point is masked; empty for a simulated point"},
    )
    dim_u, dim_v = (plane[1], plane[0]) if frame.transposed else plane
    i, j = frame.indices(first.shape)
    aligned = frame.names != ("u", "v")
    coords: dict[str, Any] = {
        plane[0]: (plane[0], frame.up, {"units": "m", "long_name": _axis_name(plane[0], aligned)}),
        plane[1]: (plane[1], frame.across, {"units": "m", "long_name": _axis_name(plane[1], aligned)}),
        "i": (dim_u, i, {"long_name": "grid index along u"}),
        "j": (dim_v, j, {"long_name": "grid index along v"}),
        "channel": (("channel",), np.array([m.channel for m in maps]), {}),
    }
    if aligned:
        coords["u"] = (dim_u, first.x[i], {"units": "m", "long_name": "offset along u"})
        coords["v"] = (dim_v, first.y[j], {"units": "m", "long_name": "offset along v"})
    pos = first.positions
    coords.update({f"position_{c}": (plane, frame.arrange(pos[..., k]), {"units": "m"}) for k, c in enumerate("xyz")})
    attrs = {
        "grid": first.grid,
        "origin": first.origin,
        "u": first.u,
        "v": first.v,
        "normal": first.receiver_normal,  # the receivers' (u x v may face the other way)
        "title": f"owcsim coverage map of grid {first.grid}",
        "comment": "point (i, j) = origin + u_offset[i] u + v_offset[j] v; NaN where masked or not available",
    }
    return data, coords, attrs


def _axis_name(name: str, aligned: bool) -> str:
    return f"{name} (room)" if aligned else f"offset along {name}"


def from_xarray(ds: xarray.Dataset) -> list[GridMap]:
    """The maps of a Dataset written by `to_xarray` (a channel that lacked a quantity reads back as NaN)."""
    dim_u, dim_v = ds["i"].dims[0], ds["j"].dims[0]
    ds = ds.sortby(["i", "j"]).transpose("channel", dim_u, dim_v, ...)
    quantities = [q for q in ds.data_vars if q != "mask_reason" and not str(q).endswith("_stderr")]
    out = []
    r = ds["mask_reason"].values
    for c in range(ds.sizes["channel"]):
        out.append(
            GridMap(
                grid=str(ds.attrs["grid"]),
                channel=str(ds["channel"].values[c]),
                origin=ds.attrs["origin"],
                u=ds.attrs["u"],
                v=ds.attrs["v"],
                x=ds["u"].values,
                y=ds["v"].values,
                values={str(q): ds[q].values[c] for q in quantities},
                stderr={str(q): ds[f"{q}_stderr"].values[c] for q in quantities if f"{q}_stderr" in ds},
                units={str(q): str(ds[q].attrs.get("units", "")) for q in quantities},
                mask_reason=(r if r.ndim == 2 else r[c]).astype(str),
                receiver_normal=ds.attrs.get("normal"),
            )
        )
    return out


def to_netcdf(
    maps: Sequence[GridMap], path: str | Path, *, engine: Literal["netcdf4", "scipy", "h5netcdf"] = "scipy"
) -> Path:
    """Write the maps of one grid as a netCDF file (netCDF3 through scipy by default); returns the path.

    The scipy engine writes `to_xarray`'s Dataset directly with scipy.io.netcdf_file (`_write_netcdf3`):
    building an xarray Dataset costs a command most of a second (xarray looks for dask, and its file
    locks for dask.distributed), more than the rest of a line-of-sight map's run."""
    path = Path(path)
    if engine == "scipy":
        _write_netcdf3(*_dataset_parts(maps), path)
    else:
        to_xarray(maps).to_netcdf(path, engine=engine)
    return path


def _write_netcdf3(data: Parts, coords: Parts, attrs: dict[str, Any], path: Path) -> None:
    """A netCDF3 file (64-bit offset) of the Dataset parts, as xarray writes them: strings as char arrays
    along a `string<n>` dimension with `_Encoding` utf-8, integers as int32, floats as float64, NaN kept."""
    netcdf = need("scipy.io", "a netCDF file").netcdf_file
    with netcdf(path, "w", version=2) as f:
        for key, value in attrs.items():
            setattr(f, key, np.asarray(value, float) if isinstance(value, tuple | list) else value)
        extra = {c: set(d) for c, (d, _, _) in coords.items() if (c,) != d}  # not a dimension's own coordinate
        for name, (dims, values, var_attrs) in {**coords, **data}.items():
            if name in data:  # CF: the coordinates of a variable are named in its `coordinates` attribute
                own = " ".join(c for c, d in extra.items() if d <= set(dims))
                var_attrs = {**var_attrs, "coordinates": own} if own else var_attrs
            a = np.asarray(values)
            if a.dtype.kind == "U":  # strings: one char per byte, xarray's CharacterArrayCoder
                raw = np.char.encode(a, "utf-8")
                width = max(1, raw.dtype.itemsize)
                a = raw.astype(f"S{width}").view("S1").reshape(*a.shape, width)
                dims = (*dims, f"string{width}")
                var_attrs = {**var_attrs, "_Encoding": "utf-8"}
            elif a.dtype.kind in "iu":
                a = a.astype(np.int32)
            else:
                a = a.astype(float)
            for dim, size in zip(dims, a.shape):
                if dim not in f.dimensions:
                    f.createDimension(dim, size)
            var = f.createVariable(name, a.dtype, dims)
            var[...] = a
            for key, value in var_attrs.items():
                setattr(var, key, value)


def _safe_name(name: str) -> str:
    """A file-name-safe form of a grid, channel or quantity name."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "map"


def _unique_names(names: Iterable[str], make) -> list[str]:
    out: list[str] = []
    for n in names:
        base = make(n)
        cand, k = base, 1
        while cand in out:
            k += 1
            cand = f"{base}_{k}"
        out.append(cand)
    return out


def _by_grid(maps: Sequence[GridMap]) -> dict[str, list[GridMap]]:
    groups: dict[str, list[GridMap]] = {}
    for m in maps:
        groups.setdefault(m.grid, []).append(m)
    return groups


def _mat_struct(maps: list[GridMap]) -> dict[str, Any]:
    first = _one_grid(maps)
    values, stderr, units = _stacked(maps)
    cell = np.empty(len(maps), dtype=object)
    cell[:] = [m.channel for m in maps]
    # reasons as codes into a list (1-based, as MATLAB indexes it; 0 = simulated): a cell per point is slow and big
    names, code = np.unique(np.stack([m.reasons for m in maps]), return_inverse=True)
    code = code.reshape(len(maps), *first.shape)
    if names[0] == "":
        names = names[1:]
    else:
        code = code + 1
    reasons = np.empty(len(names), dtype=object)
    reasons[:] = [str(n) for n in names]
    return {
        "grid": first.grid,
        "channels": cell,
        "origin": first.origin,
        "u": first.u,
        "v": first.v,
        "normal": first.receiver_normal,  # the receivers' (u x v may face the other way)
        "x": first.x,
        "y": first.y,
        "position": first.positions,
        "values": values,
        "stderr": stderr,
        "units": units,
        "mask_code": code.astype(np.int32),
        "mask_reasons": reasons,
    }


def write_map_files(
    maps: Sequence[GridMap],
    folder: str | Path,
    *,
    decor: MapDecor | None = None,
    heatmaps: bool | Iterable[str] = True,
    log: bool | None = None,
) -> list[Path]:
    """Write `map_<grid>.nc` per grid, one `maps.mat` and the heatmaps `map_<grid>_<channel>_<quantity>.png`.

    In maps.mat each grid is a struct `map_<grid>` with grid, channels (cell), origin, u, v, normal,
    x, y, position (nu, nv, 3), values.<q> and stderr.<q> (channel, nu, nv), units.<q>, mask_code
    (channel, nu, nv): 0 for a simulated point, k for the reason mask_reasons{k} (cell). `heatmaps`: True
    for every quantity, False for none, or the quantity names to draw. Returns the paths written.
    """
    savemat = need("scipy.io", "the .mat file").savemat
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    groups = _by_grid(maps)
    names = _unique_names(groups, _safe_name)
    written: list[Path] = []
    mat: dict[str, Any] = {}
    mat_names = _unique_names(names, lambda n: ("map_" + re.sub(r"\W", "_", n))[:63])
    for ms, name, mat_name in zip(groups.values(), names, mat_names):
        written.append(to_netcdf(ms, folder / f"map_{name}.nc"))
        mat[mat_name] = _mat_struct(ms)
    # long_field_names: MATLAB names up to 63 characters (cylindrical_illuminance_direct_lx has 33)
    savemat(folder / "maps.mat", mat, do_compression=True, oned_as="column", long_field_names=True)
    written.append(folder / "maps.mat")
    if heatmaps is False:
        return written
    wanted = None if heatmaps is True else set(heatmaps)
    for ms, name in zip(groups.values(), names):
        for m, ch in zip(ms, _unique_names((m.channel for m in ms), _safe_name)):
            for q in m.values:
                if wanted is None or q in wanted:
                    written.append(heatmap_png(m, q, decor, folder / f"map_{name}_{ch}_{_safe_name(q)}.png", log=log))
    return written


def to_dataframe(maps: GridMap | Sequence[GridMap]):
    """A long table (pandas): one row per (map, point) with grid, channel, i, j, x, y, z (the point in the room
    [m]), u, v (its offsets along the grid's directions [m]), mask_reason, each quantity and its `_stderr`."""
    pd = need("pandas", "a map table")

    frames = []
    for m in [maps] if isinstance(maps, GridMap) else maps:
        ii, jj = np.meshgrid(np.arange(m.shape[0]), np.arange(m.shape[1]), indexing="ij")
        pos = m.positions.reshape(-1, 3)
        cols: dict[str, Any] = {
            "grid": m.grid,
            "channel": m.channel,
            "i": ii.ravel(),
            "j": jj.ravel(),
            "x": pos[:, 0],
            "y": pos[:, 1],
            "z": pos[:, 2],
            "u": m.x[ii.ravel()],
            "v": m.y[jj.ravel()],
            "mask_reason": m.reasons.ravel(),
        }
        for q, a in m.values.items():
            cols[q] = a.ravel()
            if q in m.stderr:
                cols[f"{q}_stderr"] = m.stderr[q].ravel()
        frames.append(pd.DataFrame(cols))
    return pd.concat(frames, ignore_index=True)
