"""Coverage maps as arrays: quantities over a receiver grid (`GridMap`), what a heatmap draws besides
them (`MapDecor`), their summary (min, mean, max, uniformity U0) as numbers and as a text table.

A `GridMap` holds one channel (a transmitter, or a group of transmitters summed) over one
receiver grid, as (nu, nv) arrays indexed like the grid's receiver ids `{grid}[i,j]`. This module
only formats: the engine computes the maps; `maps_of_result` reads them from a result document.
Files (netCDF, .mat, a table) are in map_files.py, heatmaps in heatmap.py. numpy is the only import.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from owcsim.schemas.results import SimulationResultPublic
    from owcsim.schemas.scene import SceneSpec

__all__ = [
    "GridMap",
    "MapDecor",
    "PlaneFrame",
    "display_unit",
    "format_summary",
    "format_value",
    "maps_of_result",
    "masked_points",
    "room_axes",
    "summary",
]

_QUANTITY_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,55}\Z")
#: Names a quantity may not take: they are the coordinates and companions of the Dataset.
_RESERVED = {"channel", "x", "y", "z", "u", "v", "i", "j", "position_x", "position_y", "position_z", "mask_reason"}
#: Units on a logarithmic scale: no uniformity ratio (a ratio of decibels means nothing).
_LOG_UNITS = {"dB", "dBm", "dBW", "dBi", "dBc"}
#: Quantities whose min / mean is no uniformity: probabilities, error figures and path counts.
_NO_UNIFORMITY = {"ber", "outage_probability", "dc_gain_rel_error", "paths"}


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
    receiver_normal: np.ndarray | None = None  # the receivers' unit normal; None: u x v

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
        n = np.cross(u, v) if self.receiver_normal is None else _vec3(self.receiver_normal, f"{where}: receiver_normal")
        if abs(np.linalg.norm(n) - 1) > 1e-6:
            raise ValueError(f"{where}: receiver_normal must be a unit vector, got {n}")
        set_(self, "receiver_normal", n)

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


# ---------------------------------------------------------------- room coordinates


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) of the axis-aligned box lo..hi [m]."""
    sel = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    return np.where(sel == 1, hi, lo)


def convex_hull(p: np.ndarray) -> np.ndarray:
    """Convex hull (k, 2) of 2-D points, counter-clockwise (Andrew's monotone chain, 1979); a flat set keeps its
    two ends. Our own lines rather than scipy's Qhull, which refuses the degenerate (flat) projections of thin
    boxes that a map must still draw."""
    pts = sorted({(round(float(a), 12), round(float(b), 12)) for a, b in p})
    if len(pts) <= 2:
        return np.array(pts)

    def half(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
        chain: list[tuple[float, float]] = []
        for q in points:
            while len(chain) >= 2 and (
                (chain[-1][0] - chain[-2][0]) * (q[1] - chain[-2][1])
                - (chain[-1][1] - chain[-2][1]) * (q[0] - chain[-2][0])
                <= 0
            ):
                chain.pop()
            chain.append(q)
        return chain

    return np.array(half(pts)[:-1] + half(pts[::-1])[:-1])


def room_axes(m: GridMap) -> tuple[int, int] | None:
    """The room axes (0 = x, 1 = y, 2 = z) that u and v lie along (either sign), or None for a plane that is
    not axis-aligned."""
    ku, kv = int(np.argmax(np.abs(m.u))), int(np.argmax(np.abs(m.v)))
    if abs(abs(m.u[ku]) - 1) > 1e-9 or abs(abs(m.v[kv]) - 1) > 1e-9:
        return None
    return ku, kv


@dataclass(frozen=True, eq=False)
class PlaneFrame:
    """A grid's plane as a page shows it: axes `names` (across, up), ("x", "y") on a horizontal grid, ("x", "z")
    on a wall at y = const, ("u", "v") on a tilted plane; `across` and `up` the points' coordinates along
    them [m], increasing (room coordinates when axis-aligned, offsets along u and v otherwise). `arrange` turns
    (..., nu, nv) arrays in grid-index order into (..., rows = up, columns = across); `project` maps room
    points (n, 3) to (across, up) [m]: (p - base) . e_across and (p - base) . e_up."""

    names: tuple[str, str]
    across: np.ndarray
    up: np.ndarray
    transposed: bool  # rows are the j (v) index
    flips: tuple[bool, bool]  # (rows, columns) reversed to make the coordinates increase
    base: np.ndarray
    e_across: np.ndarray
    e_up: np.ndarray

    @classmethod
    def of(cls, m: GridMap) -> PlaneFrame:
        axes = room_axes(m)
        if axes is None:
            return cls(("u", "v"), m.x, m.y, True, (False, False), m.origin, m.u, m.v)
        ku, kv = axes
        transposed = kv > ku  # across is the earlier room axis (x before y before z)
        k_across, k_up = (ku, kv) if transposed else (kv, ku)
        d_across, d_up = (m.u, m.v) if transposed else (m.v, m.u)
        o_across, o_up = (m.x, m.y) if transposed else (m.y, m.x)
        across = m.origin[k_across] + np.sign(d_across[k_across]) * o_across
        up = m.origin[k_up] + np.sign(d_up[k_up]) * o_up
        flips = (bool(d_up[k_up] < 0), bool(d_across[k_across] < 0))
        eye = np.eye(3)
        return cls(
            ("xyz"[k_across], "xyz"[k_up]),
            across[::-1] if flips[1] else across,
            up[::-1] if flips[0] else up,
            transposed,
            flips,
            np.zeros(3),
            eye[k_across],
            eye[k_up],
        )

    def arrange(self, a: np.ndarray) -> np.ndarray:
        """(..., nu, nv) in grid-index order -> (..., rows = up, columns = across)."""
        out = np.swapaxes(a, -1, -2) if self.transposed else np.asarray(a)
        if self.flips[0]:
            out = out[..., ::-1, :]
        if self.flips[1]:
            out = out[..., :, ::-1]
        return out

    def indices(self, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """(i along its dim, j along its dim): the grid index at each row or column position."""
        flip_u, flip_v = (self.flips[1], self.flips[0]) if self.transposed else self.flips
        return np.arange(shape[0])[:: -1 if flip_u else 1], np.arange(shape[1])[:: -1 if flip_v else 1]

    def project(self, p: np.ndarray) -> np.ndarray:
        """(n, 3) room points [m] -> (n, 2) (across, up) [m]."""
        d = np.asarray(p, dtype=float).reshape(-1, 3) - self.base
        return np.stack([d @ self.e_across, d @ self.e_up], axis=1)


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
            if m.units[q] not in _LOG_UNITS and q not in _NO_UNIFORMITY and mean > 0 and row["min"] >= 0:
                row["uniformity"] = row["min"] / mean
        if q in m.stderr:
            se = m.stderr[q]
            ok_se = ok & np.isfinite(se) & (a != 0)
            row["max_rel_stderr"] = float(np.max(np.abs(se[ok_se] / a[ok_se]))) if ok_se.any() else None
        out[q] = row
    return out


_PREFIXES = [(1e9, "G"), (1e6, "M"), (1e3, "k"), (1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p")]


def display_unit(unit: str, values: np.ndarray) -> tuple[float, str]:
    """(factor, shown unit) for a human: delays in ns, powers and rates with an SI prefix."""
    if unit == "s":
        return 1e9, "ns"
    if unit in ("W", "Hz", "bit/s", "A"):
        finite = np.abs(values[np.isfinite(values)])
        top = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
        scale, prefix = next(((s, p) for s, p in _PREFIXES if top >= s), _PREFIXES[-1])
        return 1.0 / scale, prefix + unit
    return 1.0, unit


def format_value(x: float | None, unit: str) -> str:
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
            factor, unit = display_unit(s["unit"], m.values[q][~m.masked])
            scaled = [None if s[k] is None else s[k] * factor for k in ("min", "mean", "max")]
            pts = f"{s['count']}" + (f" ({s['missing']} n/a)" if s["missing"] else "")
            rows.append(
                (
                    f"{m.grid}/{m.channel}",
                    q,
                    *(format_value(x, unit) for x in scaled),
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


def maps_of_result(result: SimulationResultPublic) -> tuple[list[GridMap], MapDecor | None]:
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
        su, sv = m.steps
        maps.append(
            GridMap(
                grid=m.grid,
                channel=m.channel,
                origin=np.asarray(m.origin, float),
                u=np.asarray(m.u, float),
                v=np.asarray(m.v, float),
                x=su * np.arange(nu),
                y=sv * np.arange(nv),
                values={q: np.array(v, dtype=float).reshape(nu, nv) for q, v in m.values.items()},
                stderr={q: np.array(v, dtype=float).reshape(nu, nv) for q, v in m.stderr.items()},
                units=dict(m.units),
                mask_reason=reasons[m.grid],
                receiver_normal=None if m.normal is None else np.asarray(m.normal, float),
            )
        )
    return maps, MapDecor.from_scene(result.scene)
