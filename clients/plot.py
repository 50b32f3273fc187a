"""Plots of a result (schemas.results.SimulationResultPublic): h(t) per reflection order (schemas/plots.py)."""

from __future__ import annotations

from owcsim.schemas.plots import cir_figure, panels_of
from owcsim.schemas.results import SimulationResultPublic


def plot_cir(result: SimulationResultPublic, path=None, link: int | None = None):
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
