"""The serving-cell (handover) map of a result: which cell serves each grid point, the handover boundaries
as lines, the luminaires of each cell, in room coordinates; optionally the SINR or a rate as the colour map.

Reads the result's `cells` section (schemas/cells.py: engine/results/cells.py computes it). matplotlib's
object API (Figure + the Agg canvas), never pyplot, imported on first use (formats/optional.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from owcsim.formats.optional import need

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from owcsim.schemas.results import SimulationResultPublic

__all__ = ["cell_grid", "plot_cells"]

_AXES = {(1.0, 0.0, 0.0): "x", (0.0, 1.0, 0.0): "y", (0.0, 0.0, 1.0): "z"}


def _axis_name(vec: np.ndarray) -> str:
    """'x [m]' for a room axis (either sign), else 'along (ux, uy, uz) [m]'."""
    for axis, name in _AXES.items():
        if np.allclose(np.abs(vec), axis, atol=1e-9):
            return f"{name} [m]"
    return f"along ({', '.join(f'{c:.2g}' for c in vec)}) [m]"


def cell_grid(result: SimulationResultPublic, grid: str | None = None):
    """(cell map, positions (nu, nv, 3) [m]) of one grid (the first by default): the points from `receivers`."""
    if result.cells is None or not result.cells.maps:
        raise ValueError(
            "this result has no serving-cell map (it needs a receiver grid and two cells or a link_budget)"
        )
    maps = result.cells.maps
    chosen = [m for m in maps if grid is None or m.grid == grid]
    if not chosen:
        raise KeyError(f"no grid {grid!r}; the grids are {[m.grid for m in maps]}")
    m = chosen[0]
    nu, nv = m.shape
    pos = np.full((nu, nv, 3), np.nan)
    rows = [(r.i, r.j, r.position) for r in result.receivers if r.grid == m.grid and r.i is not None]
    ii = np.array([r[0] for r in rows], dtype=np.int64)
    jj = np.array([r[1] for r in rows], dtype=np.int64)
    pos[ii, jj] = np.array([r[2] for r in rows], dtype=float).reshape(-1, 3)
    return m, pos


def _edges(c: np.ndarray) -> np.ndarray:
    """Cell edges around centres c (n,): midpoints, half a step beyond the ends (one point: +-0.5)."""
    if len(c) == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = 0.5 * (c[:-1] + c[1:])
    return np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])


def plot_cells(
    result: SimulationResultPublic, path: str | Path | None = None, grid: str | None = None, quantity: str | None = None
) -> Figure:
    """The serving cell of each point of one grid (cell colours), or `quantity` (e.g. "sinr_db",
    "rate_shannon_bps") as a colour map, with the handover boundaries as black lines and each cell's
    luminaires as markers in its colour; axes in room coordinates [m]. Saved to `path` if given."""
    need("matplotlib", "a serving-cell plot")
    from matplotlib import colormaps, colors
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    m, pos = cell_grid(result, grid)  # raises without a cell map
    section = result.cells
    assert section is not None
    cells = section.cells
    u = pos[1, 0] - pos[0, 0] if m.shape[0] > 1 else np.array([1.0, 0.0, 0.0])
    v = pos[0, 1] - pos[0, 0] if m.shape[1] > 1 else np.array([0.0, 1.0, 0.0])
    u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
    xs, ys = pos[:, 0] @ u, pos[0, :] @ v  # room coordinates along the grid's axes
    palette = colormaps["tab10"] if len(cells) <= 10 else colormaps["tab20"]
    cell_colours = [palette(k % palette.N) for k in range(len(cells))]
    fig = Figure(figsize=(6.4, 5.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    serving = np.array([[np.nan if c is None else c for c in row] for row in m.serving_cell], dtype=float)
    if quantity is None:
        cmap = colors.ListedColormap(cell_colours or ["white"])
        norm = colors.BoundaryNorm(np.arange(len(cells) + 1) - 0.5, max(len(cells), 1))
        ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(serving).T, cmap=cmap, norm=norm)
    else:
        if quantity not in m.values:
            raise KeyError(f"no quantity {quantity!r} in the cell map; it has {sorted(m.values)}")
        values = np.array(m.values[quantity], dtype=float)  # None becomes NaN
        mesh = ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(values).T, cmap="viridis")
        fig.colorbar(mesh, ax=ax, label=f"{quantity} [{m.units.get(quantity, '')}]")
    segments = [[(np.dot(b.start, u), np.dot(b.start, v)), (np.dot(b.end, u), np.dot(b.end, v))] for b in m.boundaries]
    if segments:
        ax.add_collection(LineCollection(segments, colors="black", linewidths=1.5))
    tx_ids = result.scene.transmitter_ids()
    for k, members in enumerate(section.members):
        for t in members:
            p = np.asarray(result.scene.transmitters[tx_ids.index(t)].position, float)
            ax.plot(p @ u, p @ v, marker="o", ms=9, mfc=cell_colours[k], mec="black", ls="none")
    ax.legend(
        handles=[
            Line2D([], [], marker="o", ls="none", mfc=c, mec="black", label=n) for n, c in zip(cells, cell_colours)
        ],
        title="cell (luminaires)",
        loc="upper center",
        bbox_to_anchor=(0.5, -0.12),  # below the room: a legend inside it would hide luminaires
        ncol=min(len(cells), 6),
        fontsize="small",
    )
    ax.set_aspect("equal")
    ax.set_xlabel(_axis_name(u))
    ax.set_ylabel(_axis_name(v))
    what = "serving cell" if quantity is None else quantity
    ax.set_title(f"{m.grid}: {what}, handover boundaries")
    if path is not None:
        fig.savefig(path, dpi=100, bbox_inches="tight")
    return fig
