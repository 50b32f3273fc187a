"""What a job tallies (`TallyPlan`: time bins, which links keep a CIR or the order split) and its path groups.

Path groups: N_GROUPS groups of independent samples (sample index mod N_GROUPS; a batch's first
sample is in group `group_shift`) give batch-means standard errors and the reliability figures
(engine/tally/reliability.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

#: Number of batch groups kept for per-bin standard errors and the jackknife.
N_GROUPS = 16


@dataclass(frozen=True)
class TimeBins:
    """Bins of width `dt` [s] from `t_min` [s]; `n` bins."""

    t_min: float
    dt: float
    n: int

    @property
    def edges(self) -> np.ndarray:
        return self.t_min + self.dt * np.arange(self.n + 1)


@dataclass(frozen=True)
class TallyPlan:
    """What the job tallies. Slots are per receiver: link (tx, rx) has CIR slot
    tx * n_cir_rx + cir_rank[rx] when cir_rank[rx] >= 0 (likewise for the order split)."""

    bins: TimeBins
    n_orders: int  # K + 1
    n_scatter: int  # S + 1
    n_rx: int
    cir_rank: np.ndarray  # (n_rx,) rank among CIR receivers, -1 without CIR
    order_rank: np.ndarray  # (n_rx,) rank among order-split receivers, -1 without
    #: (G, n_tx) weight of each transmitter in each group's channel (P_i / sum of the group's P)
    group_weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    #: split the CIR by order where a receiver has both (outputs.cir_by_order)
    split_cir: bool = True
    #: the first batch of each source also bins its CIR per path group (`BatchBuilder`), for the per-bin
    #: errors of runs of one batch; set by the planner when the run may have one batch (simulate.tally_plan)
    first_batch_groups: bool = False

    @property
    def n_cir_rx(self) -> int:
        return int((self.cir_rank >= 0).sum())

    @property
    def n_order_rx(self) -> int:
        return int((self.order_rank >= 0).sum())

    def slots(self, links: np.ndarray, rank: np.ndarray, n_ranked: int) -> np.ndarray:
        """Slot of each global link in a per-(tx, ranked rx) array, -1 where its receiver is not ranked."""
        tx, rx = np.divmod(np.asarray(links, np.int64), self.n_rx)
        r = rank.take(rx)
        return np.where(r >= 0, tx * n_ranked + r, -1)

    def cir_slots(self, links) -> np.ndarray:
        return self.slots(links, self.cir_rank, self.n_cir_rx)

    def order_slots(self, links) -> np.ndarray:
        return self.slots(links, self.order_rank, self.n_order_rx)

    @cached_property
    def by_order_cir(self) -> bool:
        """True when some receiver has both the CIR and the order split (then the CIR is split too)."""
        return self.split_cir and bool(np.any((self.cir_rank >= 0) & (self.order_rank >= 0)))


def group_shift(batch_index: int, n_samples: int) -> int:
    """Path group of a batch's first sample: batches of fewer than N_GROUPS samples (blocks of quasi-random
    paths, engine/core/qmc.py) fill the groups in turn instead of always the first ones."""
    return batch_index * n_samples % N_GROUPS
