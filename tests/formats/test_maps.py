"""Coverage-map output (formats/maps.py, map_files.py, heatmap.py): summary, netCDF / .mat round trips, heatmaps.

References are computed here independently: positions and the 1/d^2 field point by point in plain
Python from the grid's definition (origin + i s u + j s v), and closed forms for the extremes.
"""

import math
import subprocess
import sys

import numpy as np
import pytest

from owcsim.formats.heatmap import _project, heatmap_png
from owcsim.formats.map_files import from_xarray, to_dataframe, to_netcdf, to_xarray, write_map_files
from owcsim.formats.maps import GridMap, MapDecor, convex_hull, format_summary, masked_points, summary
from tests.scenes import room_doc, spec

S = 0.5  # grid spacing [m]
H = 2.0  # source height above the grid plane [m]
PNG = b"\x89PNG\r\n\x1a\n"


def _field(
    nu=5,
    nv=4,
    origin=(1.0, 0.5, 0.85),
    u=(1.0, 0.0, 0.0),
    v=(0.0, 1.0, 0.0),
    channel="tx0",
    grid="wp",
    mask=(),
    source=None,
):
    """E = 1/d^2 from a point H above the grid point (0, 0); masked points carry a (wrong) huge value."""
    origin, u, v = np.array(origin), np.array(u), np.array(v)
    src = origin + H * np.cross(u, v) if source is None else np.asarray(source)
    pos = origin + (S * np.arange(nu))[:, None, None] * u + (S * np.arange(nv))[None, :, None] * v
    e = 1.0 / ((pos - src) ** 2).sum(-1)
    reason = np.full((nu, nv), "", dtype=object)
    for i, j in mask:
        reason[i, j] = "inside furniture 'desk'"
        e[i, j] = 1e6  # a masked point must be left out whatever it holds
    return GridMap(
        grid=grid,
        channel=channel,
        origin=origin,
        u=u,
        v=v,
        x=S * np.arange(nu),
        y=S * np.arange(nv),
        values={"illuminance": e, "dc_gain": e * 1e-6, "received_power_dbm": 10 * np.log10(e)},
        stderr={"illuminance": 0.01 * e},
        units={"illuminance": "lx", "dc_gain": "1", "received_power_dbm": "dBm"},
        mask_reason=reason,
    )


def _direct(nu, nv, skip=()):
    """The field point by point, plain Python: {(i, j): 1/d^2}, source H above point (0, 0) of an x-y grid."""
    out = {}
    for i in range(nu):
        for j in range(nv):
            if (i, j) not in skip:
                out[(i, j)] = 1.0 / ((i * S) ** 2 + (j * S) ** 2 + H**2)
    return out


def test_positions_follow_the_grid_definition():
    m = _field(u=(0.0, 0.6, 0.8), v=(1.0, 0.0, 0.0))
    for i, j in [(0, 0), (4, 3), (2, 1)]:
        want = [o + S * (i * a + j * b) for o, a, b in zip(m.origin, m.u, m.v)]
        assert np.allclose(m.positions[i, j], want)


def test_summary_against_direct_computation():
    mask = [(4, 3), (2, 2)]
    m = _field(mask=mask)
    ref = _direct(5, 4, skip=mask)
    s = summary(m)["illuminance"]
    mean = sum(ref.values()) / len(ref)
    # closed forms: brightest point under the source, darkest at the farthest unmasked corner (4, 2) or (3, 3)
    e_max = 1 / H**2
    e_min = min(1 / ((4 * S) ** 2 + (2 * S) ** 2 + H**2), 1 / ((3 * S) ** 2 + (3 * S) ** 2 + H**2))
    assert s["count"] == 18 and s["masked"] == 2 and s["missing"] == 0
    assert math.isclose(s["max"], e_max, rel_tol=1e-12) and s["max_index"] == (0, 0)
    assert math.isclose(s["min"], e_min, rel_tol=1e-12) and s["min_index"] == (4, 2)
    assert math.isclose(s["mean"], mean, rel_tol=1e-12)
    assert math.isclose(s["uniformity"], e_min / mean, rel_tol=1e-12)
    assert math.isclose(s["max_rel_stderr"], 0.01, rel_tol=1e-9)
    # with the masked corner (4, 3) counted the minimum would be lower: the mask does matter here
    assert 1 / ((4 * S) ** 2 + (3 * S) ** 2 + H**2) < e_min * 0.99
    # a ratio of decibels is no uniformity
    assert summary(m)["received_power_dbm"]["uniformity"] is None
    assert summary(m)["dc_gain"]["uniformity"] == pytest.approx(e_min / mean, rel=1e-12)


def test_masked_points_reported_and_missing_values_counted():
    m = _field(mask=[(1, 1), (3, 0)])
    assert {r: ij.tolist() for r, ij in masked_points(m).items()} == {"inside furniture 'desk'": [[1, 1], [3, 0]]}
    e = m.values["illuminance"].copy()
    e[0, 3] = np.nan  # not available (e.g. an unreachable link), not masked
    m2 = GridMap(
        m.grid, m.channel, m.origin, m.u, m.v, m.x, m.y, {"illuminance": e}, {}, {"illuminance": "lx"}, m.mask_reason
    )
    s = summary(m2)["illuminance"]
    assert (s["count"], s["masked"], s["missing"]) == (17, 2, 1)
    text = format_summary([m2])
    assert "2 masked points: 2 inside furniture 'desk'" in text and "17 (1 n/a)" in text


def test_all_masked_gives_no_figures():
    m = _field(nu=1, nv=2, mask=[(0, 0), (0, 1)])
    s = summary(m)["illuminance"]
    assert s["count"] == 0 and s["min"] is None and s["uniformity"] is None
    assert "-" in format_summary(m)


def test_format_summary_scales_units():
    m = _field()
    e = m.values["illuminance"]
    m = GridMap(
        "wp",
        "leds",
        m.origin,
        m.u,
        m.v,
        m.x,
        m.y,
        {
            "received_power": e * 1e-3,
            "rms_delay_spread": e * 1e-9,
            "dc_gain": e * 1e-6,
            "path_loss_db": -10 * np.log10(e * 1e-6),
            "illuminance": e * 1000,
        },
        {},
        {"received_power": "W", "rms_delay_spread": "s", "dc_gain": "1", "path_loss_db": "dB", "illuminance": "lx"},
    )
    lines = {ln.split()[1]: ln for ln in format_summary(m).splitlines()[2:]}
    assert "µW" in lines["received_power"] and f"{1e-3 / H**2 * 1e6:.4g}" in lines["received_power"]
    assert " ns " in lines["rms_delay_spread"] and f"{1e-9 / H**2 * 1e9:.4g}" in lines["rms_delay_spread"]
    assert f"{1e-6 / H**2:.3e}" in lines["dc_gain"]
    assert f"{-10 * math.log10(1e-6 / H**2):.2f}" in lines["path_loss_db"] and " dB " in lines["path_loss_db"]
    assert f" {1000 / H**2:.4g} " in lines["illuminance"]


def test_validation_errors_are_clear():
    m = _field()
    kw = dict(grid="g", channel="c", origin=m.origin, u=m.u, v=m.v, x=m.x, y=m.y, stderr={}, units={"a": "lx"})
    with pytest.raises(ValueError, match=r"values\['a'\] has shape \(4, 5\), the grid \(5, 4\)"):
        GridMap(values={"a": np.zeros((4, 5))}, **kw)
    with pytest.raises(ValueError, match="no unit for \\['b'\\]"):
        GridMap(values={"a": np.zeros((5, 4)), "b": np.zeros((5, 4))}, **kw)
    with pytest.raises(ValueError, match="not a usable quantity name"):
        GridMap(values={"a b": np.zeros((5, 4))}, **{**kw, "units": {"a b": "1"}})
    with pytest.raises(ValueError, match="orthogonal unit vectors"):
        GridMap(values={"a": np.zeros((5, 4))}, **{**kw, "v": (1.0, 0.0, 0.0)})
    with pytest.raises(ValueError, match="stderr of \\['z'\\]"):
        GridMap(values={"a": np.zeros((5, 4))}, **{**kw, "stderr": {"z": np.zeros((5, 4))}})


def test_unknown_quantity_raises_keyerror_with_the_names(tmp_path):
    m = _field()
    with pytest.raises(KeyError, match="available: dc_gain, illuminance, received_power_dbm"):
        heatmap_png(m, "snr", None, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_netcdf_round_trip(tmp_path):
    xr = pytest.importorskip("xarray")
    a = _field(channel="tx0", mask=[(1, 2)])
    b = _field(channel="group A", source=(1.5, 1.0, 3.0))
    b = GridMap(
        b.grid,
        b.channel,
        b.origin,
        b.u,
        b.v,
        b.x,
        b.y,
        {"illuminance": b.values["illuminance"]},
        {},
        {"illuminance": "lx"},
    )  # b lacks two quantities
    path = to_netcdf([a, b], tmp_path / "m.nc")
    with xr.open_dataset(path, engine="scipy") as ds:
        ds = ds.load()
    # A horizontal grid along x and y: dims (channel, y, x) in room metres, so that plot() draws x across.
    assert ds["illuminance"].dims == ("channel", "y", "x") and ds.sizes == {"channel": 2, "y": 4, "x": 5}
    assert list(ds["channel"].values) == ["tx0", "group A"]
    np.testing.assert_array_equal(ds["illuminance"].values[0], a.values["illuminance"].T)
    np.testing.assert_array_equal(ds["illuminance"].values[1], b.values["illuminance"].T)
    np.testing.assert_array_equal(ds["illuminance_stderr"].values[0], a.stderr["illuminance"].T)
    assert np.all(np.isnan(ds["dc_gain"].values[1])) and np.all(np.isnan(ds["illuminance_stderr"].values[1]))
    np.testing.assert_array_equal(ds["x"].values, 1.0 + a.x)  # room coordinates: the origin plus the offsets
    np.testing.assert_array_equal(ds["y"].values, 0.5 + a.y)
    np.testing.assert_array_equal(ds["u"].values, a.x)  # the offsets along u and v, and the grid indices
    np.testing.assert_array_equal(ds["j"].values, np.arange(4))
    np.testing.assert_allclose(
        np.stack([ds[f"position_{c}"].values for c in "xyz"], -1), a.positions.transpose(1, 0, 2)
    )
    assert ds["illuminance"].attrs["units"] == "lx" and ds["received_power_dbm"].attrs["units"] == "dBm"
    assert ds["x"].attrs["units"] == "m" and ds.attrs["grid"] == "wp"
    np.testing.assert_array_equal(ds.attrs["u"], a.u)
    assert ds["mask_reason"].dims == ("channel", "y", "x")  # the channels' masks differ
    assert ds["mask_reason"].values[0, 2, 1] == "inside furniture 'desk'" and ds["mask_reason"].values[1, 2, 1] == ""
    back = from_xarray(ds)
    assert [m.channel for m in back] == ["tx0", "group A"] and not back[1].masked.any()
    np.testing.assert_array_equal(back[0].values["dc_gain"], a.values["dc_gain"])
    np.testing.assert_array_equal(back[0].mask_reason, a.mask_reason.astype(str))
    assert back[0].units == a.units


def test_shared_mask_is_stored_once(tmp_path):
    xr = pytest.importorskip("xarray")
    a, b = _field(channel="a", mask=[(0, 0), (4, 3)]), _field(channel="b", mask=[(0, 0), (4, 3)])
    with xr.open_dataset(to_netcdf([a, b], tmp_path / "m.nc"), engine="scipy") as ds:
        assert ds["mask_reason"].dims == ("y", "x")
        back = from_xarray(ds.load())
    assert [int(m.masked.sum()) for m in back] == [2, 2] and back[1].mask_reason[4, 3] == "inside furniture 'desk'"


def test_xarray_refuses_mixed_grids_and_units():
    pytest.importorskip("xarray")
    a = _field()
    with pytest.raises(ValueError, match="different grids"):
        to_xarray([a, _field(grid="other", channel="x")])
    with pytest.raises(ValueError, match="given more than once"):
        to_xarray([a, _field()])
    c = _field(channel="c")
    c = GridMap(c.grid, c.channel, c.origin, c.u, c.v, c.x, c.y, c.values, {}, {**c.units, "illuminance": "W"})
    with pytest.raises(ValueError, match="'illuminance' in 'lx' and 'W'"):
        to_xarray([a, c])


def test_write_map_files_and_mat_round_trip(tmp_path):
    loadmat = pytest.importorskip("scipy.io").loadmat
    a, b = _field(channel="tx0", mask=[(0, 1)]), _field(channel="tx1", source=(2.0, 1.0, 3.0))
    tilted = _field(grid="wall/north 1", u=(0.0, 0.6, 0.8), v=(-1.0, 0.0, 0.0), nu=3, nv=2)
    paths = write_map_files([a, b, tilted], tmp_path, heatmaps=["illuminance"])
    names = sorted(p.name for p in paths)
    assert names == sorted(
        [
            "map_wp.nc",
            "map_wall_north_1.nc",
            "maps.mat",
            "map_wp_tx0_illuminance.png",
            "map_wp_tx1_illuminance.png",
            "map_wall_north_1_tx0_illuminance.png",
        ]
    )
    assert all(p.exists() and p.stat().st_size > 0 for p in paths)
    mat = loadmat(tmp_path / "maps.mat", simplify_cells=True)
    wp, wall = mat["map_wp"], mat["map_wall_north_1"]
    assert wp["grid"] == "wp" and list(wp["channels"]) == ["tx0", "tx1"] and wall["grid"] == "wall/north 1"
    np.testing.assert_array_equal(wp["values"]["illuminance"][1], b.values["illuminance"])
    np.testing.assert_array_equal(wp["stderr"]["illuminance"][0], a.stderr["illuminance"])
    assert wp["units"]["received_power_dbm"] == "dBm"
    np.testing.assert_allclose(wall["position"], tilted.positions)
    np.testing.assert_array_equal(wp["x"], a.x)
    codes = wp["mask_code"]
    assert codes.shape == (2, 5, 4) and codes.sum() == 1 and codes[0, 0, 1] == 1
    assert wp["mask_reasons"] == "inside furniture 'desk'"  # a one-element cell reads back as its string
    assert np.all(mat["map_wall_north_1"]["mask_code"] == 0)


def test_mat_file_keeps_quantity_names_longer_than_31_characters(tmp_path):
    """`lighting.cylindrical` maps `cylindrical_illuminance_direct_lx` (33 characters): MATLAB's limit is 63."""
    loadmat = pytest.importorskip("scipy.io").loadmat
    m = _field()
    m.values["cylindrical_illuminance_direct_lx"] = m.values["illuminance"] / 3
    m.units["cylindrical_illuminance_direct_lx"] = "lx"
    write_map_files([m], tmp_path, heatmaps=False)
    wp = loadmat(tmp_path / "maps.mat", simplify_cells=True)["map_wp"]
    np.testing.assert_array_equal(wp["values"]["cylindrical_illuminance_direct_lx"], m.values["illuminance"] / 3)


def _decor():
    return MapDecor(
        room=((0, 0, 0), (5, 5, 3)),
        furniture=[("desk", (1.2, 0.4, 0.0), (2.0, 1.2, 0.75)), ("shelf", (4.5, 4.0, 0), (5, 5, 2))],
        luminaires=[("led0", (1.0, 0.5, 2.85)), ("led1", (3.75, 3.75, 3.0))],
    )


@pytest.mark.parametrize("case", ["linear", "log", "decor_masked", "tilted", "one_point", "one_row", "no_data"])
def test_heatmap_png(tmp_path, case):
    m, decor, log = _field(), None, None
    if case == "log":
        log = True
    elif case == "decor_masked":
        m, decor = _field(mask=[(1, 0), (1, 1), (2, 0)]), _decor()
    elif case == "tilted":
        m, decor = _field(u=(0.0, 0.6, 0.8), v=(-1.0, 0.0, 0.0), nu=6, nv=3, mask=[(5, 2)]), _decor()
    elif case == "one_point":
        m = _field(nu=1, nv=1)
    elif case == "one_row":
        m, decor = _field(nu=7, nv=1), _decor()
    elif case == "no_data":  # every point masked: nothing to scale the colours by
        m, decor, log = _field(nu=3, nv=2, mask=[(i, j) for i in range(3) for j in range(2)]), _decor(), True
    for q in ("illuminance", "dc_gain"):
        p = heatmap_png(m, q, decor, tmp_path / f"{case}_{q}.png", log=log)
        data = p.read_bytes()
        assert data[:8] == PNG and 5_000 < len(data) < 200_000


def test_heatmaps_render_the_same_in_threads(tmp_path):
    """The object API keeps no global state: PNGs drawn in parallel threads equal those drawn one by one."""
    from concurrent.futures import ThreadPoolExecutor

    jobs = [
        (_field(channel=f"c{k}", mask=[(k, 1)], source=(1.0 + k, 1.0, 3.0)), q)
        for k in range(3)
        for q in ("illuminance", "dc_gain")
    ]
    one = [heatmap_png(m, q, _decor(), tmp_path / f"s{k}.png").read_bytes() for k, (m, q) in enumerate(jobs)]
    with ThreadPoolExecutor(4) as pool:
        par = list(
            pool.map(lambda k: heatmap_png(*jobs[k], _decor(), tmp_path / f"p{k}.png").read_bytes(), range(len(jobs)))
        )
    assert par == one and len(set(one)) == len(one)


def test_log_scale_is_chosen_for_gains_spanning_decades(tmp_path, monkeypatch):
    plt_colors = pytest.importorskip("matplotlib.colors")
    import matplotlib.figure

    m = _field(nu=20, nv=3)  # 1/d^2 over 10 m: a factor ~25 -> linear
    e = m.values["dc_gain"]
    wide = GridMap(
        m.grid,
        m.channel,
        m.origin,
        m.u,
        m.v,
        m.x,
        m.y,
        {"dc_gain": e**3, "snr_db": e},
        {},
        {"dc_gain": "1", "snr_db": "dB"},
    )
    norms = []
    orig = matplotlib.figure.Figure.savefig

    def spy(self, *a, **k):
        norms.append(self.axes[0].collections[0].norm)
        return orig(self, *a, **k)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", spy)
    heatmap_png(m, "dc_gain", None, tmp_path / "a.png")
    heatmap_png(wide, "dc_gain", None, tmp_path / "b.png")
    heatmap_png(wide, "snr_db", None, tmp_path / "c.png")
    assert [type(n) is plt_colors.LogNorm for n in norms] == [False, True, False]


def test_furniture_footprint_projection():
    m = _field(origin=(0, 0, 0), u=np.array([1, -1, 0]) / math.sqrt(2), v=np.array([1, 1, -2]) / math.sqrt(6))
    corners = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)], dtype=float)
    hull = convex_hull(_project(m, corners))
    x, y = hull[:, 0], hull[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    # a unit cube seen along its diagonal: a regular hexagon of area |nx| + |ny| + |nz| = sqrt(3)
    assert len(hull) == 6 and area == pytest.approx(math.sqrt(3), rel=1e-12)
    flat = convex_hull(_project(_field(), np.array([[1, 0, 0], [1, 2, 0], [1, 0, 1], [1, 2, 1]], dtype=float)))
    assert len(flat) == 2  # a box seen edge-on is a segment, not an error


def test_decor_from_scene():
    doc = room_doc()
    doc["furniture"] = [
        {"min": [0, 0, 0], "max": [1, 1, 0.7], "reflectance": 0.5},
        {"name": "desk", "min": [2, 2, 0], "max": [3, 3, 0.7], "reflectance": 0.5},
    ]
    doc["transmitters"].append({"position": [1, 1, 3], "normal": [0, 0, -1], "lambertian_order": 1})
    d = MapDecor.from_scene(spec(doc))
    assert [n for n, *_ in d.furniture] == ["furniture[0]", "desk"]
    assert [n for n, _ in d.luminaires] == ["tx", "tx1"]
    np.testing.assert_array_equal(d.room[1], [5, 5, 3])


def test_dataframe_is_long():
    pytest.importorskip("pandas")
    df = to_dataframe([_field(), _field(channel="tx1")])
    assert len(df) == 2 * 20 and {"channel", "i", "j", "x", "y", "z", "u", "v", "illuminance_stderr"} <= set(df.columns)
    row = df[(df.channel == "tx1") & (df.i == 3) & (df.j == 2)].iloc[0]
    assert row.illuminance == pytest.approx(_direct(5, 4)[(3, 2)], rel=1e-12)
    assert (row.x, row.y, row.z, row.u, row.v) == pytest.approx(
        (1.0 + 3 * S, 0.5 + 2 * S, 0.85, 3 * S, 2 * S), abs=1e-15
    )


def test_import_stays_light():
    code = (
        "import sys, owcsim.schemas, owcsim.formats.maps, owcsim.formats.map_files, owcsim.formats.heatmap, "
        "owcsim.formats.plots, owcsim.formats.result_files; "
        "print(sorted(m for m in ('matplotlib', 'xarray', 'scipy', 'pandas') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
