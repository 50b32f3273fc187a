"""`owcsim run` on a document with a timeline writes timeline.nc, timeline.csv and timeline.svg (issue 26)."""

import csv
import json
import math

import numpy as np
import pytest

from owcsim.cli import main
from owcsim.formats.timeline import in_outage, to_xarray
from owcsim.formats.timeline_plot import timeline_figure
from owcsim.schemas.results import SimulationResultPublic
from tests.scenes import open_doc


def _doc():
    doc = open_doc(D=3.0, medium=None, algorithm=1)
    doc["link_budget"] = {"bit_rate": 1e6}
    doc["timeline"] = {
        "frames": {
            "type": "inline",
            "times": [0.0, 100.0],
            "min": [-1, -1, -1],
            "max": [4, 1, 1],
            "shape": [1, 1, 1],
            "sigma_a": [0.0, 2.0],
            "sigma_s": [0.0, 0.0],
        },
        "times_s": [0.0, 25.0, 50.0, 75.0, 100.0],
        "outage": {"quantity": "dc_gain", "threshold": 1e-6},
    }
    return doc


def test_run_writes_the_timeline_files(tmp_path, capsys):
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(_doc()))
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert (
        "timeline: 5 times from 0 to 100 s (reweighted, " in printed
        and "tx -> rx: 1 outage(s), the first at 21.05 s" in printed
    )
    for name in ("result.json", "timeline.nc", "timeline.csv", "timeline.svg"):
        assert (out / name).is_file(), name
    result = SimulationResultPublic.model_validate_json((out / "result.json").read_text())
    tl = result.timeline
    h_los = 2.0 / (2.0 * math.pi * 9.0) * 1e-4
    sigma = 2.0 * np.array(tl.times_s) / 100.0
    np.testing.assert_allclose(tl.links[0].dc_gain, h_los * np.exp(-3.0 * sigma), rtol=1e-12)
    (o,) = tl.links[0].outages  # H0 falls below 1e-6 at sigma* = ln(H_LOS / 1e-6) / 3 and stays down
    assert o.start_s == pytest.approx(50.0 * math.log(h_los / 1e-6) / 3.0, rel=1e-9) and o.end_s is None
    rows = list(csv.DictReader((out / "timeline.csv").open()))
    assert [float(r["time_s"]) for r in rows] == tl.times_s
    expected = [int(t >= o.start_s) for t in tl.times_s]
    assert expected == [0, 1, 1, 1, 1] and [int(r["in_outage"]) for r in rows] == expected
    assert float(rows[2]["dc_gain"]) == tl.links[0].dc_gain[2]
    svg = (out / "timeline.svg").read_text()
    assert svg.count('class="outage"') == 2 and 'class="threshold"' in svg  # one band per panel (H0, BER)
    # the netCDF file read back with xarray: the Dataset of to_xarray
    xr = pytest.importorskip("xarray")
    with xr.open_dataset(out / "timeline.nc", engine="scipy") as ds:
        ds.load()
    ref = to_xarray(tl)
    np.testing.assert_array_equal(ds["dc_gain"].values, ref["dc_gain"].values)
    np.testing.assert_array_equal(ds["time"].values, tl.times_s)
    assert list(ds["in_outage"].values[0]) == expected and ds["link"].values[0] == "tx -> rx"
    assert ds["dc_gain"].dims == ("link", "time")


def test_in_outage_and_the_matplotlib_figure(tmp_path):
    from owcsim.engine.run.timeline import run_timeline
    from tests.scenes import spec

    tl = run_timeline(spec(_doc())).timeline
    np.testing.assert_array_equal(in_outage(tl.links[0], [0.0, 60.0, 1e6]), [0, 1, 1])
    fig = timeline_figure(tl)
    assert len(fig.axes) == 2 and fig.axes[1].get_ylabel().startswith("BER")


def test_the_python_api_runs_a_timeline_and_its_result_has_views(tmp_path):
    import owcsim
    from owcsim.clients.result import Result

    result = owcsim.simulate(_doc())
    assert isinstance(result, Result) and result.timeline is not None
    ds = result.timeline_to_xarray()
    assert ds["dc_gain"].dims == ("link", "time") and list(ds["time"].values) == result.timeline.times_s
    df = result.timeline_dataframe()
    assert list(df["dc_gain"]) == result.timeline.links[0].dc_gain and list(df["in_outage"]) == [0, 1, 1, 1, 1]
    result.plot_timeline(tmp_path / "t.png")
    assert (tmp_path / "t.png").stat().st_size > 0
    # the same document served by HTTP: the client's Result from the JSON keeps the timeline
    again = Result.from_document(json.loads(result.model_dump_json()))
    assert again.timeline == result.timeline
    names = {p.name for p in again.save(tmp_path / "saved")}
    assert {"timeline.nc", "timeline.csv", "timeline.png"} <= names
