"""A Result in a notebook: a compact text repr and `_repr_html_`, and `plot_map` in room coordinates."""

from __future__ import annotations

import json

import numpy as np
import pytest

import owcsim
from owcsim.clients import Result
from owcsim.clients.result_views import MAX_CHANNEL_ROWS
from owcsim.formats.map_plot import FURNITURE_LABEL
from owcsim.schemas import SceneSpec
from tests.results import simulate_document as simulate
from tests.scenes import EXAMPLES, room_doc


@pytest.fixture(scope="module")
def office() -> Result:
    """The Komine room, line of sight only, a 10 x 10 grid with a desk under 4 of its points."""
    doc = json.loads((EXAMPLES / "komine_map.json").read_text())
    doc["receiver_grids"][0]["spacing"] = 0.5
    doc["simulation"] = {"max_reflections": 0}
    doc["furniture"] = [{"name": "desk", "min": [1, 1, 0], "max": [2, 1.8, 0.9], "reflectance": 0.5}]
    return owcsim.simulate(doc)


def _bounded(text: str, lines: int) -> list[str]:
    out = text.splitlines()
    assert len(out) <= lines and max(len(line) for line in out) <= 110, text
    return out


def test_text_repr_is_a_few_lines_with_the_run_and_the_channels(office):
    text = repr(office)
    lines = _bounded(text, 8)
    assert str(office) == text
    assert lines[0].startswith("Result: Komine & Nakagawa 2004 room") and "algorithm 1" in lines[0]
    assert "4 transmitters, 100 receivers (grid plane 10x10; 4 masked)" in text
    assert "400 links, 1 group channel x 100, 1 map" in text and "stop: exact" in text
    row = next(line for line in lines if line.strip().startswith("ceiling")).split()
    h0 = np.array([c.dc_gain for c in office.channels if c.dc_gain is not None])
    assert len(h0) == 96 and row[1] == "100"
    assert [float(x) for x in row[2:5]] == pytest.approx([h0.min(), h0.mean(), h0.max()], rel=1e-3)
    assert len(repr(office.model_dump())) > 50 * len(text)  # what it replaces


def test_repr_of_a_monte_carlo_run_and_of_many_channels():
    doc = room_doc(paths=2000, max_reflections=1)
    doc["transmitters"] = [
        {"id": f"led{k}", "position": [0.5 + 0.5 * k, 2.5, 3.0], "normal": [0, 0, -1], "lambertian_order": 1}
        for k in range(8)
    ]
    doc["name"] = "a <b> room"
    res = Result.from_document(json.loads(json.dumps(simulate(SceneSpec.model_validate(doc)))))
    lines = _bounded(repr(res), 7 + MAX_CHANNEL_ROWS)  # 4 lines, the header, the rows, "more", warnings
    assert (
        "stop: paths" in lines[3] and f"{res.run.paths_total:,d} paths" in lines[3] and "worst rel. error" in lines[3]
    )
    worst = max(lk.dc_gain_stderr / lk.dc_gain for lk in res.links)
    assert f"{100 * worst:.2f} %" in lines[3]
    assert f"  ... and {8 - MAX_CHANNEL_ROWS} more channels" in lines
    page = res._repr_html_()
    assert page.count("<tr>") == 1 + MAX_CHANNEL_ROWS + 1 and "a &lt;b&gt; room" in page and "<b> room" not in page
    assert len(page) < 3000


def test_plot_map_method_draws_room_coordinates_with_the_desk(office):
    fig = office.plot_map("dc_gain", contours=3)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]"
    # the cells from 0.05 - 0.25 m to the room's far wall at 5 m
    assert ax.get_xlim() == pytest.approx((-0.2, 5.0)) and ax.get_ylim() == pytest.approx((-0.2, 5.0))
    assert len([p for p in ax.patches if p.get_label() == FURNITURE_LABEL]) == 1
    assert fig.axes[1].get_ylabel() == "DC gain H0 [1]"
    with pytest.raises(KeyError, match="no grid 'wall'; the grids are"):
        office.plot_map(grid="wall")
