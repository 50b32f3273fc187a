"""A result (schemas.results.SimulationResultPublic) in other forms: the CIR as CSV and as numpy arrays
(.npz), h(t) as PNG.

The one place that turns a result document into files. The service renders the JSON, CSV
and NPZ once, in the job's worker, when the job ends (`render_all`: compressed files the
store keeps and the routes send as they are). Plots are drawn from the stored .npz
(`npz_png`: the rows of the links drawn, read without loading the others) when first
asked for, so that no job pays matplotlib's time; the default plot is then stored too.
The CSV has the columns of the command line's cir.csv (a test holds the two equal);
ids that a spreadsheet would take for a formula are escaped.
Plots use matplotlib's object API, never pyplot, and are drawn one at a time (`_DRAWING`):
matplotlib's mathtext parser (log-axis tick labels) is not thread-safe, and concurrent
drawing failed under load.
"""
from __future__ import annotations

import csv
import gzip
import io
import threading
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from owcsim.schemas.plots import MAX_PANELS, CirPanel, cir_figure, panels_of
from owcsim.schemas.results import SimulationResultPublic

#: Rows of the CSV written per chunk.
CSV_ROWS_PER_CHUNK = 4096
#: Renders the worker stores: name -> (media type, gzip-compressed as stored?).
RENDERS = {"result.json.gz": ("application/json", True), "result.csv.gz": ("text/csv; charset=utf-8", True),
           "result.npz": ("application/octet-stream", False), "plot.png": ("image/png", False)}
#: Renders made when the job ends (the plot is drawn at its first request).
AT_JOB_END = ("result.json.gz", "result.csv.gz", "result.npz")
#: Links drawn in the default plot.
PLOT_LINKS = MAX_PANELS
#: One plot drawn at a time in a process (see the module's docstring).
_DRAWING = threading.Lock()


def csv_cell(text: str) -> str:
    """A text cell a spreadsheet will not evaluate: a leading =, +, -, @, tab or CR gets a quote (OWASP)."""
    return "'" + text if text[:1] in ("=", "+", "-", "@", "\t", "\r") else text


def cir_csv_chunks(result: SimulationResultPublic) -> Iterator[str]:
    """Long format: one row per (link, bin); power per bin per watt, h = power / dt [1/s], per order k.

    Yields the text in chunks of CSV_ROWS_PER_CHUNK rows (bounded memory for any result)."""
    tb = result.time_bins
    dt, t0 = tb.time_bin_s, tb.t_min_s
    links = [lk for lk in result.links if lk.cir is not None]  # the links that asked for a binned CIR
    k_max = max((len(lk.cir.by_reflection_order or []) for lk in links if lk.cir), default=0) - 1
    out = io.StringIO(newline="")
    w = csv.writer(out)
    w.writerow(["transmitter", "receiver", "t_start_s", "t_end_s", "h_per_s", "power", "power_stderr"]
               + [f"power_k{k}" for k in range(k_max + 1)])
    rows = 0
    for lk in links:
        cir = lk.cir
        assert cir is not None
        by_k = cir.by_reflection_order or []
        tx, rx = csv_cell(lk.transmitter), csv_cell(lk.receiver)
        for b, p in enumerate(cir.total):
            se = cir.total_stderr[b]
            w.writerow([tx, rx, f"{t0 + b * dt:.6e}", f"{t0 + (b + 1) * dt:.6e}",
                        f"{p / dt:.9e}", f"{p:.9e}", "" if se is None else f"{se:.3e}"]
                       + [f"{row[b]:.9e}" for row in by_k])
            rows += 1
            if rows % CSV_ROWS_PER_CHUNK == 0:
                yield out.getvalue()
                out.seek(0)
                out.truncate()
    yield out.getvalue()


def cir_csv(result: SimulationResultPublic) -> str:
    """The whole CSV as one string (small results; the service streams `cir_csv_chunks`)."""
    return "".join(cir_csv_chunks(result))


def _float(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], float)


def cir_arrays(result: SimulationResultPublic) -> dict[str, np.ndarray]:
    """Arrays of the result: t_edges_s (n_bins + 1); per link (axis 0, in `links` order) dc_gain,
    dc_gain_stderr, transmitter, receiver; per link with a binned CIR (axis 0, in `links` order; its
    index in `links` is cir_link) cir and cir_stderr (n, n_bins) [power per bin per watt; NaN = no error
    bar] and by_reflection_order (n, K + 1, n_bins; zeros when the order split was not asked)."""
    tb = result.time_bins
    links = result.links
    n = tb.n_bins
    cir_link = np.array([i for i, lk in enumerate(links) if lk.cir is not None], np.int64)
    cirs = [links[i].cir for i in cir_link]
    orders = max((len(c.by_reflection_order or [[]]) for c in cirs if c), default=1)
    by_k = np.zeros((len(cirs), orders, n))
    for i, c in enumerate(cirs):
        if c and c.by_reflection_order:
            by_k[i, :len(c.by_reflection_order)] = c.by_reflection_order
    return {
        "t_edges_s": tb.t_min_s + tb.time_bin_s * np.arange(n + 1),
        "cir_link": cir_link,
        "cir": np.array([c.total for c in cirs if c], float).reshape(len(cirs), n),
        "cir_stderr": np.array([_float(c.total_stderr) for c in cirs if c]).reshape(len(cirs), n),
        "by_reflection_order": by_k,
        "dc_gain": _float([lk.dc_gain for lk in links]),
        "dc_gain_stderr": _float([lk.dc_gain_stderr for lk in links]),
        "transmitter": np.array([lk.transmitter for lk in links], str),
        "receiver": np.array([lk.receiver for lk in links], str),
    }


def cir_npz(result: SimulationResultPublic) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **cir_arrays(result))
    return buf.getvalue()


def render_all(result: SimulationResultPublic, result_json: str, folder: Path) -> dict[str, Path]:
    """Write the job-end renders of a result into `folder` (AT_JOB_END); returns {name: path}.

    Memory: the CSV and JSON are compressed as they are written; the arrays are those of `cir_arrays`."""
    folder = Path(folder)
    out = {name: folder / name for name in AT_JOB_END}
    with gzip.open(out["result.json.gz"], "wt", encoding="utf-8", compresslevel=6) as f:
        f.write(result_json)
    with gzip.open(out["result.csv.gz"], "wt", encoding="utf-8", newline="", compresslevel=6) as f:
        for chunk in cir_csv_chunks(result):
            f.write(chunk)
    with open(out["result.npz"], "wb") as f:
        np.savez_compressed(f, **cir_arrays(result))
    return out


def _npy_header(f) -> tuple[tuple[int, ...], bool, np.dtype]:
    """(shape, fortran order, dtype) of an .npy stream, positioned at its data afterwards."""
    major, _ = np.lib.format.read_magic(f)
    read = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
    return read(f)


def _npy_rows(archive: zipfile.ZipFile, name: str, start: int, count: int = 1) -> np.ndarray:
    """Rows start..start+count of array `name` (axis 0) of an .npz, read by streaming past the others."""
    with archive.open(name + ".npy") as f:
        shape, fortran, dtype = _npy_header(f)
        if fortran:
            raise ValueError(f"{name}: Fortran-ordered arrays are not read by rows")
        row = dtype.itemsize * int(np.prod(shape[1:], dtype=np.int64))
        skip = row * start
        while skip > 0:
            skip -= len(f.read(min(skip, 1 << 20)))
        data = f.read(row * count)
    return np.frombuffer(data, dtype).reshape((count, *shape[1:]))


def npz_link_count(npz_file) -> int:
    with zipfile.ZipFile(npz_file) as archive, archive.open("dc_gain.npy") as f:
        return int(_npy_header(f)[0][0])


def npz_png(npz_file, link: int | None = None) -> bytes:
    """The plot `cir_png(result, link)` draws, from a stored .npz read row by row (the first
    PLOT_LINKS links, or the one asked)."""
    with zipfile.ZipFile(npz_file) as archive:
        with archive.open("t_edges_s.npy") as f:
            n_bins = int(_npy_header(f)[0][0]) - 1
        edges = _npy_rows(archive, "t_edges_s", 0, 2).ravel()
        with archive.open("cir_link.npy") as f:
            cir_link = np.lib.format.read_array(f)  # one index per link with a CIR (a few, by default)
        if link is None:
            first, count = 0, min(len(cir_link), PLOT_LINKS)
        else:
            where = np.flatnonzero(cir_link == link)
            if not len(where):
                raise KeyError(f"link {link} has no binned CIR (ask for it with outputs.cir = true)")
            first, count = int(where[0]), 1
        rows = {name: _npy_rows(archive, name, first, count) for name in ("cir", "by_reflection_order")}
        per_link = {}
        for name in ("dc_gain", "dc_gain_stderr", "transmitter", "receiver"):
            with archive.open(name + ".npy") as f:
                per_link[name] = np.lib.format.read_array(f)[cir_link[first:first + count]]
    se = per_link["dc_gain_stderr"]
    panels = [CirPanel(str(per_link["transmitter"][i]), str(per_link["receiver"][i]), float(per_link["dc_gain"][i]),
                       None if np.isnan(se[i]) else float(se[i]), rows["cir"][i], rows["by_reflection_order"][i])
              for i in range(count)]
    return _png(float(edges[0]), float(edges[1] - edges[0]), n_bins, panels)


def cir_png(result: SimulationResultPublic, link: int | None = None) -> bytes:
    """h(t) [1/s] per reflection order and total, one panel per link (up to 6, or the one asked)."""
    tb = result.time_bins
    return _png(tb.t_min_s, tb.time_bin_s, tb.n_bins, panels_of(result, link))


def _png(t_min_s: float, time_bin_s: float, n_bins: int, panels: list[CirPanel]) -> bytes:
    with _DRAWING:
        fig = cir_figure(t_min_s, time_bin_s, n_bins, panels)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100)
        return buf.getvalue()
