"""The serving-cell plot (formats/cell_plots.py): room coordinates, boundaries as lines, cells' colours."""

from __future__ import annotations

import numpy as np
import pytest

from owcsim.engine.run.simulate import simulate
from owcsim.formats.cell_plots import cell_grid, plot_cells
from tests.engine.test_cells import cells_doc
from tests.scenes import spec

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def result():
    return simulate(spec(cells_doc()))


def test_plot_draws_the_cells_boundaries_and_luminaires_in_room_coordinates(result, tmp_path):
    fig = plot_cells(result, tmp_path / "cells.png")
    assert (tmp_path / "cells.png").stat().st_size > 5000
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]"
    lines = [c for c in ax.collections if c.__class__.__name__ == "LineCollection"]
    segs = lines[0].get_segments()
    assert len(segs) == len(result.cells.maps[0].boundaries) > 0
    b = result.cells.maps[0].boundaries[0]
    np.testing.assert_allclose(segs[0], [b.start[:2], b.end[:2]])  # horizontal grid: x, y of the room
    mesh = ax.collections[0]
    x0, x1 = mesh.get_coordinates()[0, 0, 0], mesh.get_coordinates()[0, -1, 0]
    assert x0 == pytest.approx(0.1) and x1 == pytest.approx(4.9)  # grid 0.3..4.7, half a step beyond
    assert len(ax.get_lines()) == 4  # one marker per luminaire
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["A", "B", "c"]


def test_plot_of_a_quantity_has_a_colour_bar_and_unknown_names_are_refused(result):
    fig = plot_cells(result, quantity="sinr_db")
    assert len(fig.axes) == 2 and "sinr_db [dB]" in fig.axes[1].get_ylabel()
    with pytest.raises(KeyError, match="rate_shannon_bps"):
        plot_cells(result, quantity="snr")
    with pytest.raises(KeyError, match="no grid"):
        cell_grid(result, "nope")
