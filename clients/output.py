"""Write a result document to a folder: result.json, links.csv, and what the job computed:
cir.csv and cir.png for links with a binned CIR; map files (netCDF, .mat, heatmaps) for receiver grids."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from .plot import plot_cir

#: Scalar columns of links.csv (and of the command line's summaries).
LINK_COLUMNS = ("transmitter", "receiver", "direction", "paths", "dc_gain", "dc_gain_stderr", "path_loss_db",
                "received_power_w", "mean_delay_s", "mean_delay_s_stderr", "rms_delay_spread_s",
                "rms_delay_spread_s_stderr", "los_gain", "illuminance_lx", "snr_db", "ber", "max_bit_rate_bps")
#: Links above which result.json is written without indentation (a map of thousands of points).
COMPACT_JSON_LINKS = 200


def _clean(x):
    """JSON has no NaN/inf: map them to null (the engine already does; this guards the file)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    return x


def safe_cell(value):
    """A CSV cell that a spreadsheet will not run as a formula (ids starting with = + - @ are quoted)."""
    if isinstance(value, str) and value[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + value
    return "" if value is None else value


def write_cir_csv(result: dict, path: Path) -> bool:
    """Long format: one row per (link with a CIR, bin); power per bin per watt, h = power / dt [1/s], per order k.
    Returns False (and writes nothing) when no link has a CIR."""
    links = [lk for lk in result["links"] if lk.get("cir")]
    if not links:
        return False
    tb = result["time_bins"]
    dt, t0 = tb["time_bin_s"], tb["t_min_s"]
    k_max = max(len(lk["cir"].get("by_reflection_order") or []) for lk in links) - 1
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["transmitter", "receiver", "t_start_s", "t_end_s", "h_per_s", "power", "power_stderr"]
                   + [f"power_k{k}" for k in range(k_max + 1)])
        for lk in links:
            cir = lk["cir"]
            by_k = cir.get("by_reflection_order") or []
            for b, p in enumerate(cir["total"]):
                se = cir["total_stderr"][b]
                w.writerow([safe_cell(lk["transmitter"]), safe_cell(lk["receiver"]), f"{t0 + b * dt:.6e}",
                            f"{t0 + (b + 1) * dt:.6e}", f"{p / dt:.9e}", f"{p:.9e}", "" if se is None else f"{se:.3e}"]
                           + [f"{row[b]:.9e}" for row in by_k])
    return True


def write_links_csv(result: dict, path: Path) -> None:
    """One row per link with its scalar figures (empty cells where a figure does not exist)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(LINK_COLUMNS + ("receiver_x_m", "receiver_y_m", "receiver_z_m"))
        for lk in result["links"]:
            pos = lk.get("receiver_position") or (None, None, None)
            w.writerow([safe_cell(lk.get(c)) for c in LINK_COLUMNS] + list(pos))


def write_outputs(result: dict, out: Path) -> list[Path]:
    out = Path(out)
    paths = [out / "result.json", out / "links.csv"]
    indent = 1 if len(result["links"]) <= COMPACT_JSON_LINKS else None
    paths[0].write_text(json.dumps(_clean(result), indent=indent))
    write_links_csv(result, paths[1])
    if write_cir_csv(result, out / "cir.csv"):
        paths.append(out / "cir.csv")
        plot_cir(result, out / "cir.png")
        paths.append(out / "cir.png")
    if result.get("maps"):
        paths += write_map_outputs(result, out)
    return paths


def write_map_outputs(result: dict, out: Path) -> list[Path]:
    """netCDF (one file per grid), maps.mat and a heatmap PNG per map quantity (owcsim.schemas.maps)."""
    from owcsim.schemas.maps import maps_from_document, write_map_files

    maps, decor = maps_from_document(result)
    return write_map_files(maps, out, decor=decor)
