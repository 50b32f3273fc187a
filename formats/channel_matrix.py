"""The channel matrix of a result for MIMO studies: DC gain of every transmitter to every receiver.

`H[i, j]` is the DC gain H0 [-] (received power per watt) of transmitter i at receiver j, in the result's
transmitter and receiver order, with its standard error, its line-of-sight part and, for the links that kept
one (`outputs.cir`), the binned impulse response. Received power is `power_w[:, None] * H` [W]. NaN where
masked (a grid point in furniture) or not available. Files: `.npz` (numpy) or `.nc` (netCDF through xarray).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from owcsim.formats.optional import need
from owcsim.schemas.results import SimulationResultPublic

if TYPE_CHECKING:  # pragma: no cover
    import xarray

__all__ = ["ChannelMatrix", "channel_matrix", "write_channel_matrix"]


@dataclass(frozen=True, eq=False)
class ChannelMatrix:
    """Transmitters x receivers arrays with their ids (module docstring).

    transmitters (T,), receivers (R,) ids; power_w (T,) [W]; receiver_positions (R, 3) [m]; dc_gain,
    dc_gain_stderr, los_gain (T, R) [-]; t_edges_s (B + 1,) [s] and cir (T, R, B) [power per bin per watt] when
    a link has a binned CIR (NaN rows for the others), else None.
    """

    transmitters: list[str]
    receivers: list[str]
    power_w: np.ndarray
    receiver_positions: np.ndarray
    dc_gain: np.ndarray
    dc_gain_stderr: np.ndarray
    los_gain: np.ndarray
    t_edges_s: np.ndarray | None = None
    cir: np.ndarray | None = None

    def to_xarray(self) -> xarray.Dataset:
        """A Dataset over (transmitter, receiver[, time]) with the ids as coordinates and units as attributes."""
        xr = need("xarray", "a channel-matrix Dataset")
        dims = ("transmitter", "receiver")
        data = {
            "dc_gain": (dims, self.dc_gain, {"units": "1", "long_name": "DC gain H0 (power per watt)"}),
            "dc_gain_stderr": (dims, self.dc_gain_stderr, {"units": "1", "long_name": "standard error of H0"}),
            "los_gain": (dims, self.los_gain, {"units": "1", "long_name": "line-of-sight part of H0"}),
            "power_w": (("transmitter",), self.power_w, {"units": "W"}),
        }
        coords = {
            "transmitter": ("transmitter", self.transmitters),
            "receiver": ("receiver", self.receivers),
            **{
                f"position_{c}": (("receiver",), self.receiver_positions[:, k], {"units": "m"})
                for k, c in enumerate("xyz")
            },
        }
        if self.cir is not None and self.t_edges_s is not None:
            centres = 0.5 * (self.t_edges_s[:-1] + self.t_edges_s[1:])
            data["cir"] = (dims + ("time",), self.cir, {"units": "1", "long_name": "power per bin per watt"})
            coords["time"] = ("time", centres, {"units": "s", "long_name": "bin centre (absolute delay)"})
        return xr.Dataset(data, coords=coords, attrs={"title": "owcsim channel matrix H[transmitter, receiver]"})


def _floats(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def channel_matrix(result: SimulationResultPublic) -> ChannelMatrix:
    """The channel matrix of a result, read from its links (every transmitter x receiver pair is a link)."""
    links = result.links
    tx_idx = np.array([lk.transmitter_index for lk in links], dtype=np.int64)
    rx_idx = np.array([lk.receiver_index for lk in links], dtype=np.int64)
    n_tx = int(tx_idx.max()) + 1 if len(links) else 0
    n_rx = int(rx_idx.max()) + 1 if len(links) else 0
    tx_ids, rx_ids = [""] * n_tx, [""] * n_rx
    for lk in links:  # ids and positions: one pass over the document's rows
        tx_ids[lk.transmitter_index] = lk.transmitter
        rx_ids[lk.receiver_index] = lk.receiver
    positions = np.full((n_rx, 3), np.nan)
    positions[rx_idx] = np.array([lk.receiver_position for lk in links], dtype=float).reshape(-1, 3)

    def matrix(values) -> np.ndarray:
        out = np.full((n_tx, n_rx), np.nan)
        out[tx_idx, rx_idx] = _floats(values)
        return out

    dc = matrix(lk.dc_gain for lk in links)
    power = np.array([t.power for t in result.scene.transmitters], dtype=float)  # the document's, in link order
    cirs = [(k, lk.cir.total) for k, lk in enumerate(links) if lk.cir is not None]
    t_edges = cir = None
    if cirs:
        tb = result.time_bins
        t_edges = tb.t_min_s + tb.time_bin_s * np.arange(tb.n_bins + 1)
        cir = np.full((n_tx, n_rx, tb.n_bins), np.nan)
        with_cir = np.array([k for k, _ in cirs], dtype=np.int64)
        cir[tx_idx[with_cir], rx_idx[with_cir]] = np.array([total for _, total in cirs], dtype=np.float64)
    return ChannelMatrix(
        transmitters=tx_ids,
        receivers=rx_ids,
        power_w=power,
        receiver_positions=positions,
        dc_gain=dc,
        dc_gain_stderr=matrix(lk.dc_gain_stderr for lk in links),
        los_gain=matrix(lk.los_gain for lk in links),
        t_edges_s=t_edges,
        cir=cir,
    )


def write_channel_matrix(matrix: ChannelMatrix, path: str | Path) -> Path:
    """Write the matrix as `.npz` (arrays named as the fields; ids as string arrays) or `.nc` (netCDF3 through
    xarray and scipy); returns the path."""
    path = Path(path)
    if path.suffix == ".nc":
        matrix.to_xarray().to_netcdf(path, engine="scipy")
        return path
    if path.suffix != ".npz":
        raise ValueError(f"{path.name}: a channel matrix is written as .npz or .nc")
    arrays: dict[str, Any] = {  # Any: numpy's stubs type **arrays together with allow_pickle
        "transmitters": np.array(matrix.transmitters, dtype=str),
        "receivers": np.array(matrix.receivers, dtype=str),
        "power_w": matrix.power_w,
        "receiver_positions": matrix.receiver_positions,
        "dc_gain": matrix.dc_gain,
        "dc_gain_stderr": matrix.dc_gain_stderr,
        "los_gain": matrix.los_gain,
    }
    if matrix.cir is not None and matrix.t_edges_s is not None:
        arrays.update(cir=matrix.cir, t_edges_s=matrix.t_edges_s)
    np.savez_compressed(path, **arrays)
    return path
