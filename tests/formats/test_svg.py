"""The command line's figures written without matplotlib (formats/svg.py): valid files that show the data.

The PNG encoder is checked byte by byte (signature, IHDR, CRCs, the pixels back through zlib); the SVGs are
parsed as XML and their content compared with the inputs: one curve per drawn reflection order plus the
total, the axis labels, the title; a heatmap's cell colours against the colour map of the values, cell by
cell, with the orientation (u to the right, v up) and the masked cells.
"""

import base64
import math
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET
import zlib

import numpy as np
import pytest

from owcsim.formats.maps import GridMap, MapDecor
from owcsim.formats.plots import CirPanel
from owcsim.formats.svg import cir_svg, heatmap_svg, log_ticks, nice_ticks, png_rgb, viridis

NS = "{http://www.w3.org/2000/svg}"


def _png_pixels(data: bytes) -> np.ndarray:
    """Decode our 8-bit RGB PNG (one IDAT, filter 0) back to (h, w, 3), checking every chunk's CRC."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks = 8, {}
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        (crc,) = struct.unpack(">I", data[pos + 8 + n : pos + 12 + n])
        assert crc == zlib.crc32(kind + body) & 0xFFFFFFFF, kind
        chunks[kind] = body
        pos += 12 + n
    assert list(chunks) == [b"IHDR", b"IDAT", b"IEND"]
    w, h, depth, colour, _, _, _ = struct.unpack(">IIBBBBB", chunks[b"IHDR"])
    assert (depth, colour) == (8, 2)
    raw = np.frombuffer(zlib.decompress(chunks[b"IDAT"]), np.uint8).reshape(h, 1 + 3 * w)
    assert np.all(raw[:, 0] == 0)
    return raw[:, 1:].reshape(h, w, 3)


def test_png_round_trip():
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (7, 5, 3), dtype=np.uint8)
    data = png_rgb(img)
    assert struct.unpack(">II", data[16:24]) == (5, 7)  # IHDR: width, height
    np.testing.assert_array_equal(_png_pixels(data), img)


def test_ticks():
    np.testing.assert_allclose(nice_ticks(0.0, 10.0, 5), [0, 2, 4, 6, 8, 10])
    np.testing.assert_allclose(nice_ticks(12.3, 70.1, 8), [20, 30, 40, 50, 60, 70])
    np.testing.assert_allclose(log_ticks(3e-3, 2e4), 10.0 ** np.arange(-2, 5))
    np.testing.assert_allclose(log_ticks(1.5, 8), [2, 5])  # fewer than two decades: 2 and 5 added


def _panel(orders: int, nonzero: tuple[int, ...], n_bins: int = 50) -> CirPanel:
    t = np.arange(n_bins)
    rows = np.zeros((orders, n_bins))
    for k in nonzero:
        rows[k] = np.exp(-((t - 10 - 5 * k) ** 2) / 20.0) * 10.0**-k
    return CirPanel("tx", f"rx{orders}", 1.234e-6, 5e-9, rows.sum(axis=0), rows)


def _svg(path) -> ET.Element:
    return ET.parse(path).getroot()  # a parse error fails the test


def _texts(root) -> list[str]:
    return ["".join(t.itertext()) for t in root.iter(f"{NS}text")]


def test_cir_svg_draws_each_order_and_the_total(tmp_path):
    panels = [_panel(4, (0, 1, 3)), _panel(3, (1, 2))]
    root = _svg(cir_svg(0.0, 1e-10, 50, panels, tmp_path / "cir.svg"))
    groups = [g for g in root.iter(f"{NS}g") if g.get("class") == "panel"]
    assert len(groups) == 2
    for g, labels in zip(groups, (["k = 0", "k = 1", "k = 3", "total"], ["k = 1", "k = 2", "total"])):
        curves = [p for p in g.iter(f"{NS}path") if p.get("class") == "curve"]
        assert [c.get("data-label") for c in curves] == labels
        assert all(c.get("d").count("L") == 49 for c in curves)  # one vertex per bin
    texts = _texts(root)
    assert texts.count("delay t [ns]") == 2 and texts.count("h(t) [1/s]") == 2
    assert "tx -> rx4: H0 = 1.2340e-06 ± 5.0e-09" in texts


def test_cir_svg_vertices_follow_the_log_scale(tmp_path):
    """The total's vertices: x linear in the delay, y linear in log10 h (two bins compared in pixels)."""
    p = _panel(1, (0,))
    root = _svg(cir_svg(0.0, 1e-9, 50, [p], tmp_path / "c.svg"))
    total = next(c for c in root.iter(f"{NS}path") if c.get("data-label") == "total")
    xy = np.array([[float(a) for a in s.split()] for s in total.get("d")[1:].split("L")])
    h = p.total / 1e-9
    i, j = 10, 13  # the peak and a bin 3 steps later
    ratio = (xy[j, 1] - xy[i, 1]) / (xy[j, 0] - xy[i, 0])
    k = 16
    ratio2 = (xy[k, 1] - xy[i, 1]) / (xy[k, 0] - xy[i, 0])
    expected = (math.log10(h[j]) - math.log10(h[i])) / 3 / ((math.log10(h[k]) - math.log10(h[i])) / 6)
    assert ratio / ratio2 == pytest.approx(expected, rel=1e-2)


def test_cir_svg_without_links(tmp_path):
    root = _svg(cir_svg(0.0, 1e-9, 10, [], tmp_path / "c.svg"))
    assert "no links" in _texts(root)
    assert not [p for p in root.iter(f"{NS}path") if p.get("class") == "curve"]


def _map(nu=6, nv=4, mask=()):
    x, y = 0.5 * np.arange(nu), 0.5 * np.arange(nv)
    e = 100.0 + 10 * x[:, None] + y[None, :]  # grows along u, and along v
    reason = np.full((nu, nv), "", dtype=object)
    for i, j in mask:
        reason[i, j] = "inside furniture 'desk'"
    return GridMap(
        grid="wp",
        channel="tx0",
        origin=np.array([1.0, 0.5, 0.85]),
        u=np.array([1.0, 0, 0]),
        v=np.array([0, 1.0, 0]),
        x=x,
        y=y,
        values={"illuminance": e},
        stderr={},
        units={"illuminance": "lx"},
        mask_reason=reason,
    )


def test_heatmap_svg_cells_are_the_values_colours(tmp_path):
    m = _map(mask=[(2, 1)])
    decor = MapDecor(
        room=((0, 0, 0), (5, 5, 3)),
        furniture=[("desk", (1.2, 0.4, 0.0), (2.0, 1.2, 0.75))],
        luminaires=[("led0", (2.0, 1.0, 2.85))],
    )
    root = _svg(heatmap_svg(m, "illuminance", decor, tmp_path / "h.svg"))
    cells = next(i for i in root.iter(f"{NS}image") if i.get("class") == "cells")
    img = _png_pixels(base64.b64decode(cells.get("href").split(",", 1)[1]))
    rep = img.shape[0] // 4
    assert img.shape == (4 * rep, 6 * rep, 3)
    got = img[::rep, ::rep][::-1].transpose(1, 0, 2)  # back to (i, j), j up
    v = m.values["illuminance"]
    want = viridis((v - v[~m.masked].min()) / (v[~m.masked].max() - v[~m.masked].min()))
    want[2, 1] = 191  # masked: grey
    np.testing.assert_array_equal(got, want)
    assert not np.array_equal(got, want[::-1])  # orientation matters (power)
    masked = [p for p in root.iter(f"{NS}path") if p.get("class") == "masked"]
    assert len(masked) == 1 and masked[0].get("d").count("M") == 1
    texts = _texts(root)
    for label in ("desk", "led0", "v [m]", "illuminance [lx]", "masked: inside furniture 'desk' (1)"):
        assert label in texts, (label, texts)
    assert any(t.startswith("u [m]") for t in texts) and any(t.startswith("wp: illuminance from tx0") for t in texts)


@pytest.mark.parametrize("case", ["log", "one_point", "one_row", "all_masked"])
def test_heatmap_svg_edge_cases_are_valid(tmp_path, case):
    m, log = _map(), None
    if case == "log":
        m.values["illuminance"] = 10.0 ** np.linspace(-3, 3, 24).reshape(6, 4)
        log = True
    elif case == "one_point":
        m = _map(1, 1)
    elif case == "one_row":
        m = _map(7, 1)
    elif case == "all_masked":
        m = _map(3, 2, mask=[(i, j) for i in range(3) for j in range(2)])
    root = _svg(heatmap_svg(m, "illuminance", None, tmp_path / "h.svg", log=log))
    bars = [i for i in root.iter(f"{NS}image") if i.get("class") == "colour-bar"]
    assert len(bars) == (0 if case == "all_masked" else 1)
    if case == "log":
        assert "illuminance [lx] (log scale)" in _texts(root)


def test_svg_module_imports_no_matplotlib():
    code = "import sys, owcsim.formats.svg, owcsim.formats.result_files; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
