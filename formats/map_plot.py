"""A coverage map drawn in room coordinates: `plot_map(result or GridMap, quantity)`.

The map is an image whose extent is the grid's cells in metres (x across and y up for a work plane, x and
z for a wall at y = const, the offsets along u and v for a tilted plane: formats.maps.PlaneFrame), with a
colour bar in the quantity's unit, the room's outline, the furniture boxes' footprints and the luminaires
(transmitter positions) projected on the plane, masked points in grey; on request contour lines and a
second panel with the relative standard error. matplotlib's object API (a Figure, never pyplot) unless an
`ax` is given; matplotlib is imported when a map is drawn (optional.need).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from owcsim.formats.maps import (
    GridMap,
    MapDecor,
    PlaneFrame,
    box_corners,
    convex_hull,
    display_unit,
    maps_of_result,
    summary,
)
from owcsim.formats.optional import need

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["plot_map", "select_map"]

#: Readable names of the quantities a map carries (the colour bar shows "name [unit]").
QUANTITY_NAMES = {
    "illuminance_lx": "illuminance E",
    "dc_gain": "DC gain H0",
    "path_loss_db": "path loss",
    "received_power_w": "received power",
    "received_power_dbm": "received power",
    "mean_delay_s": "mean delay",
    "rms_delay_spread_s": "RMS delay spread",
    "snr_db": "SNR",
    "ber": "bit-error rate",
    "max_bit_rate_bps": "bit rate",
    "received_power_mean_w": "mean received power",
    "snr_mean_db": "mean SNR",
    "outage_probability": "outage probability",
}
#: Label of the outline patches (tests and users find them by it: `patch.get_label()`).
FURNITURE_LABEL, ROOM_LABEL, LUMINAIRE_LABEL = "furniture", "room", "luminaires"


def select_map(source: Any, grid: str | None = None, channel: str | None = None) -> tuple[GridMap, MapDecor | None]:
    """The GridMap to draw and its decor: `source` a GridMap (no decor) or a result (its maps and scene; the
    first grid and its first channel unless named)."""
    if isinstance(source, GridMap):
        return source, None
    if not hasattr(source, "maps") or not hasattr(source, "scene"):
        raise TypeError(f"plot_map draws a result or a GridMap, not {type(source).__name__}")
    maps, decor = maps_of_result(source)
    if not maps:
        raise ValueError("this result has no receiver grid: give the scene `receiver_grids` to get maps")
    grids = list(dict.fromkeys(m.grid for m in maps))
    name = grids[0] if grid is None else grid
    of_grid = [m for m in maps if m.grid == name]
    if not of_grid:
        raise KeyError(f"no grid {name!r}; the grids are {grids}")
    if channel is None:
        return of_grid[0], decor
    chosen = [m for m in of_grid if m.channel == channel]
    if not chosen:
        raise KeyError(f"no channel {channel!r} in grid {name!r}; its channels are {[m.channel for m in of_grid]}")
    return chosen[0], decor


def _extent(c: np.ndarray, step: float) -> tuple[float, float]:
    """Edges of the cells around increasing point coordinates c [m]: half a step beyond the ends."""
    half = (c[-1] - c[0]) / (2 * (c.size - 1)) if c.size > 1 else step / 2
    return float(c[0] - half), float(c[-1] + half)


def _norm(shown: np.ndarray, unit: str, log: bool | None) -> tuple[np.ndarray, Any]:
    """(values to draw, colour norm): logarithmic when asked, or by default for a gain or a power in W whose
    positive values span more than two decades (non-positive values are then not drawn)."""
    from matplotlib import colors

    positive = shown[np.isfinite(shown) & (shown > 0)]
    if log is None:
        log = unit in ("1", "W") and positive.size > 0 and positive.max() > 100 * positive.min()
    if log and positive.size:
        return np.where(shown > 0, shown, np.nan), colors.LogNorm(positive.min(), positive.max())
    finite = shown[np.isfinite(shown)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if hi <= lo:
        pad = abs(lo) * 1e-3 or 1e-12
        lo, hi = lo - pad, hi + pad
    return shown, colors.Normalize(lo, hi)


def _decorate(ax: Axes, frame: PlaneFrame, decor: MapDecor | None, luminaires: bool) -> list[float]:
    """Draw the room outline, the furniture footprints and the luminaires; returns the room's box in the page's
    coordinates [a0, a1, b0, b1], or [] without a room."""
    from matplotlib.patches import Polygon

    if decor is None:
        return []
    box: list[float] = []
    if decor.room is not None:
        room = convex_hull(frame.project(box_corners(*decor.room)))
        ax.add_patch(Polygon(room, closed=True, fill=False, edgecolor="0.2", lw=1.2, label=ROOM_LABEL))
        box = [room[:, 0].min(), room[:, 0].max(), room[:, 1].min(), room[:, 1].max()]
    for name, lo, hi in decor.furniture:
        outline = convex_hull(frame.project(box_corners(lo, hi)))
        if len(outline) >= 3:
            ax.add_patch(
                Polygon(outline, closed=True, fill=False, edgecolor="k", lw=1.0, ls="--", label=FURNITURE_LABEL)
            )
            ax.annotate(name, outline.mean(axis=0), ha="center", va="center", fontsize=7, color="k")
    if luminaires and decor.luminaires:
        p = frame.project(np.array([pos for _, pos in decor.luminaires]))
        ax.scatter(p[:, 0], p[:, 1], marker="*", s=90, c="gold", edgecolors="k", zorder=5, label=LUMINAIRE_LABEL)
    return box


def _panel(
    ax: Axes, frame: PlaneFrame, a: np.ndarray, label: str, unit: str, log: bool | None, cmap: str
) -> tuple[Any, Any]:
    """One image of (nu, nv) values on the page's axes; returns (image, colour bar)."""
    import matplotlib as mpl

    factor, shown_unit = display_unit(unit, a)
    shown, norm = _norm(frame.arrange(a) * factor, unit, log)
    colours = mpl.colormaps[cmap].with_extremes(bad="0.85")
    steps = [float(np.median(np.diff(c))) for c in (frame.across, frame.up) if c.size > 1] or [0.1]
    a0, a1 = _extent(frame.across, steps[0])
    b0, b1 = _extent(frame.up, steps[-1])
    image = ax.imshow(
        shown, origin="lower", extent=(a0, a1, b0, b1), norm=norm, cmap=colours, interpolation="nearest", aspect="equal"
    )
    bar = ax.figure.colorbar(image, ax=ax, shrink=0.85)
    bar.set_label(f"{label} [{shown_unit}]")
    return image, bar


def plot_map(
    source: Any,
    quantity: str = "illuminance_lx",
    *,
    grid: str | None = None,
    channel: str | None = None,
    decor: MapDecor | None = None,
    stderr: bool = False,
    contours: bool | int | Sequence[float] = False,
    log: bool | None = None,
    luminaires: bool = True,
    cmap: str = "viridis",
    ax: Axes | None = None,
    path: str | Path | None = None,
) -> Figure:
    """Draw one quantity of a map in room coordinates and return the Figure (its axes: `fig.axes`).

    `source`: a result (`owcsim.simulate`'s, the client's, or a SimulationResultPublic: the room, furniture
    and luminaires come from its scene; `grid` and `channel` choose the map, by default the first) or a
    GridMap (with `decor` to outline a room). `stderr=True` adds a panel with the relative standard error
    stderr / |value| [%]; `contours` draws labelled contour lines (True: matplotlib's levels, an int: that
    many, a sequence: those levels, in the quantity's unit); `log` forces a logarithmic colour scale or a
    linear one (default: logarithmic for a gain or power spanning more than two decades). `ax` draws the map
    into existing axes (then no stderr panel); `path` saves the figure (PNG, PDF, SVG from the suffix).
    """
    m, found = select_map(source, grid, channel)
    decor = decor if decor is not None else found
    a = m.quantity(quantity)
    unit = m.units[quantity]
    label = QUANTITY_NAMES.get(quantity, quantity)
    if stderr and quantity not in m.stderr:
        raise ValueError(
            f"quantity {quantity!r} has no standard error in map {m.grid!r} (those with one: "
            f"{', '.join(sorted(m.stderr)) or 'none'})"
        )
    if stderr and ax is not None:
        raise ValueError("stderr=True draws a second panel: leave `ax` out, or draw the error map on its own")
    frame = PlaneFrame.of(m)
    if ax is None:
        figure_cls = need("matplotlib.figure", "a map plot").Figure
        fig = figure_cls(figsize=(11.0, 4.6) if stderr else (6.4, 5.0), layout="constrained")
        axes = fig.subplots(1, 2) if stderr else [fig.add_subplot()]
    else:
        fig, axes = ax.figure, [ax]
    a = np.where(m.masked, np.nan, a)
    _panel(axes[0], frame, a, label, unit, log, cmap)
    if contours is not False and np.isfinite(a).sum() >= 4:
        factor, _ = display_unit(unit, a)
        levels = None if contours is True else contours
        lines = axes[0].contour(
            frame.across, frame.up, frame.arrange(a) * factor, levels=levels, colors="w", linewidths=0.8
        )
        axes[0].clabel(lines, fontsize=7, fmt="%.3g")
    s = summary(
        GridMap(m.grid, m.channel, m.origin, m.u, m.v, m.x, m.y, {quantity: a}, {}, {quantity: unit}, m.mask_reason)
    )[quantity]
    factor, shown_unit = display_unit(unit, a)
    shown_unit = "" if shown_unit == "1" else f" {shown_unit}"  # a ratio or a probability: no unit
    figures = "" if s["mean"] is None else f"mean {s['mean'] * factor:.4g}{shown_unit}"
    if s["uniformity"] is not None:
        figures += f", min/mean {s['uniformity']:.3f}"
    axes[0].set_title(f"{m.grid} / {m.channel}: {label}" + (f"\n{figures}" if figures else ""), fontsize=9)
    if stderr:
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(a != 0, 100.0 * np.abs(m.stderr[quantity] / a), np.nan)
        _panel(axes[1], frame, rel, f"relative standard error of {label}", "%", False, "magma")
        axes[1].set_title(f"{m.grid} / {m.channel}: relative standard error", fontsize=9)
    for k, axis in enumerate(axes):
        box = _decorate(axis, frame, decor, luminaires)
        lim = [*_extent(frame.across, 0.1), *_extent(frame.up, 0.1)]
        if box:
            lim = [min(lim[0], box[0]), max(lim[1], box[1]), min(lim[2], box[2]), max(lim[3], box[3])]
        axis.set_xlim(lim[0], lim[1])
        axis.set_ylim(lim[2], lim[3])
        axis.set_xlabel(f"{frame.names[0]} [m]")
        axis.set_ylabel(f"{frame.names[1]} [m]")
        if k == 0 and m.masked.any():
            axis.text(0.01, 0.01, f"{int(m.masked.sum())} masked (grey)", transform=axis.transAxes, fontsize=7)
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig
