"""Write a result document to a folder: result.json, cir.csv, cir.png."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from .plot import plot_cir


def _clean(x):
    """JSON has no NaN/inf: map them to null (the engine already does; this guards the file)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    return x


def write_cir_csv(result: dict, path: Path) -> None:
    """Long format: one row per (link, bin); power per bin per watt, h = power / dt [1/s], per order k."""
    tb = result["time_bins"]
    dt, t0 = tb["time_bin_s"], tb["t_min_s"]
    k_max = max(len(lk["cir"]["by_reflection_order"]) for lk in result["links"]) - 1
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["transmitter", "receiver", "t_start_s", "t_end_s", "h_per_s", "power", "power_stderr"]
                   + [f"power_k{k}" for k in range(k_max + 1)])
        for lk in result["links"]:
            cir = lk["cir"]
            for b, p in enumerate(cir["total"]):
                se = cir["total_stderr"][b]
                w.writerow([lk["transmitter"], lk["receiver"], f"{t0 + b * dt:.6e}", f"{t0 + (b + 1) * dt:.6e}",
                            f"{p / dt:.9e}", f"{p:.9e}", "" if se is None else f"{se:.3e}"]
                           + [f"{row[b]:.9e}" for row in cir["by_reflection_order"]])


def write_outputs(result: dict, out: Path) -> list[Path]:
    out = Path(out)
    paths = [out / "result.json", out / "cir.csv", out / "cir.png"]
    paths[0].write_text(json.dumps(_clean(result), indent=1))
    write_cir_csv(result, paths[1])
    plot_cir(result, paths[2])
    return paths
