"""Frames from netCDF files (engine/media/frames_netcdf.py): dims (time, z, y, x), cell-centre coordinates."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from pydantic import TypeAdapter, ValidationError

from owcsim.engine.core.errors import SceneError
from owcsim.engine.media.frame_sources import frames_from_spec
from owcsim.schemas.frames import FramesSpec

NX, NY, NZ, NT = 5, 4, 3, 4
H = (0.4, 0.5, 0.25)


def _write(path, values=None, x=None, **variables):
    rng = np.random.default_rng(7)
    x = np.arange(NX) * H[0] + H[0] / 2 if x is None else x
    coords = {
        "time": np.arange(NT) * 10.0,
        "z": 1.0 + np.arange(NZ) * H[2] + H[2] / 2,
        "y": np.arange(NY) * H[1] + H[1] / 2,
        "x": x,
    }
    if not variables:
        variables = {"extinction": rng.uniform(0, 3, (NT, NZ, NY, NX)) if values is None else values}
    ds = xr.Dataset({k: (("time", "z", "y", "x"), v) for k, v in variables.items()}, coords=coords)
    ds.to_netcdf(path, engine="scipy")
    return variables


def _spec(path, **kw):
    doc = {"type": "netcdf", "path": str(path.name), "origin": [0, 0, 0], "variable": "extinction", "albedo": 0.2}
    return TypeAdapter(FramesSpec).validate_python({**doc, **kw})


def test_extinction_variable_reads_transposed(tmp_path):
    ext = _write(tmp_path / "smoke.nc")["extinction"]
    frames = frames_from_spec(_spec(tmp_path / "smoke.nc", origin=[1.0, 0.0, 0.0]), base_dir=tmp_path)
    assert frames.shape == (NX, NY, NZ) and frames.n_frames == NT
    np.testing.assert_allclose(frames.sigma_t[:, 3, 2, 1], ext[:, 1, 2, 3], rtol=1e-15)  # x, y, z = 3, 2, 1
    assert np.array_equal(frames.sigma_s, 0.2 * np.transpose(ext, (0, 3, 2, 1)))
    np.testing.assert_allclose(frames.lo, [1.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(frames.hi, [1.0 + NX * H[0], NY * H[1], 1.0 + NZ * H[2]], atol=1e-12)
    report = frames.frames_report()
    assert report.kind == "netcdf" and report.data_id == "extinction" and report.albedo == 0.2


def test_sigma_a_sigma_s_variables_and_times(tmp_path):
    rng = np.random.default_rng(8)
    a, s = rng.uniform(0, 1, (NT, NZ, NY, NX)), rng.uniform(0, 1, (NT, NZ, NY, NX))
    _write(tmp_path / "ab.nc", sigma_a=a, sigma_s=s)
    doc = {
        "type": "netcdf",
        "path": str(tmp_path / "ab.nc"),
        "origin": [0, 0, 0],
        "sigma_a_variable": "sigma_a",
        "sigma_s_variable": "sigma_s",
        "times_s": [19.0, 31.0],
    }
    frames = frames_from_spec(TypeAdapter(FramesSpec).validate_python(doc))
    assert frames.times.tolist() == [20.0, 30.0]
    assert np.array_equal(frames.sigma_a, np.transpose(a[2:4], (0, 3, 2, 1)))
    assert np.array_equal(frames.sigma_s, np.transpose(s[2:4], (0, 3, 2, 1)))
    assert frames.frames_report().albedo_from == "file"
    with pytest.raises(ValidationError, match="no `albedo`"):
        TypeAdapter(FramesSpec).validate_python({**doc, "albedo": 0.3})


def test_bad_netcdf_is_refused(tmp_path):
    bad = np.ones((NT, NZ, NY, NX))
    bad[2, 1, 0, 4] = np.nan
    _write(tmp_path / "nan.nc", values=bad)
    with pytest.raises(SceneError, match="time index 2, x 4, y 0, z 1"):
        frames_from_spec(_spec(tmp_path / "nan.nc"), base_dir=tmp_path)
    _write(tmp_path / "uneven.nc", x=np.array([0.1, 0.3, 0.5, 0.8, 1.0]))
    with pytest.raises(SceneError, match="uniform spacing"):
        frames_from_spec(_spec(tmp_path / "uneven.nc"), base_dir=tmp_path)
    _write(tmp_path / "ok.nc")
    with pytest.raises(SceneError, match="no variable 'soot'"):
        frames_from_spec(_spec(tmp_path / "ok.nc", variable="soot"), base_dir=tmp_path)
    with pytest.raises(SceneError, match="not found"):
        frames_from_spec(_spec(tmp_path / "missing.nc"), base_dir=tmp_path)


def test_file_bytes_in_the_document_read_the_same(tmp_path):
    import base64

    _write(tmp_path / "smoke.nc")
    by_path = frames_from_spec(_spec(tmp_path / "smoke.nc"), base_dir=tmp_path)
    data = base64.b64encode((tmp_path / "smoke.nc").read_bytes()).decode()
    doc = {"type": "netcdf", "data_base64": data, "origin": [0, 0, 0], "variable": "extinction", "albedo": 0.2}
    inline = frames_from_spec(TypeAdapter(FramesSpec).validate_python(doc))
    assert np.array_equal(inline.sigma_a, by_path.sigma_a) and np.array_equal(inline.sigma_s, by_path.sigma_s)
    assert inline.frames_report().file == "data_base64"
    with pytest.raises(SceneError, match="not valid base64"):
        frames_from_spec(TypeAdapter(FramesSpec).validate_python({**doc, "data_base64": "%%%"}))
