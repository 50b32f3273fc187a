"""The timeline plot (issue 26): H0 and BER (or SNR, without a bit rate) against time, each link (the group
channels when the scene has transmitter groups) in its colour
with its error band (one standard error), the outage intervals shaded in the link's colour (hatched where
uncertain) and the threshold drawn where it is on the panel's quantity.

`timeline_svg` writes SVG directly (the command line: no matplotlib, as svg.py); `timeline_figure` draws the
same picture with matplotlib (the Python API and PNG files).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from owcsim.formats.optional import need
from owcsim.formats.svg import TAB10, _Doc, _path_d, _power_text, _tick_text, log_ticks, nice_ticks
from owcsim.schemas.timeline import TimelineLinkPublic, TimelineResultPublic

__all__ = ["panels", "timeline_figure", "timeline_svg"]

#: Most links drawn (the rest are in the files).
MAX_LINKS = 10
#: BER drawn no lower than this (a BER of 1e-100 is zero on any axis; the files keep the value).
BER_FLOOR = 1e-12


def drawn(tl: TimelineResultPublic) -> list[TimelineLinkPublic]:
    """The links drawn: the transmitter groups' channels when the scene has groups (what a receiver of a group
    sees), else every link; at most MAX_LINKS."""
    channels = [k for k in tl.links if k.kind == "channel"]
    return (channels or tl.links)[:MAX_LINKS]


_W, _H = 820, 300
_L, _R, _T, _B = 84, 20, 34, 46


def _arr(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values or []], float)


def panels(tl: TimelineResultPublic) -> list[tuple[str, str, bool]]:
    """(field, axis label, log scale) of each panel: H0, then BER, else SNR, else received power."""
    out = [("dc_gain", "H0 [-]", True)]
    if any(k.ber for k in tl.links):
        out.append(("ber", f"BER (OOK-NRZ, floor {BER_FLOOR:g})", True))
    elif any(k.snr_db for k in tl.links):
        out.append(("snr_db", "SNR [dB]", False))
    return out


def _series(link: TimelineLinkPublic, field: str) -> tuple[np.ndarray, np.ndarray | None]:
    y = _arr(getattr(link, field))
    if field == "ber":
        y = np.maximum(y, BER_FLOOR)
    se = _arr(link.dc_gain_stderr) if field == "dc_gain" else None
    return y, se


def _threshold(tl: TimelineResultPublic, field: str) -> float | None:
    return tl.outage.threshold if tl.outage is not None and tl.outage.quantity == field else None


def _range(tl: TimelineResultPublic, links: list[TimelineLinkPublic], field: str, log: bool) -> tuple[float, float]:
    y = np.concatenate([_series(k, field)[0] for k in links])
    thr = _threshold(tl, field)
    y = np.append(y, thr) if thr is not None else y
    ok = y[np.isfinite(y) & (y > 0)] if log else y[np.isfinite(y)]
    if not ok.size:
        return (1e-30, 1.0) if log else (0.0, 1.0)
    lo, hi = float(ok.min()), float(ok.max())
    if log:
        return lo / 2, min(hi * 2, 1.0) if field == "ber" else hi * 2
    pad = max(hi - lo, 1.0) * 0.08
    return lo - pad, hi + pad


def timeline_svg(tl: TimelineResultPublic, path: str | Path) -> Path:
    """The timeline plot as SVG."""
    rows = panels(tl)
    links = drawn(tl)
    doc = _Doc(_W, _H * len(rows) + 20 * math.ceil(len(links) / 4))
    t = np.asarray(tl.times_s, float)
    tlo, thi = (float(t[0]), float(t[-1])) if len(t) > 1 and t[-1] > t[0] else (float(t[0]) - 1, float(t[0]) + 1)
    w, h = _W - _L - _R, _H - _T - _B
    for r, (field, label, log) in enumerate(rows):
        x0, y0 = _L, r * _H + _T
        lo, hi = _range(tl, links, field, log)

        def px(v, x0=x0):
            return x0 + (np.asarray(v, float) - tlo) / (thi - tlo) * w

        def py(v, y0=y0, lo=lo, hi=hi, log=log):
            v = np.asarray(v, float)
            with np.errstate(divide="ignore", invalid="ignore"):
                f = (np.log10(v) - math.log10(lo)) / (math.log10(hi) - math.log10(lo)) if log else (v - lo) / (hi - lo)
            return y0 + (1 - np.clip(f, -0.05, 1.05)) * h

        doc.add(f'<g class="panel" id="panel{r}">')
        for c, k in enumerate(links):  # outage bands first, under the curves
            for o in k.outages:
                a, b = float(px(o.start_s)), float(px(thi if o.end_s is None else o.end_s))
                style = f'fill="{TAB10[c % 10]}" fill-opacity="{0.10 if o.uncertain else 0.18}"'
                style += ' stroke="#888" stroke-dasharray="4 3"' if o.uncertain else ""
                box = f'x="{a:.1f}" y="{y0}" width="{max(b - a, 0.5):.1f}" height="{h}"'
                doc.add(f'<rect class="outage" {box} {style}/>')
        xt = nice_ticks(tlo, thi, 8)
        step = float(xt[1] - xt[0]) if len(xt) > 1 else 1.0
        for v in xt:
            x = float(px(v))
            doc.add(f'<line x1="{x:.1f}" y1="{y0}" x2="{x:.1f}" y2="{y0 + h}" stroke="#000" stroke-opacity="0.12"/>')
            doc.text(x, y0 + h + 15, _tick_text(float(v), step), 10)
        yt = log_ticks(lo, hi) if log else nice_ticks(lo, hi, 5)
        ystep = float(yt[1] - yt[0]) if len(yt) > 1 else 1.0
        for v in yt[:: max(1, len(yt) // 8)]:
            y = float(py(v))
            doc.add(f'<line x1="{x0}" y1="{y:.1f}" x2="{x0 + w}" y2="{y:.1f}" stroke="#000" stroke-opacity="0.12"/>')
            doc.markup(x0 - 6, y + 4, _power_text(float(v)) if log else _tick_text(float(v), ystep), 10, "end")
        doc.add(f'<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="black" stroke-width="0.8"/>')
        doc.text(x0 + w / 2, y0 + h + 36, "time t [s]", 11)
        doc.text(0, 0, label, 11, extra=f' transform="translate({x0 - 62},{y0 + h / 2}) rotate(-90)"')
        thr = _threshold(tl, field)
        if thr is not None:
            yt_ = float(py(thr))
            line = f'x1="{x0}" y1="{yt_:.1f}" x2="{x0 + w}" y2="{yt_:.1f}"'
            doc.add(f'<line class="threshold" {line} stroke="#d62728" stroke-dasharray="6 4"/>')
        doc.add(f'<clipPath id="tclip{r}"><rect x="{x0}" y="{y0}" width="{w}" height="{h}"/></clipPath>')
        doc.add(f'<g clip-path="url(#tclip{r})" fill="none">')
        for c, k in enumerate(links):
            values, se = _series(k, field)
            colour = TAB10[c % 10]
            if se is not None and np.isfinite(se).any():
                top, bot = py(values + np.nan_to_num(se)), py(np.maximum(values - np.nan_to_num(se), lo))
                ok = np.isfinite(top) & np.isfinite(bot)
                d = _path_d(
                    np.concatenate([px(t), px(t)[::-1]]),
                    np.concatenate([top, bot[::-1]]),
                    np.concatenate([ok, ok[::-1]]),
                )
                doc.add(f'<path class="band" d="{d}Z" fill="{colour}" fill-opacity="0.25" stroke="none"/>')
            d = _path_d(px(t), py(values), np.isfinite(py(values)))
            doc.add(f'<path class="curve" data-label="{k.tx} -> {k.rx}" d="{d}" stroke="{colour}" stroke-width="1.5"/>')
        doc.add("</g></g>")
    y_leg = _H * len(rows) + 4
    for c, k in enumerate(links):
        cx, cy = _L + (c % 4) * 180, y_leg + 14 + (c // 4) * 20
        doc.add(
            f'<line x1="{cx}" y1="{cy - 4}" x2="{cx + 20}" y2="{cy - 4}" stroke="{TAB10[c % 10]}" stroke-width="2"/>'
        )
        doc.text(cx + 25, cy, f"{k.tx} -> {k.rx}", 10, "start")
    return doc.save(path)


def timeline_figure(tl: TimelineResultPublic) -> Any:
    """The timeline plot as a matplotlib Figure."""
    need("matplotlib", "a timeline plot")
    from matplotlib.figure import Figure

    rows = panels(tl)
    fig = Figure(figsize=(8.2, 3.0 * len(rows)), layout="constrained")
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    t = np.asarray(tl.times_s, float)
    for ax, (field, label, log) in zip(axes, rows):
        for c, k in enumerate(drawn(tl)):
            colour = TAB10[c % 10]
            for o in k.outages:
                end = t[-1] if o.end_s is None else o.end_s
                ax.axvspan(
                    o.start_s,
                    end,
                    color=colour,
                    alpha=0.10 if o.uncertain else 0.18,
                    hatch="//" if o.uncertain else None,
                    lw=0,
                )
            y, se = _series(k, field)
            ax.plot(t, y, color=colour, label=f"{k.tx} -> {k.rx}")
            if se is not None and np.isfinite(se).any():
                ax.fill_between(
                    t, np.maximum(y - np.nan_to_num(se), 1e-300), y + np.nan_to_num(se), color=colour, alpha=0.25, lw=0
                )
        thr = _threshold(tl, field)
        if thr is not None:
            ax.axhline(thr, color="#d62728", ls="--", lw=1, label=f"threshold {thr:g}")
        if log:
            ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncols=2)
    axes[-1].set_xlabel("time t [s]")
    return fig
