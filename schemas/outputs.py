"""What a job computes: the quantities asked, so that tallies, memory, output size and time scale with them.

Every job gets, per link and per transmitter group, the DC gain H0 with its standard error,
the received power, the path loss and the delay moments (mean delay and RMS delay spread, from
running per-path moments: no binned CIR needed). On top of that a job may ask for
- `cir`: the binned impulse response (and the figures computed from it: h^2-weighted delays,
  3 dB bandwidth, ISI of the link budget);
- `orders`: the split of H0 (and of the CIR, when asked) by reflection order k and scattering
  order s.
Both cost memory and time per link x order x bin, so by default they are computed for the
explicit `receivers` (a handful of links whose CIR a user plots) and not for `receiver_grids`
(maps of thousands of points, where the map quantities are what is read). `true` or `false`
applies to every receiver.
"""

from __future__ import annotations

from pydantic import Field

from .base import SpecModel


class OutputsSpec(SpecModel):
    """Which optional quantities to compute: null = the default by receiver kind (see the module docstring)."""

    cir: bool | None = Field(
        None, description="binned impulse response per link (default: for explicit receivers, not for grid receivers)"
    )
    orders: bool | None = Field(
        None,
        description="H0 (and CIR) split by reflection and scattering order "
        "(default: for explicit receivers, not for grid receivers)",
    )
    cir_by_order: bool | None = Field(
        None,
        description="split the CIR by order too, where a receiver has both `cir` and `orders` (default: yes, "
        "unless K or S is chosen automatically past the pilot's 40 orders: orders x bins numbers per link)",
    )

    def per_receiver(self, explicit: int, gridded: int) -> tuple[list[bool], list[bool]]:
        """(cir, orders) flags for `explicit` receivers followed by `gridded` grid receivers."""

        def flags(choice: bool | None) -> list[bool]:
            if choice is None:
                return [True] * explicit + [False] * gridded
            return [choice] * (explicit + gridded)

        return flags(self.cir), flags(self.orders)
