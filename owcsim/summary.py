"""Command-line summaries of results too large to print link by link (maps of thousands of points)."""
from __future__ import annotations

import numpy as np

#: How each map quantity is printed: (scale, unit shown, format).
_SHOWN = {
    "dc_gain": (1.0, "", ".3e"), "path_loss_db": (1.0, "dB", ".2f"), "received_power_w": (1e3, "mW", ".4g"),
    "received_power_dbm": (1.0, "dBm", ".2f"), "mean_delay_s": (1e9, "ns", ".3f"),
    "rms_delay_spread_s": (1e9, "ns", ".3f"), "illuminance_lx": (1.0, "lx", ".1f"), "snr_db": (1.0, "dB", ".2f"),
    "ber": (1.0, "", ".2e"), "max_bit_rate_bps": (1e-6, "Mbit/s", ".4g"),
}


def map_statistics(values) -> dict[str, float]:
    """min, mean, max over the finite points and the uniformity ratio min / mean (EN 12464-1's U0)."""
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    if not a.size:
        return {"min": np.nan, "mean": np.nan, "max": np.nan, "uniformity": np.nan, "points": 0}
    mean = float(a.mean())
    return {"min": float(a.min()), "mean": mean, "max": float(a.max()),
            "uniformity": float(a.min() / mean) if mean > 0 else np.nan, "points": int(a.size)}


def format_result_summary(result: dict) -> str:
    """Per map (grid x channel): min / mean / max / uniformity of every quantity; then a count of the links."""
    lines = []
    for m in result.get("maps", []):
        nu, nv = m["shape"]
        masked = sum(v is None for row in m["values"]["dc_gain"] for v in row)
        lines.append(f"map {m['grid']} ({nu} x {nv} points{f', {masked} masked' if masked else ''}), "
                     f"channel {m['channel']}:")
        lines.append(f"  {'quantity':<22}{'min':>12}{'mean':>12}{'max':>12}{'min/mean':>10}")
        for q, vals in m["values"].items():
            scale, unit, fmt = _SHOWN.get(q, (1.0, m["units"].get(q, ""), ".4g"))
            st = map_statistics(vals)
            name = f"{q} [{unit}]" if unit else q
            cells = [format(st[k] * scale, fmt) if np.isfinite(st[k]) else "-" for k in ("min", "mean", "max")]
            uni = format(st["uniformity"], ".3f") if np.isfinite(st["uniformity"]) else "-"
            lines.append(f"  {name:<22}{cells[0]:>12}{cells[1]:>12}{cells[2]:>12}{uni:>10}")
    n_links = len(result["links"])
    errs = [lk["dc_gain_stderr"] / lk["dc_gain"] for lk in result["links"] if lk["dc_gain"] and lk["dc_gain_stderr"] is not None]
    worst = max(errs) if errs else float("nan")
    lines.append(f"{n_links:,d} links; largest relative standard error of H0 over links: {worst:.2e}"
                 f"{'; per group: see channels' if result.get('channels') else ''}")
    return "\n".join(lines)
