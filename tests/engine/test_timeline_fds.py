"""A timeline over the real FDS office fire, end to end: FDS output -> frames -> timeline job -> H0(t).

Reference: the line of sight between two devices on a line parallel to x through the room is
H_LOS(t) = H_free exp(-integral of K along the segment), with K the cell values of FDS's cell-centred
extinction slice read here directly through fdsreader, integrated cell by cell in this test (exact overlap
lengths of the segment with each cell column), not by the code under test.
"""

import math

import numpy as np
import pytest

from owcsim.engine.run.timeline import run_timeline
from tests.fds_data import office_fire
from tests.scenes import room_doc, spec

fdsreader = pytest.importorskip("fdsreader", reason="pip install 'owcsim[fire]' (scripts/test installs it)")

Y, Z, X0, X1 = 2.1, 1.5, 0.3, 5.7  # the link's line [m]; cells 0.2 m
TIMES = [0.0, 45.0, 90.0]


def _line_integral(k_cells: np.ndarray) -> float:
    """integral of K dx from X0 to X1 at (Y, Z): sum over cells i of K[i, j, k] overlap([x_i, x_i + 0.2], [X0, X1])."""
    j, k = int(Y // 0.2), int(Z // 0.2)
    edges = np.arange(31) * 0.2
    overlap = np.clip(np.minimum(edges[1:], X1) - np.maximum(edges[:-1], X0), 0.0, None)
    return float(np.sum(k_cells[:, j, k] * overlap))


@pytest.fixture(scope="module")
def fire_result():
    case = office_fire()
    doc = room_doc(
        size=(6.0, 4.0, 3.0),
        tx=(X0, Y, Z),
        tx_normal=(1, 0, 0),
        rx=(X1, Y, Z),
        rx_normal=(-1, 0, 0),
        rho_walls=0.0,
        rho_floor=0.0,
        rho_ceiling=0.0,
        paths=500,
        max_reflections=1,
    )
    doc["timeline"] = {
        "frames": {
            "type": "fds",
            "path": str(case),
            "slice_id": "EXT_3D_CELL",
            "albedo": 0.0,
            "origin": [0.0, 0.0, 0.0],
            "times_s": TIMES,
        },
    }
    return run_timeline(spec(doc)), case


def test_fds_timeline_line_of_sight_is_beer_lambert_through_fds_cells(fire_result):
    result, case = fire_result
    fdsreader.settings.ENABLE_CACHING = False
    ext = fdsreader.Simulation(str(case)).slices.get_by_id("EXT_3D_CELL")
    frames = [int(np.argmin(np.abs(ext.times - t))) for t in TIMES]
    d = X1 - X0
    h_free = 2.0 * 1e-4 / (2.0 * math.pi * d * d)  # Lambertian m = 1 facing each other: (m + 1) A / (2 pi d^2)
    link = result.timeline.links[0]
    times = np.asarray(result.timeline.times_s)
    for i, f in enumerate(frames):
        ref = h_free * math.exp(-_line_integral(np.asarray(ext[0].data[f], np.float64)))
        assert link.los_gain[i] == pytest.approx(ref, rel=1e-9), (times[i], link.los_gain[i], ref)
    assert link.los_gain[-1] < 1e-3 * link.los_gain[0]  # the smoke is dense at 90 s: a test that can fail


def test_fds_timeline_reports_where_its_frames_came_from(fire_result):
    result, _ = fire_result
    report = result.timeline.frames_report
    assert report is not None and report.kind == "fds" and report.data_id == "EXT_3D_CELL"
    assert report.grid_shape == (30, 20, 15) and report.albedo == 0.0
    assert "EXT_3D_CELL" in result.timeline.frames_source
