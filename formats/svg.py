"""The command line's figures as SVG, written directly: no matplotlib (its import and drawing took
0.75 s of a 1.37 s `owcsim run`), only numpy and the standard library.

- `cir_svg`: h(t) per reflection order and total, one panel per link (the picture of plots.cir_figure);
- `heatmap_svg`: one quantity of a map in the grid's (u, v) coordinates [m] with the room, furniture,
  luminaires and masked points (the picture of heatmap.heatmap_png); the cells are one embedded PNG
  (`png_rgb`: numpy + zlib), one pixel block per point.

Text stays text (selectable, any size); every curve is one <path> with class "curve". matplotlib's
PNGs remain for `owcsim run --plot-format png` and the Python API (plots.plot_cir, heatmap.heatmap_png).
"""

from __future__ import annotations

import base64
import math
import struct
import zlib
from collections.abc import Sequence
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING
from xml.sax.saxutils import escape

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from owcsim.formats.maps import GridMap, MapDecor
    from owcsim.formats.plots import CirPanel

__all__ = ["PlotFormat", "cir_svg", "heatmap_svg", "png_rgb"]


class PlotFormat(StrEnum):
    """How the command line draws its figures: SVG written directly (fast), or PNG by matplotlib."""

    SVG = "svg"
    PNG = "png"


#: matplotlib's tab10 colours: reflection order k is drawn in colour k.
TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
#: viridis at 33 evenly spaced points (matplotlib's table; linear between them: within 3/255 of the 256 entries)
_VIRIDIS = (
    "440154470d6048186a482374472d7b4537814240863e49893b528b375b8d33638d2f6b8e2c728e297a8e26828e23898e21918c1f988b"
    "1fa08822a78528ae8032b67a3fbc734ec36b5ec96270cf5784d44b98d83eaddc30c2df23d8e219ece51bfde725"
)
MINUS = "\u2212"
FONT = "DejaVu Sans, Verdana, Arial, sans-serif"


def png_rgb(rgb: np.ndarray) -> bytes:
    """A PNG file of an (h, w, 3) uint8 image: signature, IHDR (8-bit RGB), one zlib IDAT (filter 0 per row),
    IEND; each chunk length, type, data, CRC-32 (PNG specification, ISO/IEC 15948:2004)."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w, _ = rgb.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rgb.reshape(h, 3 * w)], axis=1).tobytes()

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def viridis(t: np.ndarray) -> np.ndarray:
    """(..., 3) uint8 colours of t in [0, 1] (clipped); NaN gives white."""
    table = np.frombuffer(bytes.fromhex(_VIRIDIS), np.uint8).reshape(-1, 3).astype(float)
    x = np.linspace(0.0, 1.0, len(table))
    tc = np.clip(np.nan_to_num(t, nan=0.0), 0.0, 1.0)
    rgb = np.stack([np.interp(tc, x, table[:, c]) for c in range(3)], axis=-1)
    return np.where(np.isnan(t)[..., None], 255.0, np.round(rgb)).astype(np.uint8)


def nice_ticks(lo: float, hi: float, n: int = 6) -> np.ndarray:
    """Ticks at multiples of 1, 2, 2.5 or 5 x 10^k, at most about n of them, inside [lo, hi]."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return np.array([lo]) if math.isfinite(lo) else np.array([])
    raw = (hi - lo) / max(n, 1)
    mag = 10 ** math.floor(math.log10(raw))
    step = next(s * mag for s in (1, 2, 2.5, 5, 10) if s * mag >= raw)
    ticks = np.arange(math.ceil(lo / step - 1e-9), math.floor(hi / step + 1e-9) + 1) * step
    return np.where(np.abs(ticks) < step * 1e-9, 0.0, ticks)


def log_ticks(lo: float, hi: float) -> np.ndarray:
    """Decades 10^k inside [lo, hi] (lo > 0), with 2 and 5 x 10^k added when fewer than two decades fall in."""
    k = np.arange(math.ceil(math.log10(lo) - 1e-9), math.floor(math.log10(hi) + 1e-9) + 1)
    ticks = 10.0**k
    if len(ticks) < 2:
        k = np.arange(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1)
        ticks = np.sort(np.concatenate([10.0**k, 2 * 10.0**k, 5 * 10.0**k]))
        ticks = ticks[(ticks >= lo * (1 - 1e-9)) & (ticks <= hi * (1 + 1e-9))]
    return ticks


def _tick_text(v: float, step: float) -> str:
    """A tick label with the decimals its step needs (2.5 -> one, 0.2 -> one, 50 -> none)."""
    digits = max(0, -math.floor(math.log10(step) + 1e-9)) if step > 0 else 3
    while digits < 6 and abs(step * 10**digits - round(step * 10**digits)) > 1e-6:
        digits += 1
    return f"{v:.{digits}f}" if abs(v) < 1e5 else f"{v:.3g}"


def _power_text(v: float) -> str:
    """10^k as SVG text (a superscript tspan), other values as m x 10^k."""
    k = math.floor(math.log10(v) + 1e-9)
    m = v / 10**k
    head = "" if abs(m - 1) < 1e-6 else f"{m:g}\u00d7"
    exponent = str(k).replace("-", MINUS)
    return f'{head}10<tspan dy="-5" font-size="8">{exponent}</tspan>'


class _Doc:
    """An SVG document: elements appended as text, written once."""

    def __init__(self, width: float, height: float):
        self.width, self.height = width, height
        self.parts: list[str] = []

    def add(self, s: str) -> None:
        self.parts.append(s)

    def text(self, x: float, y: float, s: str, size: float = 11, anchor: str = "middle", extra: str = "") -> None:
        """Text `s` (escaped) at (x, y) [px], baseline at y."""
        self.add(f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size:g}" text-anchor="{anchor}"{extra}>{escape(s)}</text>')

    def label(self, x: float, y: float, s: str, size: float = 10, anchor: str = "middle") -> None:
        """Text over a white halo (a white-stroked copy below it: readable on any colour)."""
        self.text(x, y, s, size, anchor, ' stroke="white" stroke-width="3" stroke-linejoin="round"')
        self.text(x, y, s, size, anchor)

    def markup(self, x: float, y: float, s: str, size: float = 11, anchor: str = "middle") -> None:
        """Text with markup already in it (tspans)."""
        self.add(f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size:g}" text-anchor="{anchor}">{s}</text>')

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        head = (
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{self.width:.0f}" height="{self.height:.0f}" '
            f'viewBox="0 0 {self.width:.0f} {self.height:.0f}" font-family="{FONT}">'
            f'<rect width="100%" height="100%" fill="white"/>'
        )
        path.write_text("\n".join([head, *self.parts, "</svg>"]) + "\n", encoding="utf-8")
        return path


def _path_d(x: np.ndarray, y: np.ndarray, ok: np.ndarray) -> str:
    """SVG path data through the points (x, y) [px] where `ok`, a new subpath after every gap."""
    idx = np.flatnonzero(ok)
    if not idx.size:
        return ""
    starts = np.ones(idx.size, bool)
    starts[1:] = np.diff(idx) > 1
    cmd = np.where(starts, "M", "L")
    xy = np.round(np.stack([x[idx], y[idx]], axis=1), 1)
    return ("%s%.1f %.1f" * idx.size) % tuple(v for row in zip(cmd, xy[:, 0], xy[:, 1]) for v in row)


# --- the CIR --------------------------------------------------------------------------------------
PANEL_W, PANEL_H = 800, 320
_LEFT, _RIGHT, _TOP, _BOTTOM = 84, 16, 30, 46


def cir_svg(t_min_s: float, time_bin_s: float, n_bins: int, panels: Sequence[CirPanel], path: str | Path) -> Path:
    """h(t) = power per bin / dt [1/s] against the delay [ns], log scale, per reflection order k (colour k) and
    total (black), one panel per link (at most plots.MAX_PANELS); a single empty panel when there is no link."""
    from owcsim.formats.plots import MAX_ORDER, MAX_PANELS

    rows: list[CirPanel | None] = list(panels[:MAX_PANELS]) or [None]
    doc = _Doc(PANEL_W, PANEL_H * len(rows))
    t_ns = 1e9 * (t_min_s + time_bin_s * (np.arange(n_bins) + 0.5))
    for i, p in enumerate(rows):
        _cir_panel(doc, i, p, t_ns, time_bin_s, MAX_ORDER)
    return doc.save(path)


def _cir_panel(doc: _Doc, i: int, p: CirPanel | None, t_ns: np.ndarray, dt: float, max_order: int) -> None:
    x0, y0 = _LEFT, i * PANEL_H + _TOP
    w, h = PANEL_W - _LEFT - _RIGHT, PANEL_H - _TOP - _BOTTOM
    doc.add(f'<g class="panel" id="panel{i}">')
    total = None if p is None else np.asarray(p.total, float) / dt
    nz = np.array([], int) if total is None else np.flatnonzero(total > 0)
    if len(nz):
        xlo, xhi = t_ns[nz[0]] - 2, t_ns[min(nz[-1] + 1, len(t_ns) - 1)]
        assert total is not None
        ylo, yhi = max(total[nz].min(), total[nz].max() * 1e-6) * 0.5, total[nz].max() * 2
    else:
        xlo, xhi = (t_ns[0], t_ns[-1]) if len(t_ns) else (0.0, 1.0)
        ylo, yhi = 1.0, 10.0
    if xhi <= xlo:
        xhi = xlo + 1.0
    lyl, lyh = math.log10(ylo), math.log10(yhi)

    def px(t: np.ndarray) -> np.ndarray:
        return x0 + (t - xlo) / (xhi - xlo) * w

    def py(v: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return y0 + (lyh - np.log10(v)) / (lyh - lyl) * h

    # grid, ticks and labels
    xt = nice_ticks(xlo, xhi, 8)
    step = float(xt[1] - xt[0]) if len(xt) > 1 else 1.0
    for t in xt:
        tx = float(px(np.array(t)))
        doc.add(f'<line x1="{tx:.1f}" y1="{y0}" x2="{tx:.1f}" y2="{y0 + h}" stroke="#000" stroke-opacity="0.12"/>')
        doc.text(tx, y0 + h + 15, _tick_text(float(t), step), 10)
    for v in log_ticks(ylo, yhi) if len(nz) else []:
        ty = float(py(np.array(v)))
        doc.add(f'<line x1="{x0}" y1="{ty:.1f}" x2="{x0 + w}" y2="{ty:.1f}" stroke="#000" stroke-opacity="0.12"/>')
        doc.markup(x0 - 6, ty + 4, _power_text(float(v)), 10, "end")
    doc.add(f'<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="black" stroke-width="0.8"/>')
    doc.text(x0 + w / 2, y0 + h + 36, "delay t [ns]", 11)
    doc.text(0, 0, "h(t) [1/s]", 11, extra=f' transform="translate({x0 - 62},{y0 + h / 2}) rotate(-90)"')
    if p is None or total is None:
        doc.text(x0 + w / 2, y0 - 10, "no links", 12)
        doc.add("</g>")
        return
    gain = "n/a" if p.dc_gain is None else f"{p.dc_gain:.4e}"
    title = f"{p.transmitter} -> {p.receiver}: H0 = {gain}" + (f" ± {p.dc_gain_stderr:.1e}" if p.dc_gain_stderr else "")
    doc.text(x0 + w / 2, y0 - 10, title, 12)
    # curves, clipped to the axes
    doc.add(f'<clipPath id="clip{i}"><rect x="{x0}" y="{y0}" width="{w}" height="{h}"/></clipPath>')
    doc.add(f'<g clip-path="url(#clip{i})" fill="none" stroke-linejoin="round">')
    curves: list[tuple[str, str]] = []
    X = px(t_ns)
    floor = ylo * 1e-3  # zeros drawn below the axes, as matplotlib clips them on a log scale
    for k, row in enumerate(np.asarray(p.by_reflection_order)[: max_order + 1]):
        hk = np.asarray(row, float) / dt
        if hk.any():
            colour = TAB10[k % len(TAB10)]
            d = _path_d(X, py(np.maximum(hk, floor)), np.ones(hk.size, bool))
            doc.add(f'<path class="curve" data-label="k = {k}" d="{d}" stroke="{colour}" stroke-width="1.1"/>')
            curves.append((f"k = {k}", colour))
    d = _path_d(X, py(np.maximum(total, floor)), np.ones(total.size, bool))
    doc.add(f'<path class="curve" data-label="total" d="{d}" stroke="black" stroke-width="1.5"/>')
    curves.append(("total", "black"))
    doc.add("</g>")
    # legend: three columns at the top right
    cols = 3
    lw = 78
    n_rows = math.ceil(len(curves) / cols)
    lx, ly = x0 + w - cols * lw - 6, y0 + 6
    doc.add(
        f'<rect x="{lx - 4}" y="{ly}" width="{cols * lw + 6}" height="{n_rows * 15 + 6}" fill="white" '
        'fill-opacity="0.85" stroke="#ccc"/>'
    )
    for j, (label, colour) in enumerate(curves):
        cx, cy = lx + (j % cols) * lw, ly + 13 + (j // cols) * 15
        doc.add(f'<line x1="{cx}" y1="{cy - 4}" x2="{cx + 20}" y2="{cy - 4}" stroke="{colour}" stroke-width="1.5"/>')
        doc.text(cx + 25, cy, label, 10, "start")
    doc.add("</g>")


# --- map heatmaps ---------------------------------------------------------------------------------
_PLOT = 440.0  # the longer side of the map's axes [px]
_M_LEFT, _M_TOP, _M_BOTTOM = 70.0, 58.0, 50.0


def heatmap_svg(
    m: GridMap, quantity: str, decor: MapDecor | None, path: str | Path, *, log: bool | None = None
) -> Path:
    """Draw one quantity of a map as SVG in the grid's own (u, v) coordinates [m]; returns the path.

    As heatmap.heatmap_png: masked points grey and hatched (with a legend of the reasons), points without a
    value white, furniture whose projection overlaps the grid outlined and named, the room's projection
    dashed, luminaires as stars with their ids; `log`: colour scale (None: log for a gain or a power in W
    whose positive values span more than two decades). Colour map viridis.
    """
    from owcsim.formats.heatmap import _Frame, _overlaps, _project, _title
    from owcsim.formats.maps import box_corners, convex_hull, display_unit, masked_points, summary

    a = m.quantity(quantity)
    unit = m.units[quantity]
    shown = np.where(m.masked, np.nan, a)
    factor, shown_unit = display_unit(unit, shown)
    shown = shown * factor
    s = summary(m)[quantity]
    frame = _Frame.of(m, decor)
    lim = frame.lim
    scale = _PLOT / max(frame.width, frame.height)
    pw, ph = frame.width * scale, frame.height * scale
    reasons = masked_points(m) if m.masked.any() else {}
    width = _M_LEFT + pw + 140
    height = _M_TOP + ph + _M_BOTTOM + 16 * len(reasons)
    doc = _Doc(width, height)
    doc.add(
        '<defs><pattern id="hatch" width="6" height="6" patternUnits="userSpaceOnUse">'
        '<path d="M0 6L6 0M-1.5 1.5L1.5 -1.5M4.5 7.5L7.5 4.5" stroke="#737373" stroke-width="0.8"/></pattern></defs>'
    )

    def X(u: np.ndarray | float) -> np.ndarray:
        return _M_LEFT + (np.asarray(u, float) - lim[0]) * scale

    def Y(v: np.ndarray | float) -> np.ndarray:
        return _M_TOP + (lim[3] - np.asarray(v, float)) * scale

    # colours of the cells: one embedded PNG, a block of pixels per point (row 0 at the largest v)
    positive = shown[np.isfinite(shown) & (shown > 0)]
    if log is None:
        log = unit in ("1", "W") and positive.size > 0 and positive.max() > 100 * positive.min()
    log = bool(log and positive.size)
    finite = shown[np.isfinite(shown)]
    if log:
        lo, hi = float(positive.min()), float(positive.max())
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(shown > 0, np.log10(shown / lo) / max(math.log10(hi / lo), 1e-300), np.nan)
    else:
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if hi <= lo:
            pad = abs(lo) * 1e-3 or 1e-12
            lo, hi = lo - pad, hi + pad
        t = (shown - lo) / (hi - lo)
    rgb = viridis(t)
    rgb[m.masked] = 191  # matplotlib's "0.75" grey
    img = rgb.transpose(1, 0, 2)[::-1]  # (nv, nu, 3), top row = largest v
    rep = max(1, math.ceil(200 / max(img.shape[:2])))
    img = np.repeat(np.repeat(img, rep, axis=0), rep, axis=1)
    xe, ye = frame.xe, frame.ye
    png = base64.b64encode(png_rgb(img)).decode()
    doc.add(
        f'<image class="cells" x="{X(xe[0]):.2f}" y="{Y(ye[-1]):.2f}" width="{(xe[-1] - xe[0]) * scale:.2f}" '
        f'height="{(ye[-1] - ye[0]) * scale:.2f}" preserveAspectRatio="none" image-rendering="pixelated" '
        f'style="image-rendering:pixelated" href="data:image/png;base64,{png}"/>'
    )
    if m.masked.any():  # the hatch over the masked cells: one path of rectangles
        i, j = np.nonzero(m.masked)
        rect = np.stack([X(xe[i]), Y(ye[j + 1]), (xe[i + 1] - xe[i]) * scale, (ye[j + 1] - ye[j]) * scale], axis=1)
        d = ("M%.2f %.2fh%.2fv%.2fh-%.2fz" * len(i)) % tuple(v for r in rect for v in (r[0], r[1], r[2], r[3], r[2]))
        doc.add(f'<path class="masked" d="{d}" fill="url(#hatch)" stroke="none"/>')
    clip = f'<clipPath id="axes"><rect x="{_M_LEFT}" y="{_M_TOP}" width="{pw:.2f}" height="{ph:.2f}"/></clipPath>'
    doc.add(clip + '<g clip-path="url(#axes)">')
    if frame.room is not None:
        doc.add(
            f'<polygon class="room" points="{_points(X(frame.room[:, 0]), Y(frame.room[:, 1]))}" fill="none" '
            'stroke="#4d4d4d" stroke-dasharray="5 3"/>'
        )
    if decor is not None:
        for name, box_lo, box_hi in decor.furniture:
            poly = convex_hull(_project(m, box_corners(box_lo, box_hi)))
            if len(poly) and _overlaps(poly, frame.grid_box):
                tag = "polygon" if len(poly) > 2 else "polyline"
                doc.add(
                    f'<{tag} class="furniture" points="{_points(X(poly[:, 0]), Y(poly[:, 1]))}" fill="none" '
                    'stroke="black" stroke-width="1.4"/>'
                )
                cx = (max(poly[:, 0].min(), lim[0]) + min(poly[:, 0].max(), lim[1])) / 2
                cy = (max(poly[:, 1].min(), lim[2]) + min(poly[:, 1].max(), lim[3])) / 2
                doc.label(float(X(cx)), float(Y(cy)) + 4, name)
        if decor.luminaires:
            lp = _project(m, np.array([p for _, p in decor.luminaires]))
            star = _star()
            for (lid, _), (u, v) in zip(decor.luminaires, lp):
                if lim[0] <= u <= lim[1] and lim[2] <= v <= lim[3]:
                    sx, sy = float(X(u)), float(Y(v))
                    doc.add(
                        f'<polygon class="luminaire" points="{_points(sx + star[:, 0], sy + star[:, 1])}" '
                        'fill="white" stroke="black"/>'
                    )
                    doc.label(sx + 9, sy - 7, lid, anchor="start")
    doc.add("</g>")
    doc.add(
        f'<rect x="{_M_LEFT}" y="{_M_TOP}" width="{pw:.2f}" height="{ph:.2f}" fill="none" stroke="black" '
        'stroke-width="0.8"/>'
    )
    _map_axes(doc, m, frame, X, Y, pw, ph)
    title = _title(m, quantity, s, factor, shown_unit).split("\n")
    for k, line in enumerate(title):
        doc.text(_M_LEFT + pw / 2, 20 + 15 * k, line, 12)
    if s["count"]:
        _colour_bar(doc, _M_LEFT + pw + 18, ph, lo, hi, log, f"{quantity} [{shown_unit}]" + (" (log scale)" * log))
    for k, (reason, ij) in enumerate(reasons.items()):
        y = _M_TOP + ph + 44 + 16 * k
        doc.add(f'<rect x="{_M_LEFT}" y="{y - 10}" width="18" height="11" fill="#bfbfbf" stroke="#737373"/>')
        doc.add(f'<rect x="{_M_LEFT}" y="{y - 10}" width="18" height="11" fill="url(#hatch)"/>')
        doc.text(_M_LEFT + 24, y, f"masked: {reason} ({len(ij)})", 10, "start")
    return doc.save(path)


def _points(x: np.ndarray, y: np.ndarray) -> str:
    return " ".join(f"{a:.2f},{b:.2f}" for a, b in zip(np.atleast_1d(x), np.atleast_1d(y)))


def _star(r: float = 8.0) -> np.ndarray:
    """(10, 2) corners of a five-pointed star of outer radius r [px], point up."""
    k = np.arange(10)
    radius = np.where(k % 2 == 0, r, r * 0.42)
    angle = -np.pi / 2 + k * np.pi / 5
    return np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)


def _map_axes(doc: _Doc, m: GridMap, frame, X, Y, pw: float, ph: float) -> None:
    """Ticks in metres along u and v and the axes' labels."""
    from owcsim.formats.heatmap import _vec_text

    lim = frame.lim
    longest = max(frame.width, frame.height)
    for axis, lo, hi, extent in (("u", lim[0], lim[1], frame.width), ("v", lim[2], lim[3], frame.height)):
        ticks = nice_ticks(lo, hi, max(2, min(7, round(7 * extent / longest))))
        step = float(ticks[1] - ticks[0]) if len(ticks) > 1 else 1.0
        for t in ticks:
            if axis == "u":
                x = float(X(t))
                doc.add(f'<line x1="{x:.1f}" y1="{_M_TOP + ph}" x2="{x:.1f}" y2="{_M_TOP + ph + 4}" stroke="black"/>')
                doc.text(x, _M_TOP + ph + 16, _tick_text(float(t), step), 10)
            else:
                y = float(Y(t))
                doc.add(f'<line x1="{_M_LEFT - 4}" y1="{y:.1f}" x2="{_M_LEFT}" y2="{y:.1f}" stroke="black"/>')
                doc.text(_M_LEFT - 7, y + 4, _tick_text(float(t), step), 10, "end")
    doc.text(_M_LEFT + pw / 2, _M_TOP + ph + 33, f"u [m]     (u = {_vec_text(m.u)}, v = {_vec_text(m.v)})", 11)
    doc.text(0, 0, "v [m]", 11, extra=f' transform="translate({_M_LEFT - 46},{_M_TOP + ph / 2}) rotate(-90)"')


def _colour_bar(doc: _Doc, x: float, ph: float, lo: float, hi: float, log: bool, label: str) -> None:
    """A vertical viridis bar from lo (bottom) to hi (top) with its ticks and label."""
    ramp = np.repeat(viridis(np.linspace(1.0, 0.0, 256))[:, None, :], 4, axis=1)  # top row = hi
    png = base64.b64encode(png_rgb(ramp)).decode()
    w = 16
    doc.add(
        f'<image class="colour-bar" x="{x:.2f}" y="{_M_TOP}" width="{w}" height="{ph:.2f}" preserveAspectRatio="none" '
        f'image-rendering="pixelated" style="image-rendering:pixelated" href="data:image/png;base64,{png}"/>'
    )
    doc.add(
        f'<rect x="{x:.2f}" y="{_M_TOP}" width="{w}" height="{ph:.2f}" fill="none" stroke="black" stroke-width="0.8"/>'
    )
    if log:
        ticks = log_ticks(lo, hi)
        frac = np.log10(ticks / lo) / max(math.log10(hi / lo), 1e-300)
        labels = [_power_text(float(v)) for v in ticks]
    else:
        ticks = nice_ticks(lo, hi, 6)
        frac = (ticks - lo) / (hi - lo)
        step = float(ticks[1] - ticks[0]) if len(ticks) > 1 else 1.0
        top = float(np.abs(ticks).max()) if len(ticks) else 1.0
        shift = math.floor(math.log10(top)) if top > 0 and not 1e-2 <= top < 1e5 else 0
        labels = [escape(_tick_text(float(v) / 10**shift, step / 10**shift)) for v in ticks]
        if shift:  # a common factor above the bar, as matplotlib's offset text
            doc.markup(x, _M_TOP - 6, _power_text(10.0**shift).replace("10<", "\u00d710<", 1), 10, "start")
    for f, text in zip(frac, labels):
        y = _M_TOP + (1 - f) * ph
        doc.add(f'<line x1="{x + w:.1f}" y1="{y:.1f}" x2="{x + w + 4:.1f}" y2="{y:.1f}" stroke="black"/>')
        doc.markup(x + w + 7, y + 4, text, 10, "start")
    doc.text(0, 0, label, 11, extra=f' transform="translate({x + w + 52:.1f},{_M_TOP + ph / 2:.1f}) rotate(90)"')
