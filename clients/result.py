"""The result of a job: the typed result document, with numpy arrays, plots and files at hand."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import PrivateAttr

from owcsim.clients.result_views import result_html, result_text
from owcsim.formats.channel_matrix import ChannelMatrix, channel_matrix
from owcsim.formats.map_files import to_xarray
from owcsim.formats.map_plot import plot_map
from owcsim.formats.maps import GridMap, maps_of_result
from owcsim.formats.plots import plot_cir
from owcsim.formats.result_files import LINK_COLUMNS, write_outputs
from owcsim.formats.result_tables import cir_arrays
from owcsim.formats.timeline import to_xarray as timeline_xarray
from owcsim.formats.timeline_plot import timeline_figure
from owcsim.schemas.results import LinkPublic, SimulationResultPublic
from owcsim.schemas.timeline import TimelineResultPublic

if TYPE_CHECKING:  # pragma: no cover
    import pandas
    import xarray
    from matplotlib.figure import Figure


class Result(SimulationResultPublic):
    """schemas.results.SimulationResultPublic plus helpers: the same type from `owcsim.simulate` (in this
    process) and from the HTTP client. `raw` is the document exactly as a server sent it (fields a newer
    server adds are kept there, and in the result.json `save` writes); an in-process result has none."""

    _raw: dict | None = PrivateAttr(default=None)

    @classmethod
    def from_document(cls, doc: dict) -> "Result":
        """A result document received as JSON (the HTTP client)."""
        out = cls.model_validate(doc)
        out._raw = doc
        return out

    @classmethod
    def of(cls, result: SimulationResultPublic) -> "Result":
        """The engine's typed result as a Result (its fields shared, not copied or validated again)."""
        return cls.model_construct(_fields_set=result.model_fields_set, **dict(result))

    @property
    def raw(self) -> dict:
        """The document as served, or this result as a JSON-ready dict."""
        return self._raw if self._raw is not None else self.model_dump(mode="json")

    def link(self, transmitter: str, receiver: str) -> LinkPublic:
        """The link between two devices, by id."""
        for lk in self.links:
            if lk.transmitter == transmitter and lk.receiver == receiver:
                return lk
        raise KeyError(f"no link {transmitter} -> {receiver}")

    def grid_maps(self) -> list[GridMap]:
        """The receiver grids as `owcsim.formats.maps.GridMap`s (2-D arrays with coordinates, units, masks)."""
        return maps_of_result(self)[0]

    def to_xarray(self, grid: str | None = None) -> xarray.Dataset:
        """One grid's maps (all channels) as an xarray Dataset in room coordinates (dims channel, y, x for a
        horizontal grid: formats.map_files.to_xarray); the first grid by default."""
        maps = self.grid_maps()
        if not maps:
            raise ValueError("this result has no receiver grid")
        name = grid if grid is not None else maps[0].grid
        chosen = [m for m in maps if m.grid == name]
        if not chosen:
            raise KeyError(f"no grid {name!r}; the grids are {sorted({m.grid for m in maps})}")
        return to_xarray(chosen)

    def plot_map(self, quantity: str = "illuminance_lx", **options: Any) -> Figure:
        """One quantity of a map in room coordinates, with the room, furniture and luminaires outlined
        (formats.map_plot.plot_map: grid=, channel=, stderr=, contours=, log=, ax=, path=)."""
        return plot_map(self, quantity, **options)

    def __repr__(self) -> str:
        """A few lines (clients/result_views.py), not every field: print(result.model_dump()) shows them all."""
        return result_text(self)

    __str__ = __repr__

    def _repr_html_(self) -> str:
        return result_html(self)

    def _repr_pretty_(self, printer: Any, cycle: bool) -> None:
        printer.text(result_text(self))

    def to_dataframe(self) -> pandas.DataFrame:
        """The links' scalar figures as a pandas DataFrame (one row per link)."""
        import pandas as pd

        return pd.DataFrame(
            [lk.model_dump(mode="json", include=set(LINK_COLUMNS)) for lk in self.links], columns=list(LINK_COLUMNS)
        )

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays of the server's result.npz: t_edges_s (n_bins + 1) [s]; per link (axis 0, in `links`
        order) dc_gain, dc_gain_stderr, transmitter, receiver; per link with a binned CIR (its index in
        `links` is cir_link) cir and cir_stderr (n, n_bins) [power per bin per watt; NaN = no error bar] and
        by_reflection_order (n, K + 1, n_bins)."""
        return cir_arrays(self)

    def channel_matrix(self) -> ChannelMatrix:
        """DC gain of every transmitter x receiver with its error, LOS part and CIR (formats.channel_matrix):
        `.dc_gain[i, j]`, ids in `.transmitters` / `.receivers`, `.to_xarray()`; for MIMO studies."""
        return channel_matrix(self)

    def plot(self, path: str | Path | None = None, link: int | None = None) -> Figure:
        """h(t) per reflection order and total (formats.plots.plot_cir); saved to `path` if given."""
        return plot_cir(self, path, link)

    def save(self, folder: str | Path) -> list[Path]:
        """Write result.json, cir.csv and cir.png, as `owcsim run` does."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        return write_outputs(self, folder, self._raw)

    def _timeline(self) -> TimelineResultPublic:
        if self.timeline is None:
            raise ValueError("this result has no timeline: its scene has no `timeline` section")
        return self.timeline

    def timeline_to_xarray(self) -> xarray.Dataset:
        """The timeline as an xarray Dataset with dims (link, time): dc_gain, its errors, SNR, BER, in_outage, ...
        (formats.timeline.to_xarray)."""
        return timeline_xarray(self._timeline())

    def timeline_dataframe(self) -> pandas.DataFrame:
        """The timeline as a pandas DataFrame, one row per link and time (the columns of timeline.csv)."""
        import io

        import pandas as pd

        from owcsim.formats.timeline import timeline_rows

        return pd.read_csv(io.StringIO(timeline_rows(self._timeline())))

    def plot_timeline(self, path: str | Path | None = None) -> Figure:
        """H0 and BER against time with the outage bands (formats.timeline_plot.timeline_figure); saved to `path`
        if given."""
        fig = timeline_figure(self._timeline())
        if path is not None:
            fig.savefig(path, dpi=100)
        return fig

    def to_json(self) -> str:
        return json.dumps(self._raw) if self._raw is not None else self.model_dump_json()
