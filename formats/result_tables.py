"""A result's CIR as tables: the long CSV (cir.csv, the service's result.csv) and numpy arrays (result.npz).

One copy for the command line and the client (result_files.py, clients/result.py) and the
service (server/formats.py): the files they write are the same bytes. Ids that a spreadsheet
would take for a formula are escaped (OWASP CSV injection).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator

import numpy as np

from owcsim.schemas.results import SimulationResultPublic

#: Rows of the CSV per chunk of `cir_csv_chunks`.
CSV_ROWS_PER_CHUNK = 4096
#: The CSV's columns before the per-order ones (power_k0, power_k1, ...).
CIR_CSV_HEADER = ("transmitter", "receiver", "t_start_s", "t_end_s", "h_per_s", "power", "power_stderr")


def csv_cell(value):
    """A CSV cell a spreadsheet will not evaluate: a text starting with =, +, -, @, tab or CR gets a quote;
    None is an empty cell."""
    if isinstance(value, str) and value[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + value
    return "" if value is None else value


def cir_csv_chunks(result: SimulationResultPublic) -> Iterator[str]:
    """Long format: one row per (link with a binned CIR, bin); power per bin per watt, h = power / dt [1/s],
    per reflection order k. Yields the text in chunks of CSV_ROWS_PER_CHUNK rows (bounded memory)."""
    tb = result.time_bins
    dt, t0 = tb.time_bin_s, tb.t_min_s
    cirs = [(lk, lk.cir) for lk in result.links if lk.cir is not None]
    k_max = max((len(c.by_reflection_order or []) for _, c in cirs), default=0) - 1
    out = io.StringIO(newline="")
    w = csv.writer(out)
    w.writerow([*CIR_CSV_HEADER, *(f"power_k{k}" for k in range(k_max + 1))])
    rows = 0
    for lk, cir in cirs:
        by_k = cir.by_reflection_order or []
        tx, rx = csv_cell(lk.transmitter), csv_cell(lk.receiver)
        for b, p in enumerate(cir.total):
            se = cir.total_stderr[b]
            w.writerow(
                [
                    tx,
                    rx,
                    f"{t0 + b * dt:.6e}",
                    f"{t0 + (b + 1) * dt:.6e}",
                    f"{p / dt:.9e}",
                    f"{p:.9e}",
                    "" if se is None else f"{se:.3e}",
                ]
                + [f"{row[b]:.9e}" for row in by_k]
            )
            rows += 1
            if rows % CSV_ROWS_PER_CHUNK == 0:
                yield out.getvalue()
                out.seek(0)
                out.truncate()
    yield out.getvalue()


def _float(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], float)


def cir_arrays(result: SimulationResultPublic) -> dict[str, np.ndarray]:
    """Arrays of the result: t_edges_s (n_bins + 1) [s]; per link (axis 0, in `links` order) dc_gain,
    dc_gain_stderr, transmitter, receiver; per link with a binned CIR (axis 0, in `links` order; its index
    in `links` is cir_link) cir and cir_stderr (n, n_bins) [power per bin per watt; NaN = no error bar] and
    by_reflection_order (n, K + 1, n_bins; zeros when the order split was not asked)."""
    tb = result.time_bins
    links = result.links
    n = tb.n_bins
    cir_link = np.array([i for i, lk in enumerate(links) if lk.cir is not None], np.int64)
    cirs = [c for c in (links[i].cir for i in cir_link) if c is not None]
    orders = max((len(c.by_reflection_order or [[]]) for c in cirs), default=1)
    by_k = np.zeros((len(cirs), orders, n))
    for i, c in enumerate(cirs):
        if c.by_reflection_order:
            by_k[i, : len(c.by_reflection_order)] = c.by_reflection_order
    return {
        "t_edges_s": tb.t_min_s + tb.time_bin_s * np.arange(n + 1),
        "cir_link": cir_link,
        "cir": np.array([c.total for c in cirs], float).reshape(len(cirs), n),
        "cir_stderr": np.array([_float(c.total_stderr) for c in cirs]).reshape(len(cirs), n),
        "by_reflection_order": by_k,
        "dc_gain": _float([lk.dc_gain for lk in links]),
        "dc_gain_stderr": _float([lk.dc_gain_stderr for lk in links]),
        "transmitter": np.array([lk.transmitter for lk in links], str),
        "receiver": np.array([lk.receiver for lk in links], str),
    }
