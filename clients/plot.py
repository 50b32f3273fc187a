"""Plots of a result (schemas.results.SimulationResultPublic): h(t) per reflection order."""
from __future__ import annotations

import numpy as np

from owcsim.schemas.results import SimulationResultPublic


def plot_cir(result: SimulationResultPublic, path=None, link: int | None = None):
    """h(t) [1/s] of each link, per reflection order k and total (report figures 6.1-6.5).

    Draws every link (up to 6) unless `link` picks one; saves to `path` if given and
    returns the matplotlib figure.
    """
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tb = result.time_bins
    links = result.links if link is None else [result.links[link]]
    links = [lk for lk in links if lk.cir is not None][:6]
    if not links:
        raise ValueError("no link of this result has a binned CIR (ask for it with outputs.cir = true)")
    t = tb.t_min_s + tb.time_bin_s * (np.arange(tb.n_bins) + 0.5)
    fig, axes = plt.subplots(len(links), 1, figsize=(8, 3.2 * len(links)), squeeze=False)
    for ax, lk in zip(axes[:, 0], links):
        cir = lk.cir
        assert cir is not None
        by_k = np.asarray(cir.by_reflection_order or [], float) / tb.time_bin_s
        for k, h in enumerate(by_k):
            if h.any() and k <= 8:
                ax.plot(t * 1e9, h, lw=0.9, label=f"k = {k}")
        total = np.asarray(cir.total) / tb.time_bin_s
        ax.plot(t * 1e9, total, "k", lw=1.2, label="total")
        nz = np.flatnonzero(total)
        if len(nz):
            ax.set_xlim(t[nz[0]] * 1e9 - 2, t[min(nz[-1] + 1, len(t) - 1)] * 1e9)
            pos = total[total > 0]
            ax.set_yscale("log")
            ax.set_ylim(max(pos.min(), pos.max() * 1e-6) * 0.5, pos.max() * 2)
        ax.set_xlabel("delay t [ns]")
        ax.set_ylabel("h(t) [1/s]")
        err = lk.dc_gain_stderr
        ax.set_title(f"{lk.transmitter} -> {lk.receiver}: H0 = {lk.dc_gain:.4e}"
                     + (f" ± {err:.1e}" if err else ""), fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
