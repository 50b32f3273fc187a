"""A result (schemas.results.SimulationResultPublic) in other forms: the CIR as CSV and as numpy arrays
(.npz), h(t) as PNG.

The one place that turns a result document into files. The service renders the JSON, CSV
and NPZ once, in the job's worker, when the job ends (`render_all`: compressed files the
store keeps and the routes send as they are). Plots are drawn from the stored .npz
(`npz_png`: the rows of the links drawn, read without loading the others) when first
asked for, so that no job pays matplotlib's time; the default plot is then stored too.
The CSV and the arrays are formats/result_tables.py's, which the command line and the client
write too (the same bytes).
Plots use matplotlib's object API, never pyplot, and are drawn one at a time (`_DRAWING`):
matplotlib's mathtext parser (log-axis tick labels) is not thread-safe, and concurrent
drawing failed under load.
"""

from __future__ import annotations

import gzip
import io
import threading
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from owcsim.formats.plots import MAX_PANELS, CirPanel, cir_figure, panels_of
from owcsim.formats.result_tables import CSV_ROWS_PER_CHUNK, cir_arrays, cir_csv_chunks, csv_cell

__all__ = [
    "CSV_ROWS_PER_CHUNK",
    "cir_arrays",
    "cir_csv",
    "cir_csv_chunks",
    "cir_npz",
    "cir_png",
    "csv_cell",
    "npz_png",
    "render_all",
]
from owcsim.schemas.results import SimulationResultPublic

#: Renders the worker stores: name -> (media type, gzip-compressed as stored?).
RENDERS = {
    "result.json.gz": ("application/json", True),
    "result.csv.gz": ("text/csv; charset=utf-8", True),
    "result.npz": ("application/octet-stream", False),
    "plot.png": ("image/png", False),
    "timeline.csv.gz": ("text/csv; charset=utf-8", True),  # a result with a `timeline` (formats/timeline.py)
    "timeline.nc": ("application/x-netcdf", False),
    "timeline.svg": ("image/svg+xml", False),
}
#: Renders made when the job ends (the plot is drawn at its first request).
AT_JOB_END = ("result.json.gz", "result.csv.gz", "result.npz")
#: Links drawn in the default plot.
PLOT_LINKS = MAX_PANELS
#: One plot drawn at a time in a process (see the module's docstring).
_DRAWING = threading.Lock()


def cir_csv(result: SimulationResultPublic) -> str:
    """The whole CSV as one string (small results; the service streams `cir_csv_chunks`)."""
    return "".join(cir_csv_chunks(result))


def cir_npz(result: SimulationResultPublic) -> bytes:
    buf = io.BytesIO()
    arrays: dict[str, Any] = cir_arrays(result)  # Any: numpy's stubs type **arrays together with allow_pickle
    np.savez_compressed(buf, **arrays)
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
    arrays: dict[str, Any] = cir_arrays(result)  # Any: numpy's stubs type **arrays together with allow_pickle
    with open(out["result.npz"], "wb") as f:
        np.savez_compressed(f, **arrays)
    if result.timeline is not None:  # the timeline's files: netCDF, CSV (gzipped as stored) and its SVG plot
        from owcsim.formats.timeline import write_timeline_files

        nc, table, svg = write_timeline_files(result.timeline, folder, "svg")
        out["timeline.csv.gz"] = folder / "timeline.csv.gz"
        with open(table, "rb") as src, gzip.open(out["timeline.csv.gz"], "wb", compresslevel=6) as dst:
            dst.write(src.read())
        out.update({"timeline.nc": nc, "timeline.svg": svg})
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
                per_link[name] = np.lib.format.read_array(f)[cir_link[first : first + count]]
    se = per_link["dc_gain_stderr"]
    panels = [
        CirPanel(
            str(per_link["transmitter"][i]),
            str(per_link["receiver"][i]),
            float(per_link["dc_gain"][i]),
            None if np.isnan(se[i]) else float(se[i]),
            rows["cir"][i],
            rows["by_reflection_order"][i],
        )
        for i in range(count)
    ]
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
