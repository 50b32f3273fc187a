"""A result document in other forms: the CIR as CSV and as numpy arrays (.npz), h(t) as PNG.

The CSV has the columns of the command line's cir.csv (a test holds the two equal).
Plots use matplotlib's object API, never pyplot, so request threads can draw at once.
"""
from __future__ import annotations

import csv
import io

import numpy as np


def cir_csv(result: dict) -> str:
    """Long format: one row per (link, bin); power per bin per watt, h = power / dt [1/s], per order k."""
    tb = result["time_bins"]
    dt, t0 = tb["time_bin_s"], tb["t_min_s"]
    k_max = max((len(lk["cir"]["by_reflection_order"]) for lk in result["links"]), default=1) - 1
    out = io.StringIO(newline="")
    w = csv.writer(out)
    w.writerow(["transmitter", "receiver", "t_start_s", "t_end_s", "h_per_s", "power", "power_stderr"]
               + [f"power_k{k}" for k in range(k_max + 1)])
    for lk in result["links"]:
        cir = lk["cir"]
        for b, p in enumerate(cir["total"]):
            se = cir["total_stderr"][b]
            w.writerow([lk["transmitter"], lk["receiver"], f"{t0 + b * dt:.6e}", f"{t0 + (b + 1) * dt:.6e}",
                        f"{p / dt:.9e}", f"{p:.9e}", "" if se is None else f"{se:.3e}"]
                       + [f"{row[b]:.9e}" for row in cir["by_reflection_order"]])
    return out.getvalue()


def _float(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], float)


def cir_arrays(result: dict) -> dict[str, np.ndarray]:
    """Arrays of the result: t_edges_s (n_bins + 1), and per link (axis 0, in `links` order):
    cir and cir_stderr (n_links, n_bins) [power per bin per watt; NaN = no error bar],
    by_reflection_order (n_links, K + 1, n_bins), dc_gain, dc_gain_stderr, transmitter, receiver."""
    tb = result["time_bins"]
    links = result["links"]
    n = tb["n_bins"]
    orders = max((len(lk["cir"]["by_reflection_order"]) for lk in links), default=1)
    by_k = np.zeros((len(links), orders, n))
    for i, lk in enumerate(links):
        rows = lk["cir"]["by_reflection_order"]
        by_k[i, :len(rows)] = rows
    return {
        "t_edges_s": tb["t_min_s"] + tb["time_bin_s"] * np.arange(n + 1),
        "cir": np.array([lk["cir"]["total"] for lk in links], float).reshape(len(links), n),
        "cir_stderr": np.array([_float(lk["cir"]["total_stderr"]) for lk in links]).reshape(len(links), n),
        "by_reflection_order": by_k,
        "dc_gain": np.array([lk["dc_gain"] for lk in links], float),
        "dc_gain_stderr": _float([lk["dc_gain_stderr"] for lk in links]),
        "transmitter": np.array([lk["transmitter"] for lk in links], str),
        "receiver": np.array([lk["receiver"] for lk in links], str),
    }


def cir_npz(result: dict) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **cir_arrays(result))
    return buf.getvalue()


def cir_png(result: dict, link: int | None = None) -> bytes:
    """h(t) [1/s] per reflection order and total, one panel per link (up to 6, or the one asked)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    tb = result["time_bins"]
    links = result["links"] if link is None else [result["links"][link]]
    links = links[:6] or [None]
    t_ns = 1e9 * (tb["t_min_s"] + tb["time_bin_s"] * (np.arange(tb["n_bins"]) + 0.5))
    fig = Figure(figsize=(8, 3.2 * len(links)))
    FigureCanvasAgg(fig)
    for i, lk in enumerate(links):
        ax = fig.add_subplot(len(links), 1, i + 1)
        ax.set_xlabel("delay t [ns]")
        ax.set_ylabel("h(t) [1/s]")
        ax.grid(alpha=0.3)
        if lk is None:
            ax.set_title("no links")
            continue
        for k, row in enumerate(lk["cir"]["by_reflection_order"][:9]):
            h = np.asarray(row) / tb["time_bin_s"]
            if h.any():
                ax.plot(t_ns, h, lw=0.9, label=f"k = {k}")
        total = np.asarray(lk["cir"]["total"]) / tb["time_bin_s"]
        ax.plot(t_ns, total, "k", lw=1.2, label="total")
        nz = np.flatnonzero(total > 0)
        if len(nz):
            ax.set_xlim(t_ns[nz[0]] - 2, t_ns[min(nz[-1] + 1, len(t_ns) - 1)])
            ax.set_yscale("log")
            ax.set_ylim(max(total[nz].min(), total[nz].max() * 1e-6) * 0.5, total[nz].max() * 2)
        err = lk["dc_gain_stderr"]
        ax.set_title(f"{lk['transmitter']} -> {lk['receiver']}: H0 = {lk['dc_gain']:.4e}"
                     + (f" ± {err:.1e}" if err else ""), fontsize=10)
        ax.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()
