"""Coverage maps: quantities over a receiver grid, their summary, files (netCDF, .mat) and heatmaps.

A `GridMap` holds one channel (a transmitter, or a group of transmitters summed) over one
receiver grid, as (nu, nv) arrays indexed like the grid's receiver ids `{grid}[i,j]`. This module
only formats and writes: the engine computes the maps. numpy is the only import at module level;
xarray, scipy and matplotlib (the `engine` extra) are imported inside the functions that need them,
so `import owcsim.schemas` stays light.

Files: netCDF through xarray's scipy backend (netCDF3 64-bit offset). It needs no HDF5 library and
scipy is already an engine dependency; a map of 1e5 points x a few quantities is a few MB, far from
any netCDF3 limit, and netCDF3 files open in every netCDF reader (xarray, MATLAB `ncread`, ncview,
Panoply). Pass `engine="h5netcdf"` to `to_netcdf` for netCDF4 if that package is installed.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    import xarray

    from .results import SimulationResultPublic
    from .scene import SceneSpec

__all__ = [
    "GridMap",
    "MapDecor",
    "format_summary",
    "from_xarray",
    "heatmap_png",
    "masked_points",
    "summary",
    "to_dataframe",
    "to_netcdf",
    "to_xarray",
    "write_map_files",
]

_QUANTITY_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,55}\Z")
#: Names a quantity may not take: they are the coordinates and companions of the Dataset.
_RESERVED = {"channel", "x", "y", "i", "j", "position_x", "position_y", "position_z", "mask_reason"}
#: Units on a logarithmic scale: no uniformity ratio (a ratio of decibels means nothing).
_LOG_UNITS = {"dB", "dBm", "dBW", "dBi", "dBc"}


def _need(module: str, what: str):
    """Import an optional dependency, or say which install brings it."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"{what} needs {module.split('.')[0]}: pip install 'owcsim[engine]'") from exc


def _vec3(a: Any, what: str) -> np.ndarray:
    out = np.asarray(a, dtype=float).reshape(-1)
    if out.shape != (3,) or not np.all(np.isfinite(out)):
        raise ValueError(f"{what} must be 3 finite numbers [m], got {a!r}")
    return out


@dataclass(frozen=True, eq=False)
class MapDecor:
    """What a heatmap draws besides the values: room box, furniture footprints, luminaires.

    room: (lo (3,), hi (3,)) [m] or None; furniture: (name, min (3,), max (3,)) [m] per box;
    luminaires: (id, position (3,)) [m] per transmitter.
    """

    room: tuple[np.ndarray, np.ndarray] | None
    furniture: list[tuple[str, np.ndarray, np.ndarray]]
    luminaires: list[tuple[str, np.ndarray]]

    def __post_init__(self) -> None:
        room = None if self.room is None else (_vec3(self.room[0], "room lo"), _vec3(self.room[1], "room hi"))
        furniture = [
            (str(n), _vec3(lo, f"furniture {n!r} min"), _vec3(hi, f"furniture {n!r} max"))
            for n, lo, hi in self.furniture
        ]
        luminaires = [(str(n), _vec3(p, f"luminaire {n!r} position")) for n, p in self.luminaires]
        object.__setattr__(self, "room", room)
        object.__setattr__(self, "furniture", furniture)
        object.__setattr__(self, "luminaires", luminaires)

    @classmethod
    def from_scene(cls, scene: SceneSpec) -> MapDecor:
        """The room box, the furniture boxes (named as the engine names them) and the transmitters of a scene."""
        room = (np.array(scene.room.lo), np.array(scene.room.hi)) if scene.room is not None else None
        furniture = [
            (b.name or f"furniture[{k}]", np.array(b.min), np.array(b.max)) for k, b in enumerate(scene.furniture)
        ]
        luminaires = [(tid, np.array(t.position)) for tid, t in zip(scene.transmitter_ids(), scene.transmitters)]
        return cls(room=room, furniture=furniture, luminaires=luminaires)


@dataclass(frozen=True, eq=False)
class GridMap:
    """Quantities over one receiver grid for one channel (a transmitter, or a group of transmitters summed).

    Point (i, j) sits at `origin + x[i] u + y[j] v` [m]. `values[q]` is (nu, nv), NaN where masked or
    not available; `stderr[q]` its standard error (for a subset of the quantities); `units[q]` a unit
    string ("lx", "W", "dBm", "s", "1" for a gain); `mask_reason[i, j]` is "" for a simulated point,
    else why it is masked (e.g. "inside furniture 'desk'"). Quantity names are identifiers (they
    become netCDF variables and MATLAB fields). Arrays are converted and checked on construction.
    """

    grid: str
    channel: str
    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    x: np.ndarray
    y: np.ndarray
    values: dict[str, np.ndarray]
    stderr: dict[str, np.ndarray]
    units: dict[str, str]
    mask_reason: np.ndarray | None = None

    def __post_init__(self) -> None:
        where = f"map {self.grid!r} / {self.channel!r}"
        set_ = object.__setattr__
        set_(self, "origin", _vec3(self.origin, f"{where}: origin"))
        u, v = _vec3(self.u, f"{where}: u"), _vec3(self.v, f"{where}: v")
        if abs(np.linalg.norm(u) - 1) > 1e-6 or abs(np.linalg.norm(v) - 1) > 1e-6 or abs(u @ v) > 1e-6:
            raise ValueError(f"{where}: u and v must be orthogonal unit vectors, got {u} and {v}")
        set_(self, "u", u)
        set_(self, "v", v)
        x, y = np.asarray(self.x, dtype=float).reshape(-1), np.asarray(self.y, dtype=float).reshape(-1)
        if x.size == 0 or y.size == 0 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise ValueError(f"{where}: x and y must be non-empty finite offsets [m]")
        set_(self, "x", x)
        set_(self, "y", y)
        shape = (x.size, y.size)
        values = {}
        for q, a in self.values.items():
            if not _QUANTITY_NAME.match(q) or q in _RESERVED or q.endswith("_stderr"):
                raise ValueError(
                    f"{where}: {q!r} is not a usable quantity name (an identifier of at most 56 "
                    f"characters, not ending in _stderr, none of {sorted(_RESERVED)})"
                )
            values[q] = self._shaped(a, shape, f"{where}: values[{q!r}]")
        extra = sorted(set(self.stderr) - set(values))
        if extra:
            raise ValueError(f"{where}: stderr of {extra}, which have no values")
        no_unit = sorted(set(values) - set(self.units))
        if no_unit:
            raise ValueError(f"{where}: no unit for {no_unit}")
        set_(self, "values", values)
        set_(self, "stderr", {q: self._shaped(a, shape, f"{where}: stderr[{q!r}]") for q, a in self.stderr.items()})
        set_(self, "units", {q: str(self.units[q]) for q in values})
        if self.mask_reason is None:
            reason = np.full(shape, "", dtype="<U1")
        else:
            reason = np.asarray(self.mask_reason, dtype=str)
            if reason.shape != shape:
                raise ValueError(f"{where}: mask_reason has shape {reason.shape}, the grid {shape}")
        set_(self, "mask_reason", reason)

    @staticmethod
    def _shaped(a: Any, shape: tuple[int, int], what: str) -> np.ndarray:
        out = np.asarray(a, dtype=float)
        if out.shape != shape:
            raise ValueError(f"{what} has shape {out.shape}, the grid {shape}")
        return out

    @property
    def shape(self) -> tuple[int, int]:
        """(nu, nv)."""
        return (self.x.size, self.y.size)

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the grid plane, u x v."""
        return np.cross(self.u, self.v)

    @property
    def reasons(self) -> np.ndarray:
        """(nu, nv) str: `mask_reason` as set on construction ("" where simulated)."""
        assert self.mask_reason is not None  # __post_init__ fills it
        return self.mask_reason

    @property
    def masked(self) -> np.ndarray:
        """(nu, nv) bool: True where the point is masked (has a reason)."""
        return self.reasons != ""

    @property
    def positions(self) -> np.ndarray:
        """(nu, nv, 3) point positions [m]: origin + x[i] u + y[j] v."""
        return self.origin + self.x[:, None, None] * self.u + self.y[None, :, None] * self.v

    def quantity(self, name: str) -> np.ndarray:
        """values[name]; KeyError naming the available quantities if there is none."""
        if name not in self.values:
            raise KeyError(
                f"no quantity {name!r} in map {self.grid!r} / {self.channel!r}; "
                f"available: {', '.join(sorted(self.values)) or 'none'}"
            )
        return self.values[name]


# ---------------------------------------------------------------- summary


def masked_points(m: GridMap) -> dict[str, np.ndarray]:
    """Masked points by reason: reason -> (k, 2) int array of (i, j)."""
    idx = np.argwhere(m.masked)
    reasons = m.reasons[idx[:, 0], idx[:, 1]]
    return {str(r): idx[reasons == r] for r in np.unique(reasons)}


def summary(m: GridMap) -> dict[str, dict]:
    """Per quantity, over the unmasked points with a finite value: count, min, mean, max, uniformity.

    uniformity = min / mean, the illuminance uniformity U0 = E_min / E_mean of lighting design
    (EN 12464-1:2021 sec. 4.4, ISO 8995-1:2002), the classic VLC case being the work-plane illuminance
    maps of Komine & Nakagawa 2004; the mean is the arithmetic mean over the grid points (the area
    average for a regular grid). None for a quantity on a decibel scale (take the linear one: received
    power in W, not dBm; the mean of a dB quantity is the mean of its dB values), for a non-positive
    mean or negative minimum, and when no point is left.
    Also: `masked` (points with a mask reason), `missing` (unmasked points without a finite value),
    `min_index` / `max_index` (i, j), and `max_rel_stderr` = max stderr / |value| where a stderr is given.
    """
    keep = ~m.masked
    out: dict[str, dict] = {}
    for q, a in m.values.items():
        ok = keep & np.isfinite(a)
        n = int(ok.sum())
        row: dict[str, Any] = {
            "unit": m.units[q],
            "count": n,
            "masked": int(m.masked.sum()),
            "missing": int((keep & ~np.isfinite(a)).sum()),
            "min": None,
            "mean": None,
            "max": None,
            "uniformity": None,
            "min_index": None,
            "max_index": None,
        }
        if n:
            lo = np.where(ok, a, np.inf)
            hi = np.where(ok, a, -np.inf)
            imin, imax = np.unravel_index(np.argmin(lo), a.shape), np.unravel_index(np.argmax(hi), a.shape)
            mean = float(a[ok].mean())
            row.update(
                min=float(a[imin]),
                mean=mean,
                max=float(a[imax]),
                min_index=(int(imin[0]), int(imin[1])),
                max_index=(int(imax[0]), int(imax[1])),
            )
            if m.units[q] not in _LOG_UNITS and mean > 0 and row["min"] >= 0:
                row["uniformity"] = row["min"] / mean
        if q in m.stderr:
            se = m.stderr[q]
            ok_se = ok & np.isfinite(se) & (a != 0)
            row["max_rel_stderr"] = float(np.max(np.abs(se[ok_se] / a[ok_se]))) if ok_se.any() else None
        out[q] = row
    return out


_PREFIXES = [(1e9, "G"), (1e6, "M"), (1e3, "k"), (1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p")]


def _display(unit: str, values: np.ndarray) -> tuple[float, str]:
    """(factor, shown unit) for a human: delays in ns, powers and rates with an SI prefix."""
    if unit == "s":
        return 1e9, "ns"
    if unit in ("W", "Hz", "bit/s", "A"):
        finite = np.abs(values[np.isfinite(values)])
        top = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
        scale, prefix = next(((s, p) for s, p in _PREFIXES if top >= s), _PREFIXES[-1])
        return 1.0 / scale, prefix + unit
    return 1.0, unit


def _fmt(x: float | None, unit: str) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    if unit == "1":
        return f"{x:.3e}"
    if unit in _LOG_UNITS:
        return f"{x:.2f}"
    return f"{x:.4g}"


def format_summary(maps: GridMap | Sequence[GridMap]) -> str:
    """A text table for the command line: one line per (map, quantity), then the masked points by reason."""
    maps = [maps] if isinstance(maps, GridMap) else list(maps)
    header = ("map", "quantity", "min", "mean", "max", "unit", "U0", "points")
    rows, notes = [], []
    for m in maps:
        for q, s in summary(m).items():
            factor, unit = _display(s["unit"], m.values[q][~m.masked])
            scaled = [None if s[k] is None else s[k] * factor for k in ("min", "mean", "max")]
            pts = f"{s['count']}" + (f" ({s['missing']} n/a)" if s["missing"] else "")
            rows.append(
                (
                    f"{m.grid}/{m.channel}",
                    q,
                    *(_fmt(x, unit) for x in scaled),
                    unit,
                    "-" if s["uniformity"] is None else f"{s['uniformity']:.3f}",
                    pts,
                )
            )
        reasons = {r: len(ij) for r, ij in masked_points(m).items()}
        if reasons:
            notes.append(
                f"{m.grid}/{m.channel}: {sum(reasons.values())} masked points: "
                + "; ".join(f"{n} {r}" for r, n in reasons.items())
            )
    widths = [max(len(str(r[c])) for r in [header, *rows]) for c in range(len(header))]
    right = {2, 3, 4, 6, 7}
    lines = [
        "  ".join(
            str(c).rjust(w) if k in right else str(c).ljust(w) for k, (c, w) in enumerate(zip(r, widths))
        ).rstrip()
        for r in [header, *rows]
    ]
    return "\n".join([lines[0], "-" * len(lines[0]), *lines[1:], *dict.fromkeys(notes)])


# ---------------------------------------------------------------- xarray / netCDF / MATLAB


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


def to_xarray(maps: Sequence[GridMap]) -> xarray.Dataset:
    """The maps of ONE grid (several channels) as a Dataset over (channel, i, j).

    Coordinates channel, x(i), y(j) [m] (offsets along u, v) and position_x/y/z(i, j) [m]; a variable
    per quantity and `<q>_stderr`, each with a `units` attribute; `mask_reason` string over (i, j) when
    every channel has the same mask (masks come from the geometry), else over (channel, i, j) (xarray
    broadcasts either); attributes grid, origin, u, v, normal. netCDF3 does not compress: one string
    per point and channel would be the largest variable of a big grid.
    """
    xr = _need("xarray", "a map Dataset")
    first = _one_grid(maps)
    values, stderr, units = _stacked(maps)
    pos = first.positions
    dims = ("channel", "i", "j")
    data: dict[str, Any] = {}
    for q, a in values.items():
        data[q] = (dims, a, {"units": units[q]})
        if q in stderr:
            data[f"{q}_stderr"] = (dims, stderr[q], {"units": units[q], "long_name": f"standard error of {q}"})
    reasons = np.stack([m.reasons for m in maps]).astype(str)
    same = bool(np.all(reasons == reasons[:1]))
    data["mask_reason"] = (
        dims[1:] if same else dims,
        reasons[0] if same else reasons,
        {"long_name": "why the point is masked; empty for a simulated point"},
    )
    coords = {
        "channel": ("channel", [m.channel for m in maps]),
        "x": ("i", first.x, {"units": "m", "long_name": "offset along u"}),
        "y": ("j", first.y, {"units": "m", "long_name": "offset along v"}),
        **{f"position_{c}": (("i", "j"), pos[..., k], {"units": "m"}) for k, c in enumerate("xyz")},
    }
    attrs = {
        "grid": first.grid,
        "origin": first.origin,
        "u": first.u,
        "v": first.v,
        "normal": first.normal,
        "title": f"owcsim coverage map of grid {first.grid}",
        "comment": "point (i, j) = origin + x[i] u + y[j] v; NaN where masked or not available",
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)


def from_xarray(ds: xarray.Dataset) -> list[GridMap]:
    """The maps of a Dataset written by `to_xarray` (a channel that lacked a quantity reads back as NaN)."""
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
                x=ds["x"].values,
                y=ds["y"].values,
                values={str(q): ds[q].values[c] for q in quantities},
                stderr={str(q): ds[f"{q}_stderr"].values[c] for q in quantities if f"{q}_stderr" in ds},
                units={str(q): str(ds[q].attrs.get("units", "")) for q in quantities},
                mask_reason=(r if r.ndim == 2 else r[c]).astype(str),
            )
        )
    return out


def to_netcdf(
    maps: Sequence[GridMap], path: str | Path, *, engine: Literal["netcdf4", "scipy", "h5netcdf"] = "scipy"
) -> Path:
    """Write the maps of one grid as a netCDF file (netCDF3 through scipy by default); returns the path."""
    path = Path(path)
    to_xarray(maps).to_netcdf(path, engine=engine)
    return path


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
        "normal": first.normal,
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
    savemat = _need("scipy.io", "the .mat file").savemat
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
    savemat(folder / "maps.mat", mat, do_compression=True, oned_as="column")
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
    """A long table (pandas): one row per (map, point) with grid, channel, i, j, x, y, position, mask_reason,
    each quantity and its `_stderr`."""
    pd = _need("pandas", "a map table")

    frames = []
    for m in [maps] if isinstance(maps, GridMap) else maps:
        ii, jj = np.meshgrid(np.arange(m.shape[0]), np.arange(m.shape[1]), indexing="ij")
        pos = m.positions.reshape(-1, 3)
        cols: dict[str, Any] = {
            "grid": m.grid,
            "channel": m.channel,
            "i": ii.ravel(),
            "j": jj.ravel(),
            "x": m.x[ii.ravel()],
            "y": m.y[jj.ravel()],
            "position_x": pos[:, 0],
            "position_y": pos[:, 1],
            "position_z": pos[:, 2],
            "mask_reason": m.reasons.ravel(),
        }
        for q, a in m.values.items():
            cols[q] = a.ravel()
            if q in m.stderr:
                cols[f"{q}_stderr"] = m.stderr[q].ravel()
        frames.append(pd.DataFrame(cols))
    return pd.concat(frames, ignore_index=True)


# ---------------------------------------------------------------- heatmap


def _edges(c: np.ndarray, fallback: float) -> np.ndarray:
    """Cell edges around the point offsets c (midpoints; half a step beyond the ends)."""
    if c.size == 1:
        return np.array([c[0] - fallback / 2, c[0] + fallback / 2])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def _hull(p: np.ndarray) -> np.ndarray:
    """Convex hull (k, 2) of 2D points, counter-clockwise (Andrew's monotone chain, 1979).

    Our own 10 lines rather than scipy's Qhull, which refuses the degenerate (flat) projections of
    thin boxes that a map must still draw.
    """
    pts = sorted({(round(a, 12), round(b, 12)) for a, b in p})
    if len(pts) <= 2:
        return np.array(pts)

    def half(points):
        chain: list[tuple[float, float]] = []
        for q in points:
            while (
                len(chain) >= 2
                and (
                    (chain[-1][0] - chain[-2][0]) * (q[1] - chain[-2][1])
                    - (chain[-1][1] - chain[-2][1]) * (q[0] - chain[-2][0])
                )
                <= 0
            ):
                chain.pop()
            chain.append(q)
        return chain

    return np.array(half(pts)[:-1] + half(pts[::-1])[:-1])


def _project(m: GridMap, pts: np.ndarray) -> np.ndarray:
    """(n, 3) points -> (n, 2) coordinates (along u, along v) in the grid plane [m]."""
    d = np.asarray(pts, dtype=float).reshape(-1, 3) - m.origin
    return np.stack([d @ m.u, d @ m.v], axis=1)


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    sel = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    return np.where(sel == 1, hi, lo)


def _overlaps(poly: np.ndarray, lim: tuple[float, float, float, float]) -> bool:
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    return bool(lo[0] <= lim[1] and hi[0] >= lim[0] and lo[1] <= lim[3] and hi[1] >= lim[2])


def _vec_text(a: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.3g}" if abs(c) > 1e-12 else "0" for c in a) + ")"


def heatmap_png(
    m: GridMap,
    quantity: str,
    decor: MapDecor | None,
    path: str | Path,
    *,
    log: bool | None = None,
    dpi: int = 100,
    cmap: str = "viridis",
) -> Path:
    """Draw one quantity of a map as a PNG in the grid's own (u, v) coordinates [m]; returns the path.

    Masked points are grey and hatched (legend gives the reasons), points without a value white.
    Furniture whose projection along the grid normal overlaps the grid is outlined and named; the
    room's projection is dashed; luminaires are stars with their ids. `log`: colour scale; None picks
    a log scale for a gain or a power in W whose positive values span more than two decades.
    Matplotlib's object API only (Figure + FigureCanvasAgg): safe in server threads.
    """
    matplotlib = _need("matplotlib", "a heatmap")
    from matplotlib import colors, ticker
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch, Polygon

    a = m.quantity(quantity)
    unit = m.units[quantity]
    masked = m.masked
    shown = np.where(masked, np.nan, a)
    factor, shown_unit = _display(unit, shown)
    shown = shown * factor
    s = summary(m)[quantity]

    positive = shown[np.isfinite(shown) & (shown > 0)]
    if log is None:
        log = unit in ("1", "W") and positive.size > 0 and positive.max() > 100 * positive.min()
    if log and positive.size:
        norm: colors.Normalize = colors.LogNorm(positive.min(), positive.max())
        shown = np.where(shown > 0, shown, np.nan)
    else:
        finite = shown[np.isfinite(shown)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if hi <= lo:
            pad = abs(lo) * 1e-3 or 1e-12
            lo, hi = lo - pad, hi + pad
        norm = colors.Normalize(lo, hi)

    steps = [np.median(np.diff(c)) for c in (m.x, m.y) if c.size > 1]
    fallback = float(steps[0]) if steps else 0.1
    xe, ye = _edges(m.x, fallback), _edges(m.y, fallback)
    lim = [xe[0], xe[-1], ye[0], ye[-1]]
    grid_box = tuple(lim)
    room = None
    if decor is not None and decor.room is not None:
        room = _hull(_project(m, _box_corners(*decor.room)))
        rlo, rhi = room.min(axis=0), room.max(axis=0)
        # Show the walls when the grid covers most of the room; a small patch of a big hall keeps its own frame.
        if (rhi[0] - rlo[0]) <= 2 * (lim[1] - lim[0]) and (rhi[1] - rlo[1]) <= 2 * (lim[3] - lim[2]):
            lim = [min(lim[0], rlo[0]), max(lim[1], rhi[0]), min(lim[2], rlo[1]), max(lim[3], rhi[1])]
    pad = 0.02 * max(lim[1] - lim[0], lim[3] - lim[2])
    lim = [lim[0] - pad, lim[1] + pad, lim[2] - pad, lim[3] + pad]

    width, height = lim[1] - lim[0], lim[3] - lim[2]
    wide = height < 0.5 * width  # a strip: colour bar below, else beside
    fig_h = min(8.0, max(2.8, (5.2 if wide else 4.6) * height / width + (2.1 if wide else 1.4)))
    fig = Figure(figsize=(6.4, fig_h), dpi=dpi, layout="compressed")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    cm = matplotlib.colormaps[cmap].with_extremes(bad="white")
    mesh = ax.pcolormesh(xe, ye, shown.T, cmap=cm, norm=norm, shading="flat")
    if s["count"]:  # no colour bar for a map without a single value
        bar = fig.colorbar(
            mesh, ax=ax, location="bottom" if wide else "right", shrink=0.8 if wide else 1.0, aspect=30 if wide else 20
        )
        bar.set_label(f"{quantity} [{shown_unit}]" + (" (log scale)" if isinstance(norm, colors.LogNorm) else ""))

    handles = []
    if masked.any():
        ax.pcolor(
            xe,
            ye,
            np.ma.masked_where(~masked.T, np.ones(masked.T.shape)),
            cmap=colors.ListedColormap(["0.75"]),
            hatch="///",
            edgecolor="0.45",
            linewidth=0.0,
        )
        for r, ij in masked_points(m).items():
            handles.append(Patch(facecolor="0.75", edgecolor="0.45", hatch="///", label=f"masked: {r} ({len(ij)})"))
    if room is not None:
        ax.add_patch(Polygon(room, closed=True, fill=False, edgecolor="0.3", linestyle="--", linewidth=1.0))
    if decor is not None:
        for name, box_lo, box_hi in decor.furniture:
            poly = _hull(_project(m, _box_corners(box_lo, box_hi)))
            if len(poly) and _overlaps(poly, grid_box):
                ax.add_patch(Polygon(poly, closed=len(poly) > 2, fill=False, edgecolor="black", linewidth=1.4))
                # name at the centre of the visible part of the footprint's bounding box
                cx = (max(poly[:, 0].min(), lim[0]) + min(poly[:, 0].max(), lim[1])) / 2
                cy = (max(poly[:, 1].min(), lim[2]) + min(poly[:, 1].max(), lim[3])) / 2
                ax.text(
                    cx,
                    cy,
                    name,
                    ha="center",
                    va="center",
                    fontsize=8,
                    clip_on=True,
                    bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "alpha": 0.7, "linewidth": 0},
                )
        if decor.luminaires:
            lp = _project(m, np.array([p for _, p in decor.luminaires]))
            inside = (lp[:, 0] >= lim[0]) & (lp[:, 0] <= lim[1]) & (lp[:, 1] >= lim[2]) & (lp[:, 1] <= lim[3])
            ax.scatter(
                lp[inside, 0],
                lp[inside, 1],
                marker="*",
                s=160,
                facecolor="white",
                edgecolor="black",
                linewidth=1.0,
                zorder=5,
            )
            for (lid, _), (px, py) in zip([lu for lu, k in zip(decor.luminaires, inside) if k], lp[inside]):
                ax.annotate(
                    lid,
                    (px, py),
                    xytext=(6, 6),
                    textcoords="offset points",
                    fontsize=8,
                    zorder=6,
                    bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "alpha": 0.8, "linewidth": 0},
                )
    if handles:
        fig.legend(handles=handles, loc="outside lower center", fontsize=8, frameon=False, ncols=min(2, len(handles)))

    ax.set_xlim(lim[0], lim[1])
    ax.set_ylim(lim[2], lim[3])
    ax.set_aspect("equal")
    # Tick counts fixed from the extents: the automatic ones follow the axes' size, which the layout
    # changes after it has measured the tick labels (and then clips the v label).
    for axis, extent in ((ax.xaxis, width), (ax.yaxis, height)):
        bins = max(2, min(7, round(7 * extent / max(width, height))))
        axis.set_major_locator(ticker.MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]))
    ax.set_xlabel(f"u [m]     (u = {_vec_text(m.u)}, v = {_vec_text(m.v)})")
    ax.set_ylabel("v [m]")
    stats = (
        "no simulated point with a value"
        if not s["count"]
        else "  ".join(
            f"{k} {_fmt(None if s[k] is None else s[k] * factor, shown_unit)}" for k in ("min", "mean", "max")
        )
    )
    stats += "" if shown_unit == "1" or not s["count"] else f" {shown_unit}"
    u0 = "" if s["uniformity"] is None else f",  U0 = min/mean = {s['uniformity']:.3f}"
    fig.suptitle(f"{m.grid}: {quantity} from {m.channel}\n{stats}{u0}", fontsize=10)
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path


def maps_of_result(result: "SimulationResultPublic") -> tuple[list[GridMap], MapDecor | None]:
    """The maps of a result (its `maps`, `receivers` and `scene`) as GridMaps, with the scene's decor."""
    reasons: dict[str, np.ndarray] = {}
    for m in result.maps:
        if m.grid not in reasons:
            mask = np.full(tuple(m.shape), "", dtype=object)
            for r in result.receivers:
                if r.grid == m.grid and r.masked and r.i is not None and r.j is not None:
                    mask[r.i, r.j] = r.masked
            reasons[m.grid] = mask.astype(str)
    maps = []
    for m in result.maps:
        nu, nv = m.shape
        maps.append(
            GridMap(
                grid=m.grid,
                channel=m.channel,
                origin=np.asarray(m.origin, float),
                u=np.asarray(m.u, float),
                v=np.asarray(m.v, float),
                x=m.spacing * np.arange(nu),
                y=m.spacing * np.arange(nv),
                values={q: np.array(v, dtype=float).reshape(nu, nv) for q, v in m.values.items()},
                stderr={q: np.array(v, dtype=float).reshape(nu, nv) for q, v in m.stderr.items()},
                units=dict(m.units),
                mask_reason=reasons[m.grid],
            )
        )
    return maps, MapDecor.from_scene(result.scene)
