"""The channel matrix (formats/channel_matrix.py): equal to the links' DC gains, as arrays, xarray and files."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from owcsim.clients.result import Result
from owcsim.engine.run.simulate import simulate
from owcsim.formats.channel_matrix import channel_matrix, write_channel_matrix
from tests.engine.test_cells import AREA, TX, cells_doc, lambertian_gain
from tests.scenes import spec


@pytest.fixture(scope="module")
def los_result():
    return simulate(spec(cells_doc(budget=False)))


def test_matrix_equals_the_lambertian_gains_and_the_links(los_result):
    m = Result.of(los_result).channel_matrix()
    assert m.transmitters == [t[0] for t in TX]
    assert m.receivers == [r.id for r in los_result.receivers]
    ref = np.array([lambertian_gain(p, mm, m.receiver_positions) for _, p, mm, _ in TX])
    np.testing.assert_allclose(m.dc_gain, ref, rtol=1e-12)  # exact in line of sight
    assert not np.allclose(m.dc_gain, 1.1 * ref, rtol=1e-3)
    for lk in los_result.links:
        assert m.dc_gain[lk.transmitter_index, lk.receiver_index] == lk.dc_gain
    np.testing.assert_array_equal(m.dc_gain_stderr, 0.0)
    np.testing.assert_array_equal(m.power_w, [t[3] for t in TX])
    assert m.cir is not None and m.t_edges_s is not None  # explicit receivers keep a CIR by default
    explicit = [j for j, r in enumerate(m.receivers) if not r.startswith("g[")]
    np.testing.assert_allclose(np.nansum(m.cir[:, explicit], axis=2), m.dc_gain[:, explicit], rtol=1e-12)
    assert np.isnan(m.cir[:, len(explicit) :]).all()  # grid points: no CIR asked


def test_npz_and_netcdf_files_read_back(los_result, tmp_path):
    m = channel_matrix(los_result)
    with np.load(write_channel_matrix(m, tmp_path / "h.npz")) as f:
        np.testing.assert_array_equal(f["dc_gain"], m.dc_gain)
        assert f["transmitters"].tolist() == m.transmitters and f["receivers"].tolist() == m.receivers
        assert f["cir"].shape == (len(TX), len(m.receivers), len(m.t_edges_s) - 1)
    xr = pytest.importorskip("xarray")
    ds = xr.open_dataset(write_channel_matrix(m, tmp_path / "h.nc"), engine="scipy")
    np.testing.assert_array_equal(ds["dc_gain"].sel(transmitter="b1").values, m.dc_gain[2])
    assert ds["dc_gain"].dims == ("transmitter", "receiver")
    ds.close()
    with pytest.raises(ValueError, match="npz or .nc"):
        write_channel_matrix(m, tmp_path / "h.csv")


def test_the_command_line_writes_the_matrix_when_asked(tmp_path):
    import json

    doc = cells_doc(budget=False)
    doc["receiver_grids"] = []
    (tmp_path / "s.json").write_text(json.dumps(doc))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "owcsim", "run", str(tmp_path / "s.json"), "--out", str(out), "--no-plot"]
    subprocess.run(cmd + ["--channel-matrix"], check=True, capture_output=True)
    with np.load(out / "channel_matrix.npz") as f:
        assert f["dc_gain"].shape == (len(TX), 3)
        p = np.array(doc["receivers"][0]["position"])
        assert math.isclose(f["dc_gain"][0, 0], lambertian_gain(TX[0][1], TX[0][2], p, AREA), rel_tol=1e-12)
