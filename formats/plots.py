"""The CIR figure of a result: h(t) per reflection order and total, one panel per link.

One drawing for the command line's cir.png (`--plot-format png`; its default cir.svg is svg.py's), the
client's `Result.plot()` (`plot_cir`) and the service's plot.png (server/formats.py draws it from the rows
of a stored .npz). matplotlib's object API (Figure + the Agg canvas), never pyplot: no global state (the
service draws from several threads, under a lock), and pyplot's import is not paid. matplotlib is
imported inside `cir_figure`, so importing this module stays light.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from owcsim.schemas.results import SimulationResultPublic

#: Links drawn at most in one figure.
MAX_PANELS = 6
#: Reflection orders drawn (k = 0..MAX_ORDER), besides the total.
MAX_ORDER = 8


@dataclass(frozen=True)
class CirPanel:
    """One link's panel: its ids, H0 with its error, power per bin per watt (total and per reflection order)."""

    transmitter: str
    receiver: str
    dc_gain: float | None
    dc_gain_stderr: float | None
    total: np.ndarray  # (n_bins,)
    by_reflection_order: np.ndarray  # (K + 1, n_bins), possibly (0, n_bins)


def panels_of(result: SimulationResultPublic, link: int | None = None) -> list[CirPanel]:
    """The panels of the links with a binned CIR (the first MAX_PANELS, or link `link`)."""
    n = result.time_bins.n_bins
    links = result.links if link is None else [result.links[link]]
    return [
        CirPanel(
            lk.transmitter,
            lk.receiver,
            lk.dc_gain,
            lk.dc_gain_stderr,
            np.asarray(lk.cir.total, float),
            np.asarray(lk.cir.by_reflection_order or [], float).reshape(-1, n),
        )
        for lk in links
        if lk.cir is not None
    ][:MAX_PANELS]


def cir_figure(t_min_s: float, time_bin_s: float, n_bins: int, panels: list[CirPanel]) -> Figure:
    """h(t) = power per bin / dt [1/s] against the delay [ns], log scale, one panel per link (report
    figures 6.1-6.5); a single empty panel when there is no link."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows: list[CirPanel | None] = list(panels[:MAX_PANELS]) or [None]
    t_ns = 1e9 * (t_min_s + time_bin_s * (np.arange(n_bins) + 0.5))
    fig = Figure(figsize=(8, 3.2 * len(rows)))
    FigureCanvasAgg(fig)
    for i, p in enumerate(rows):
        ax = fig.add_subplot(len(rows), 1, i + 1)
        ax.set_xlabel("delay t [ns]")
        ax.set_ylabel("h(t) [1/s]")
        ax.grid(alpha=0.3)
        if p is None:
            ax.set_title("no links")
            continue
        for k, row in enumerate(p.by_reflection_order[: MAX_ORDER + 1]):
            h = np.asarray(row) / time_bin_s
            if h.any():
                ax.plot(t_ns, h, lw=0.9, label=f"k = {k}")
        total = np.asarray(p.total) / time_bin_s
        ax.plot(t_ns, total, "k", lw=1.2, label="total")
        nz = np.flatnonzero(total > 0)
        if len(nz):
            ax.set_xlim(t_ns[nz[0]] - 2, t_ns[min(nz[-1] + 1, len(t_ns) - 1)])
            ax.set_yscale("log")
            ax.set_ylim(max(total[nz].min(), total[nz].max() * 1e-6) * 0.5, total[nz].max() * 2)
        gain = "n/a" if p.dc_gain is None else f"{p.dc_gain:.4e}"
        ax.set_title(
            f"{p.transmitter} -> {p.receiver}: H0 = {gain}"
            + (f" ± {p.dc_gain_stderr:.1e}" if p.dc_gain_stderr else ""),
            fontsize=10,
        )
        ax.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    return fig


def plot_cir(result: SimulationResultPublic, path=None, link: int | None = None) -> Figure:
    """h(t) [1/s] of each link, per reflection order k and total (report figures 6.1-6.5).

    Draws every link with a binned CIR (up to 6) unless `link` picks one; saves to `path` (PNG)
    if given and returns the matplotlib Figure.
    """
    panels = panels_of(result, link)
    if not panels:
        raise ValueError("no link of this result has a binned CIR (ask for it with outputs.cir = true)")
    tb = result.time_bins
    fig = cir_figure(tb.t_min_s, tb.time_bin_s, tb.n_bins, panels)
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig
