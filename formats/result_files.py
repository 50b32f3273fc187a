"""Write a result to a folder: result.json, links.csv, and what the job computed: cir.csv and the CIR figure
for links with a binned CIR; map files (netCDF, .mat, heatmaps) for receiver grids. The figures are SVG
written directly (svg.py: no matplotlib, a few milliseconds) or, with plot_format "png", matplotlib's PNGs.

The result is the typed model (schemas.results.SimulationResultPublic, or the client's Result);
it becomes JSON here, where its bytes leave the process."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from owcsim.formats.map_files import _by_grid, _safe_name, _unique_names, write_map_files
from owcsim.formats.maps import maps_of_result
from owcsim.formats.plots import panels_of, plot_cir
from owcsim.formats.result_tables import cir_csv_chunks, csv_cell
from owcsim.formats.svg import PlotFormat, cir_svg, heatmap_svg
from owcsim.formats.timeline import write_timeline_files
from owcsim.schemas.results import SimulationResultPublic

#: Scalar columns of links.csv (and of the client's links table).
LINK_COLUMNS = (
    "transmitter",
    "receiver",
    "direction",
    "paths",
    "dc_gain",
    "dc_gain_stderr",
    "path_loss_db",
    "received_power_w",
    "mean_delay_s",
    "mean_delay_s_stderr",
    "rms_delay_spread_s",
    "rms_delay_spread_s_stderr",
    "los_gain",
    "illuminance_lx",
    "illuminance_lx_stderr",
    "illuminance_direct_lx",
    "snr_db",
    "ber",
    "max_bit_rate_bps",
)
#: Links above which result.json is written without indentation (a map of thousands of points).
COMPACT_JSON_LINKS = 200


def write_cir_csv(result: SimulationResultPublic, path: Path) -> bool:
    """cir.csv (result_tables.cir_csv_chunks: one row per link with a CIR and bin). Returns False
    (and writes nothing) when no link has a CIR."""
    if not any(lk.cir is not None for lk in result.links):
        return False
    with open(path, "w", newline="") as fh:
        for chunk in cir_csv_chunks(result):
            fh.write(chunk)
    return True


def write_links_csv(result: SimulationResultPublic, path: Path) -> None:
    """One row per link with its scalar figures (empty cells where a figure does not exist)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(LINK_COLUMNS + ("receiver_x_m", "receiver_y_m", "receiver_z_m"))
        for lk in result.links:
            w.writerow([csv_cell(getattr(lk, c)) for c in LINK_COLUMNS] + list(lk.receiver_position))


def result_json(result: SimulationResultPublic, raw: dict | None = None) -> str:
    """result.json's text: the document as served when `raw` is given (fields a newer server adds are kept),
    else the model's; indented for a few links, compact for a map (COMPACT_JSON_LINKS). NaN and inf are null."""
    indent = 1 if len(result.links) <= COMPACT_JSON_LINKS else None
    if raw is not None:
        return json.dumps(raw, indent=indent)
    return result.model_dump_json(indent=indent)


def write_outputs(
    result: SimulationResultPublic,
    out: Path,
    raw: dict | None = None,
    plot: bool = True,
    plot_format: PlotFormat | str = PlotFormat.PNG,
) -> list[Path]:
    """Write the files of a result into the folder `out` (module docstring); `raw`: the document as a server
    sent it (kept in result.json); `plot`: draw the CIR figure and the map heatmaps, as `plot_format`: "png"
    (cir.png, map_*.png by matplotlib: its import and drawing take ~0.3-0.8 s, more for many heatmaps; the
    Python API's `Result.save`) or "svg" (cir.svg, map_*.svg written directly in milliseconds: `owcsim run`)."""
    out = Path(out)
    fmt = PlotFormat(plot_format)
    paths = [out / "result.json", out / "links.csv"]
    paths[0].write_text(result_json(result, raw))
    write_links_csv(result, paths[1])
    if write_cir_csv(result, out / "cir.csv"):
        paths.append(out / "cir.csv")
        if plot:
            paths.append(out / f"cir.{fmt}")
            if fmt is PlotFormat.SVG:
                tb = result.time_bins
                cir_svg(tb.t_min_s, tb.time_bin_s, tb.n_bins, panels_of(result), paths[-1])
            else:
                plot_cir(result, paths[-1])
    if result.maps:
        paths += write_map_outputs(result, out, fmt if plot else None)
    if result.timeline is not None:  # timeline.nc, timeline.csv and its plot (formats/timeline.py)
        paths += write_timeline_files(result.timeline, out, fmt.value if plot else None)
    return paths


#: Map quantities drawn as heatmaps. The others are the same picture in other units or through a monotone
#: function (path loss and received power of the gain, BER of the SNR, the delay-limited bit rate of the
#: RMS delay spread); every quantity is in the netCDF and .mat files.
HEATMAPS = ("dc_gain", "received_power_dbm", "mean_delay_s", "rms_delay_spread_s", "illuminance_lx", "snr_db")


def write_map_outputs(
    result: SimulationResultPublic, out: Path, plot_format: PlotFormat | str | None = PlotFormat.SVG
) -> list[Path]:
    """netCDF (one file per grid), maps.mat and the heatmaps (HEATMAPS) of the maps (maps.py), as
    `map_<grid>_<channel>_<quantity>.svg` (or .png by matplotlib; None: no heatmap)."""
    maps, decor = maps_of_result(result)
    drawn = [q for q in HEATMAPS if any(q in m.values for m in maps)]
    if plot_format is None or PlotFormat(plot_format) is PlotFormat.PNG:
        return write_map_files(maps, out, decor=decor, heatmaps=plot_format is not None and drawn)
    paths = write_map_files(maps, out, decor=decor, heatmaps=False)
    groups = _by_grid(maps)  # the names map_files gives the PNGs, with .svg
    for ms, name in zip(groups.values(), _unique_names(groups, _safe_name)):
        for m, ch in zip(ms, _unique_names((m.channel for m in ms), _safe_name)):
            for q in (q for q in drawn if q in m.values):
                paths.append(heatmap_svg(m, q, decor, out / f"map_{name}_{ch}_{_safe_name(q)}.svg"))
    return paths
