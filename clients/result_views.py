"""A result at a glance: the few lines a notebook shows for a `Result` (text and HTML), instead of every field.

What ran (scene name, devices, links, group channels, maps), how it ran (paths, wall time, stop reason, the
worst relative standard error of H0 against the target) and a small table of the channels: per group channel
(or per transmitter, without groups) its H0 over the receivers (min, mean, max) and its worst relative error.
"""

from __future__ import annotations

import html
import math
from typing import Any

import numpy as np

from owcsim.schemas.results import SimulationResultPublic

__all__ = ["result_html", "result_text", "MAX_CHANNEL_ROWS"]

#: Channels shown in the table; the others are counted on one line.
MAX_CHANNEL_ROWS = 6
_NAME = 60  # characters of the scene name shown


def _plural(n: int, word: str) -> str:
    return f"{n:,d} {word}{'' if n == 1 else 's'}"


def _e(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.3e}"


def _pct(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{100 * x:.2f} %"


def _facts(r: SimulationResultPublic) -> dict[str, Any]:
    """The figures both views show."""
    n_tx, n_rx = len(r.scene.transmitters), len(r.receivers) or len(r.scene.receivers)
    masked = sum(1 for x in r.receivers if x.masked)
    grids = [f"{g.id_prefix} {g.shape[0]}x{g.shape[1]}" for g in r.scene.receiver_grids]
    groups = list(dict.fromkeys(c.group for c in r.channels))
    devices = f"{_plural(n_tx, 'transmitter')}, {_plural(n_rx, 'receiver')}"
    if grids:
        devices += f" ({'grid' if len(grids) == 1 else 'grids'} {', '.join(grids)}" + (
            f"; {masked:,d} masked)" if masked else ")"
        )
    counts = [_plural(len(r.links), "link")]
    if groups:
        counts.append(f"{_plural(len(groups), 'group channel')} x {n_rx:,d}")
    if r.maps:
        counts.append(_plural(len(r.maps), "map"))
    run = r.run
    worst = run.max_dc_gain_rel_stderr
    err = f", worst rel. error {_pct(worst)}" + (
        f" (target {_pct(run.target_rel_error)})" if run.target_rel_error is not None else ""
    )
    if run.stop_reason.value == "exact":  # line of sight in closed form: no error bar to quote
        err = ""
    name = r.scene.name or "(unnamed scene)"
    return {
        "title": f"{name[:_NAME]}{'...' if len(name) > _NAME else ''}",
        "head": f"algorithm {r.algorithm}, owcsim {r.owcsim_version}",
        "devices": devices,
        "counts": ", ".join(counts),
        "run": f"{run.paths_total:,d} paths in {run.wall_time_s:.3g} s, stop: {run.stop_reason.value}{err}",
        "rows": _channel_rows(r),
        "warnings": len(r.warnings),
    }


def _channel_rows(r: SimulationResultPublic) -> tuple[list[tuple[str, ...]], int]:
    """(rows: channel, receivers, H0 min, mean, max, worst rel. error; channels left out)."""
    if r.channels:
        names = [c.group for c in r.channels]
        h0 = np.array([np.nan if c.dc_gain is None else c.dc_gain for c in r.channels], float)
        se = np.array([np.nan if c.dc_gain_stderr is None else c.dc_gain_stderr for c in r.channels], float)
    else:
        names = [lk.transmitter for lk in r.links]
        h0 = np.array([np.nan if lk.dc_gain is None else lk.dc_gain for lk in r.links], float)
        se = np.array([np.nan if lk.dc_gain_stderr is None else lk.dc_gain_stderr for lk in r.links], float)
    # channels in order of appearance: np.unique sorts, its first indices give the document's order back
    uniq, first, inverse = np.unique(np.array(names, dtype=str), return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first))
    order = [str(n) for n in uniq[np.argsort(first)]]
    key = rank[inverse.reshape(-1)] if names else np.zeros(0, int)
    rows = []
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(h0 > 0, se / h0, np.nan)
    for k, name in enumerate(order[:MAX_CHANNEL_ROWS]):  # a few channels; each a vectorized reduction
        sel = key == k
        h, e = h0[sel], rel[sel]
        ok = np.isfinite(h)
        fig = [float(f(h[ok])) if ok.any() else None for f in (np.min, np.mean, np.max)]
        worst = float(np.nanmax(e)) if np.isfinite(e).any() else None
        rows.append((name, f"{int(sel.sum()):,d}", *(_e(x) for x in fig), _pct(worst)))
    return rows, max(0, len(order) - MAX_CHANNEL_ROWS)


_HEADER = ("channel", "receivers", "H0 min", "H0 mean", "H0 max", "worst rel. err")


def result_text(r: SimulationResultPublic) -> str:
    """A few lines: what ran, how it ran, a table of the channels (at most MAX_CHANNEL_ROWS rows)."""
    f = _facts(r)
    rows, more = f["rows"]
    lines = [
        f"Result: {f['title']} (algorithm {r.algorithm})",
        f"  {f['devices']}",
        f"  {f['counts']}",
        f"  run: {f['run']}",
    ]
    if rows:
        widths = [max(len(row[c]) for row in [_HEADER, *rows]) for c in range(len(_HEADER))]
        for row in [_HEADER, *rows]:
            lines.append(
                "  " + "  ".join(c.ljust(w) if k == 0 else c.rjust(w) for k, (c, w) in enumerate(zip(row, widths)))
            )
        if more:
            lines.append(f"  ... and {more} more channels")
    if f["warnings"]:
        lines.append(f"  {_plural(f['warnings'], 'warning')}: see .warnings")
    return "\n".join(lines)


def result_html(r: SimulationResultPublic) -> str:
    """The same as `result_text`, as a small HTML block for notebooks."""
    f = _facts(r)
    rows, more = f["rows"]
    esc = html.escape
    cells = "".join(f"<th>{esc(h)}</th>" for h in _HEADER)
    body = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in row) + "</tr>" for row in rows) + (
        f'<tr><td colspan="6">... and {more} more channels</td></tr>' if more else ""
    )
    table = f"<table><thead><tr>{cells}</tr></thead><tbody>{body}</tbody></table>" if rows else ""
    warn = f"<p>{_plural(f['warnings'], 'warning')}: see <code>.warnings</code></p>" if f["warnings"] else ""
    return (
        f"<div><p><b>Result</b>: {esc(f['title'])} <small>({esc(f['head'])})</small><br>"
        f"{esc(f['devices'])}<br>{esc(f['counts'])}<br>run: {esc(f['run'])}</p>{table}{warn}</div>"
    )
