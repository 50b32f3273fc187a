"""Maps in room coordinates (issue 24 item 6): the xarray layout per plane, `plot_map`'s image, outlines and
colour bar. The references are the grid's own definition: a field that is a known function of the room
position (f = x + 10 y + 100 z) must sit at that position in every layout and every picture."""

from __future__ import annotations

import numpy as np
import pytest

from owcsim.formats.map_files import from_xarray, to_dataframe, to_xarray
from owcsim.formats.map_plot import FURNITURE_LABEL, LUMINAIRE_LABEL, ROOM_LABEL, plot_map
from owcsim.formats.maps import GridMap, MapDecor, PlaneFrame

pytest.importorskip("matplotlib")
S = 0.5


def _f(p: np.ndarray) -> np.ndarray:
    return p[..., 0] + 10 * p[..., 1] + 100 * p[..., 2]


def _map(origin=(1.0, 0.5, 0.85), u=(1.0, 0.0, 0.0), v=(0.0, 1.0, 0.0), nu=5, nv=4, sv=S, mask=()) -> GridMap:
    origin, u, v = np.array(origin, float), np.array(u, float), np.array(v, float)
    u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
    x, y = S * np.arange(nu), sv * np.arange(nv)
    pos = origin + x[:, None, None] * u + y[None, :, None] * v
    reason = np.full((nu, nv), "", dtype=object)
    for ij in mask:
        reason[ij] = "inside furniture 'desk'"
    f = _f(pos)
    return GridMap(
        "wp",
        "tx0",
        origin,
        u,
        v,
        x,
        y,
        {"illuminance_lx": f},
        {"illuminance_lx": 0.01 * f},
        {"illuminance_lx": "lx"},
        reason,
    )


LAYOUTS = {  # name: (grid, dims of a variable, the page's axis names)
    "floor": (dict(), ("channel", "y", "x"), ("x", "y")),
    "floor, u along -y": (dict(origin=(4.0, 4.0, 0.85), u=(0, -1, 0), v=(1, 0, 0)), ("channel", "y", "x"), ("x", "y")),
    "wall y = 0.01": (dict(origin=(0.5, 0.01, 0.2), u=(0, 0, 1), v=(1, 0, 0)), ("channel", "z", "x"), ("x", "z")),
    "wall x = 4.99": (dict(origin=(4.99, 0.5, 0.2), u=(0, 1, 0), v=(0, 0, 1)), ("channel", "z", "y"), ("y", "z")),
    "tilted": (dict(origin=(2.0, 1.0, 0.5), u=(0, 1, 0), v=(1, 0, 1)), ("channel", "v", "u"), ("u", "v")),
}


@pytest.mark.parametrize("name", LAYOUTS)
def test_xarray_dims_are_room_axes_with_increasing_metre_coordinates(name):
    grid, dims, names = LAYOUTS[name]
    m = _map(mask=[(1, 2)], **grid)
    ds = to_xarray([m])
    assert ds["illuminance_lx"].dims == dims and ds["illuminance_lx_stderr"].dims == dims
    rows, cols = dims[1], dims[2]
    assert (np.diff(ds[rows].values) > 0).all() and (np.diff(ds[cols].values) > 0).all()
    assert ds[cols].attrs["units"] == "m" and ds["illuminance_lx"].attrs["units"] == "lx"
    pos = np.stack([ds[f"position_{c}"].values for c in "xyz"], -1)
    np.testing.assert_allclose(ds["illuminance_lx"].values[0], _f(pos), rtol=1e-12)  # each value at its point
    if names != ("u", "v"):  # axis-aligned: the dim coordinates are the room coordinates of the points
        k_row, k_col = "xyz".index(rows), "xyz".index(cols)
        np.testing.assert_allclose(pos[..., k_col], np.broadcast_to(ds[cols].values, pos.shape[:2]), atol=1e-12)
        np.testing.assert_allclose(
            pos[..., k_row], np.broadcast_to(ds[rows].values[:, None], pos.shape[:2]), atol=1e-12
        )
    back = from_xarray(ds)[0]
    np.testing.assert_array_equal(back.values["illuminance_lx"], m.values["illuminance_lx"])
    np.testing.assert_array_equal(back.mask_reason, m.mask_reason.astype(str))
    np.testing.assert_array_equal(back.x, m.x)
    np.testing.assert_array_equal(back.y, m.y)
    assert PlaneFrame.of(m).names == names


def test_xarray_plot_draws_x_across_and_y_up():
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    m = _map(nu=6, nv=3)  # a 2.5 x 1 m grid: a transposed picture would be taller than wide
    ds = to_xarray([m])
    mesh = ds["illuminance_lx"].plot()  # one channel: xarray squeezes it
    ax = mesh.axes
    assert ax.get_xlabel().startswith("x") and ax.get_ylabel().startswith("y")
    assert ax.get_xlim() == pytest.approx((0.75, 3.75)) and ax.get_ylim() == pytest.approx((0.25, 1.75))
    plt.close("all")


def test_dataframe_has_room_coordinates():
    pytest.importorskip("pandas")
    df = to_dataframe(_map(**LAYOUTS["wall y = 0.01"][0]))
    np.testing.assert_allclose(df["illuminance_lx"], _f(df[["x", "y", "z"]].to_numpy()), rtol=1e-12)
    assert df["y"].eq(0.01).all()


def _decor():
    return MapDecor(
        room=(np.zeros(3), np.array([5.0, 5.0, 3.0])),
        furniture=[
            ("desk", np.array([1.0, 1.0, 0.0]), np.array([2.0, 1.8, 0.75])),
            ("shelf", np.array([4.0, 0.0, 0.0]), np.array([5.0, 0.4, 2.0])),
        ],
        luminaires=[("a", np.array([1.25, 1.25, 3.0])), ("b", np.array([3.75, 3.75, 3.0]))],
    )


def _patches(ax, label):
    return [p for p in ax.patches if p.get_label() == label]


def test_plot_map_of_a_work_plane_in_room_metres_with_outlines_and_colour_bar():
    m = _map(nu=8, nv=7, mask=[(2, 2)])  # x from 1 to 4.5 m, y from 0.5 to 3.5 m
    fig = plot_map(m, decor=_decor())
    ax, bar = fig.axes[0], fig.axes[1]
    assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]"
    assert ax.get_xlim() == pytest.approx((0.0, 5.0)) and ax.get_ylim() == pytest.approx((0.0, 5.0))  # the room
    assert len(_patches(ax, FURNITURE_LABEL)) == 2 and len(_patches(ax, ROOM_LABEL)) == 1
    desk = _patches(ax, FURNITURE_LABEL)[0].get_xy()
    assert desk[:, 0].min() == pytest.approx(1.0) and desk[:, 1].max() == pytest.approx(1.8)
    stars = [c for c in ax.collections if c.get_label() == LUMINAIRE_LABEL][0].get_offsets()
    np.testing.assert_allclose(stars, [[1.25, 1.25], [3.75, 3.75]])
    assert bar.get_ylabel() == "illuminance E [lx]"
    image = ax.images[0]
    assert image.get_extent() == pytest.approx((0.75, 4.75, 0.25, 3.75))
    data = image.get_array()
    across, up = 1.0 + S * np.arange(8), 0.5 + S * np.arange(7)
    want = across[None, :] + 10 * up[:, None] + 100 * 0.85  # row r is y = up[r], column c is x = across[c]
    assert np.ma.is_masked(data[2, 2]) or np.isnan(data[2, 2])  # the masked point is not drawn
    want[2, 2] = np.nan
    np.testing.assert_allclose(np.ma.filled(data, np.nan), want, rtol=1e-12)


def test_plot_map_of_a_wall_with_stderr_panel_and_contours(tmp_path):
    m = _map(**LAYOUTS["wall y = 0.01"][0])
    fig = plot_map(m, decor=_decor(), stderr=True, contours=4, path=tmp_path / "wall.png")
    assert (tmp_path / "wall.png").stat().st_size > 1000
    value_ax, error_ax = fig.axes[0], fig.axes[1]
    assert value_ax.get_xlabel() == "x [m]" and value_ax.get_ylabel() == "z [m]"
    assert value_ax.get_ylim() == pytest.approx((0.2 - S / 2, 3.0))  # the lowest cell's edge, up to the ceiling
    assert len(_patches(value_ax, FURNITURE_LABEL)) == 2  # the boxes' elevations
    np.testing.assert_allclose(np.ma.filled(error_ax.images[0].get_array(), np.nan), 1.0, rtol=1e-12)  # 1 % [%]
    labels = [a.get_ylabel() for a in fig.axes[2:]]
    assert labels == ["illuminance E [lx]", "relative standard error of illuminance E [%]"]
    assert len(value_ax.collections) >= 2  # the contour set beside the luminaire markers


def test_plot_map_errors_are_clear():
    m = _map()
    with pytest.raises(KeyError, match="available: illuminance_lx"):
        plot_map(m, "snr_db")
    with pytest.raises(TypeError, match="draws a result or a GridMap"):
        plot_map({"maps": []})
    bare = GridMap("g", "c", m.origin, m.u, m.v, m.x, m.y, {"q": m.values["illuminance_lx"]}, {}, {"q": "1"})
    with pytest.raises(ValueError, match="has no standard error"):
        plot_map(bare, "q", stderr=True)


def test_imports_stay_light():
    import subprocess
    import sys

    code = (
        "import sys, owcsim.formats.map_plot, owcsim.clients.result; "
        "print(sorted(m for m in ('matplotlib', 'xarray', 'pandas') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_map_files_carry_the_receivers_normal_not_u_cross_v(tmp_path):
    """A floor plan indexed (y, x): u x v points down while its receivers face up. The netCDF file and its read-back
    say up (the receivers'), and a map without a given normal keeps u x v."""
    import xarray as xr

    from owcsim.formats.map_files import to_netcdf

    m = _map(u=(0.0, 1.0, 0.0), v=(1.0, 0.0, 0.0))
    assert np.allclose(m.receiver_normal, [0, 0, -1])  # u x v: the default
    up = GridMap(m.grid, m.channel, m.origin, m.u, m.v, m.x, m.y, m.values, m.stderr, m.units, None, (0, 0, 1))
    with xr.open_dataset(to_netcdf([up], tmp_path / "m.nc"), engine="scipy") as ds:
        assert np.allclose(ds.attrs["normal"], [0, 0, 1])
        (back,) = from_xarray(ds.load())
    assert np.allclose(back.receiver_normal, [0, 0, 1])
    with pytest.raises(ValueError, match="receiver_normal must be a unit vector"):
        GridMap(m.grid, m.channel, m.origin, m.u, m.v, m.x, m.y, m.values, m.stderr, m.units, None, (0, 0, 2))
