"""Heatmaps of coverage maps: one quantity of a `GridMap` as a PNG in the grid's own (u, v) coordinates,
with the room, the furniture footprints and the luminaires (`MapDecor`).

matplotlib's object API (Figure + the Agg canvas), never pyplot: no global state, so the service can
draw from several threads. matplotlib is imported inside `heatmap_png` (optional.need).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from owcsim.formats.maps import (
    GridMap,
    MapDecor,
    box_corners,
    convex_hull,
    display_unit,
    format_value,
    masked_points,
    summary,
)
from owcsim.formats.optional import need

__all__ = ["heatmap_png"]


def _edges(c: np.ndarray, fallback: float) -> np.ndarray:
    """Cell edges around the point offsets c (midpoints; half a step beyond the ends)."""
    if c.size == 1:
        return np.array([c[0] - fallback / 2, c[0] + fallback / 2])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def _project(m: GridMap, pts: np.ndarray) -> np.ndarray:
    """(n, 3) points -> (n, 2) coordinates (along u, along v) in the grid plane [m]."""
    d = np.asarray(pts, dtype=float).reshape(-1, 3) - m.origin
    return np.stack([d @ m.u, d @ m.v], axis=1)


def _overlaps(poly: np.ndarray, lim: tuple[float, float, float, float]) -> bool:
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    return bool(lo[0] <= lim[1] and hi[0] >= lim[0] and lo[1] <= lim[3] and hi[1] >= lim[2])


def _vec_text(a: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.3g}" if abs(c) > 1e-12 else "0" for c in a) + ")"


def _color_scale(shown: np.ndarray, unit: str, log: bool | None) -> tuple[np.ndarray, Any]:
    """(values to draw, colour norm): a log scale when asked, or by default for a gain or a power in W
    whose positive values span more than two decades (non-positive values are then not drawn)."""
    from matplotlib import colors

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
    return shown, norm


@dataclass(frozen=True)
class _Frame:
    """Where a heatmap draws, in the grid plane's (u, v) coordinates [m]: the cell edges, the grid's box
    (u0, u1, v0, v1), the axes' limits (the grid, or the room when the grid covers most of it, plus 2 %)
    and the room's outline (k, 2) or None."""

    xe: np.ndarray
    ye: np.ndarray
    grid_box: tuple[float, float, float, float]
    lim: list[float]
    room: np.ndarray | None

    @classmethod
    def of(cls, m: GridMap, decor: MapDecor | None) -> _Frame:
        steps = [np.median(np.diff(c)) for c in (m.x, m.y) if c.size > 1]
        fallback = float(steps[0]) if steps else 0.1
        xe, ye = _edges(m.x, fallback), _edges(m.y, fallback)
        lim = [xe[0], xe[-1], ye[0], ye[-1]]
        grid_box = (lim[0], lim[1], lim[2], lim[3])
        room = None
        if decor is not None and decor.room is not None:
            room = convex_hull(_project(m, box_corners(*decor.room)))
            rlo, rhi = room.min(axis=0), room.max(axis=0)
            # Show the walls when the grid covers most of the room; a small patch of a big hall keeps its own frame.
            if (rhi[0] - rlo[0]) <= 2 * (lim[1] - lim[0]) and (rhi[1] - rlo[1]) <= 2 * (lim[3] - lim[2]):
                lim = [min(lim[0], rlo[0]), max(lim[1], rhi[0]), min(lim[2], rlo[1]), max(lim[3], rhi[1])]
        pad = 0.02 * max(lim[1] - lim[0], lim[3] - lim[2])
        lim = [lim[0] - pad, lim[1] + pad, lim[2] - pad, lim[3] + pad]
        return cls(xe, ye, grid_box, lim, room)

    @property
    def width(self) -> float:
        return self.lim[1] - self.lim[0]

    @property
    def height(self) -> float:
        return self.lim[3] - self.lim[2]


def _draw_masked(ax: Any, m: GridMap, frame: _Frame) -> list[Any]:
    """Grey hatched cells where the map is masked; returns a legend entry per reason."""
    from matplotlib import colors
    from matplotlib.patches import Patch

    masked = m.masked
    handles = []
    if masked.any():
        ax.pcolor(
            frame.xe,
            frame.ye,
            np.ma.masked_where(~masked.T, np.ones(masked.T.shape)),
            cmap=colors.ListedColormap(["0.75"]),
            hatch="///",
            edgecolor="0.45",
            linewidth=0.0,
        )
        for r, ij in masked_points(m).items():
            handles.append(Patch(facecolor="0.75", edgecolor="0.45", hatch="///", label=f"masked: {r} ({len(ij)})"))
    return handles


def _draw_furniture(ax: Any, m: GridMap, decor: MapDecor, frame: _Frame) -> None:
    """Outline and name each piece of furniture whose footprint overlaps the grid."""
    from matplotlib.patches import Polygon

    lim = frame.lim
    for name, box_lo, box_hi in decor.furniture:
        poly = convex_hull(_project(m, box_corners(box_lo, box_hi)))
        if len(poly) and _overlaps(poly, frame.grid_box):
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


def _draw_luminaires(ax: Any, m: GridMap, decor: MapDecor, frame: _Frame) -> None:
    """A star with its id for each luminaire whose projection falls inside the axes."""
    if not decor.luminaires:
        return
    lim = frame.lim
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


def _set_axes(ax: Any, m: GridMap, frame: _Frame) -> None:
    """Limits, equal aspect, tick counts and the (u, v) labels."""
    from matplotlib import ticker

    lim, width, height = frame.lim, frame.width, frame.height
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


def _title(m: GridMap, quantity: str, s: dict[str, Any], factor: float, shown_unit: str) -> str:
    """Grid, quantity and channel; min, mean, max in the shown unit; U0 when it means something."""
    stats = (
        "no simulated point with a value"
        if not s["count"]
        else "  ".join(
            f"{k} {format_value(None if s[k] is None else s[k] * factor, shown_unit)}" for k in ("min", "mean", "max")
        )
    )
    stats += "" if shown_unit == "1" or not s["count"] else f" {shown_unit}"
    u0 = "" if s["uniformity"] is None else f",  U0 = min/mean = {s['uniformity']:.3f}"
    return f"{m.grid}: {quantity} from {m.channel}\n{stats}{u0}"


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
    matplotlib = need("matplotlib", "a heatmap")
    from matplotlib import colors
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon

    a = m.quantity(quantity)
    unit = m.units[quantity]
    shown = np.where(m.masked, np.nan, a)
    factor, shown_unit = display_unit(unit, shown)
    shown, norm = _color_scale(shown * factor, unit, log)
    s = summary(m)[quantity]
    frame = _Frame.of(m, decor)

    wide = frame.height < 0.5 * frame.width  # a strip: colour bar below, else beside
    fig_h = min(8.0, max(2.8, (5.2 if wide else 4.6) * frame.height / frame.width + (2.1 if wide else 1.4)))
    fig = Figure(figsize=(6.4, fig_h), dpi=dpi, layout="compressed")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    cm = matplotlib.colormaps[cmap].with_extremes(bad="white")
    mesh = ax.pcolormesh(frame.xe, frame.ye, shown.T, cmap=cm, norm=norm, shading="flat")
    if s["count"]:  # no colour bar for a map without a single value
        bar = fig.colorbar(
            mesh, ax=ax, location="bottom" if wide else "right", shrink=0.8 if wide else 1.0, aspect=30 if wide else 20
        )
        bar.set_label(f"{quantity} [{shown_unit}]" + (" (log scale)" if isinstance(norm, colors.LogNorm) else ""))

    handles = _draw_masked(ax, m, frame)
    if frame.room is not None:
        ax.add_patch(Polygon(frame.room, closed=True, fill=False, edgecolor="0.3", linestyle="--", linewidth=1.0))
    if decor is not None:
        _draw_furniture(ax, m, decor, frame)
        _draw_luminaires(ax, m, decor, frame)
    if handles:
        fig.legend(handles=handles, loc="outside lower center", fontsize=8, frameon=False, ncols=min(2, len(handles)))

    _set_axes(ax, m, frame)
    fig.suptitle(_title(m, quantity, s, factor, shown_unit), fontsize=10)
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path
