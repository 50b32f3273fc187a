"""Multi-cell figures of a result: serving cell, SINR, rates and handover boundaries (docs/link-budget.md).

Each transmitter group is a cell (its members send one signal); a transmitter in no group is a cell of
its own. At a receiver the serving cell is the one with the strongest received electrical signal
(gamma P_c)^2, i.e. the largest received optical power P_c [W] (ties: the first cell); the other cells
interfere. With a `link_budget`:
    SINR = (gamma P_s)^2 / (sum_{k != s} (gamma P_k)^2 + sigma_shot^2(P_total) + sigma_thermal^2),
the noise of the Komine & Nakagawa model with the shot noise of all the received light. Rates:
Shannon B log2(1 + SINR); DCO-OFDM B (N - 2) / (2N) log2(1 + SINR_ac) with the AC signal
power (gamma P)^2 / k^2 of a bias of k standard deviations (Dimitrov & Haas 2015); OOK-NRZ the
highest bit rate R_b <= B whose SINR, with the noise bandwidth R_b, reaches Q^-1(BER target)^2.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class _Public(BaseModel):
    model_config = ConfigDict(extra="ignore")


#: Rate and SINR fields of a receiver and of a cell map: name -> (unit, description).
CELL_QUANTITIES = {
    "sinr_db": ("dB", "SINR of the serving cell, 10 log10 SINR"),
    "rate_shannon_bps": ("bit/s", "Shannon rate B log2(1 + SINR)"),
    "rate_dco_ofdm_bps": ("bit/s", "DCO-OFDM rate B (N - 2) / (2N) log2(1 + SINR_ac)"),
    "rate_ook_bps": ("bit/s", "highest OOK-NRZ bit rate <= B meeting the BER target (noise bandwidth = bit rate)"),
}


class CellReceiverPublic(_Public):
    """One receiver's serving cell and, with a link budget, its SINR and rates (null where masked or dark)."""

    receiver: str = Field(description="receiver id")
    receiver_index: int = Field(description="index in `receivers`")
    serving_cell: str | None = Field(description="the cell with the largest received power (ties: the first)")
    serving_cell_index: int | None = Field(description="index of the serving cell in `cells.cells`")
    serving_power_w: float | None = Field(description="optical power received from the serving cell P_s [W]")
    interference_power_w: float | None = Field(description="optical power received from the other cells [W]")
    sinr_db: float | None = Field(None, description="SINR [dB] (with `link_budget`)")
    sinr_db_stderr: float | None = Field(None, description="standard error of sinr_db [dB] (delta method)")
    rate_shannon_bps: float | None = Field(None, description="B log2(1 + SINR) [bit/s]")
    rate_shannon_bps_stderr: float | None = Field(None, description="standard error [bit/s]")
    rate_dco_ofdm_bps: float | None = Field(None, description="B (N - 2) / (2N) log2(1 + SINR_ac) [bit/s]")
    rate_dco_ofdm_bps_stderr: float | None = Field(None, description="standard error [bit/s]")
    rate_ook_bps: float | None = Field(
        None,
        description="highest OOK-NRZ bit rate R_b <= B with SINR(noise bandwidth R_b) >= Q^-1(BER target)^2 "
        "[bit/s]; 0 if none",
    )
    rate_ook_bps_stderr: float | None = Field(None, description="standard error [bit/s]")


class BoundaryPublic(_Public):
    """A piece of a handover boundary: the edge between two neighbouring grid points served by different cells,
    through their midpoint, across the grid (the edge of their cells of the grid's dual mesh)."""

    start: tuple[float, float, float] = Field(description="one end [m]")
    end: tuple[float, float, float] = Field(description="the other end [m]")
    cells: tuple[str, str] = Field(description="the serving cells on either side (lower index first)")


class CellMapPublic(_Public):
    """A receiver grid's serving-cell map: `serving_cell[i][j]` indexes `cells.cells` (null where masked or
    dark), `values[q][i][j]` the SINR and rates (with a link budget), and the handover boundaries."""

    grid: str = Field(description="the grid's id_prefix")
    shape: tuple[int, int] = Field(description="(nu, nv) points along u and v")
    serving_cell: list[list[int | None]] = Field(description="[i][j] index of the serving cell")
    units: dict[str, str] = Field(default_factory=dict, description="unit of each quantity")
    values: dict[str, list[list[float | None]]] = Field(default_factory=dict, description="quantity -> [i][j]")
    stderr: dict[str, list[list[float | None]]] = Field(default_factory=dict, description="quantity -> [i][j]")
    boundaries: list[BoundaryPublic] = Field(default_factory=list, description="handover boundary segments [m]")


class CellsPublic(_Public):
    """The scene's cells and, per receiver and per grid, the serving cell, SINR and rates."""

    cells: list[str] = Field(description="cell names: the transmitter groups, then transmitters in no group")
    members: list[list[str]] = Field(description="transmitter ids of each cell")
    note: str | None = Field(None, description="why figures are null (e.g. no `link_budget`)")
    receivers: list[CellReceiverPublic] = Field(default_factory=list, description="per receiver, in order")
    maps: list[CellMapPublic] = Field(default_factory=list, description="per receiver grid")
