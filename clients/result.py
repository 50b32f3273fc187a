"""The result of a job: the typed result document, with numpy arrays, plots and files at hand."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from pydantic import PrivateAttr

from owcsim.schemas.results import LinkPublic, SimulationResultPublic


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

    def grid_maps(self):
        """The receiver grids as `owcsim.schemas.maps.GridMap`s (2-D arrays with coordinates, units, masks)."""
        from owcsim.schemas.maps import maps_of_result

        return maps_of_result(self)[0]

    def to_xarray(self, grid: str | None = None):
        """One grid's maps (all channels) as an xarray Dataset (dims channel, i, j); the first grid by default."""
        from owcsim.schemas.maps import to_xarray

        maps = self.grid_maps()
        if not maps:
            raise ValueError("this result has no receiver grid")
        name = grid if grid is not None else maps[0].grid
        chosen = [m for m in maps if m.grid == name]
        if not chosen:
            raise KeyError(f"no grid {name!r}; the grids are {sorted({m.grid for m in maps})}")
        return to_xarray(chosen)

    def to_dataframe(self):
        """The links' scalar figures as a pandas DataFrame (one row per link)."""
        import pandas as pd

        from .output import LINK_COLUMNS

        return pd.DataFrame([lk.model_dump(mode="json", include=set(LINK_COLUMNS)) for lk in self.links],
                            columns=list(LINK_COLUMNS))

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays of the server's result.npz: t_edges_s (n_bins + 1) [s]; per link (axis 0, in `links`
        order) dc_gain, dc_gain_stderr, transmitter, receiver; per link with a binned CIR (its index in
        `links` is cir_link) cir and cir_stderr (n, n_bins) [power per bin per watt; NaN = no error bar] and
        by_reflection_order (n, K + 1, n_bins)."""
        tb = self.time_bins
        cir_link = np.array([i for i, lk in enumerate(self.links) if lk.cir is not None], np.int64)
        links = [self.links[i] for i in cir_link]
        n = tb.n_bins
        orders = max((len(lk.cir.by_reflection_order or [[]]) for lk in links), default=1)
        by_k = np.zeros((len(links), orders, n))
        for i, lk in enumerate(links):
            if lk.cir.by_reflection_order:
                by_k[i, :len(lk.cir.by_reflection_order)] = lk.cir.by_reflection_order
        nan = lambda xs: np.array([np.nan if x is None else x for x in xs], float)  # noqa: E731
        return {
            "t_edges_s": tb.t_min_s + tb.time_bin_s * np.arange(n + 1),
            "cir_link": cir_link,
            "cir": np.array([lk.cir.total for lk in links], float).reshape(len(links), n),
            "cir_stderr": np.array([nan(lk.cir.total_stderr) for lk in links]).reshape(len(links), n),
            "by_reflection_order": by_k,
            "dc_gain": nan([lk.dc_gain for lk in self.links]),
            "dc_gain_stderr": nan([lk.dc_gain_stderr for lk in self.links]),
            "transmitter": np.array([lk.transmitter for lk in self.links], str),
            "receiver": np.array([lk.receiver for lk in self.links], str),
        }

    def plot(self, path: str | Path | None = None, link: int | None = None):
        """h(t) per reflection order and total (clients.plot.plot_cir); saved to `path` if given."""
        from .plot import plot_cir

        return plot_cir(self, path, link)

    def save(self, folder: str | Path) -> list[Path]:
        """Write result.json, cir.csv and cir.png, as `owcsim run` does."""
        from .output import write_outputs

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        return write_outputs(self, folder, self._raw)

    def to_json(self) -> str:
        return json.dumps(self._raw) if self._raw is not None else self.model_dump_json()
