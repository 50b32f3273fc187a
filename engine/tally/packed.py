"""The tally of a packed batch: the paths of several sources (a map's receivers) in one kernel batch.

A map runs paths from each receiver to the few transmitters; one receiver's paths alone make a small batch,
whose fixed cost per kernel step dominates (benchmarks/path_cost.py). A packed batch (engine/run/allocation.py,
`WorkItem.sources`, `counts`) traces `counts[m]` paths from source m, in source order, in one kernel run.
Its tally keeps what every link needs: the per-path sums (a, b, c) = (sum w, sum w t, sum w t^2) per (target,
path) while the batch runs, then per link (target, source) their sums over the source's paths (`s1`), the sums
of their outer products (`s2`), the path groups of the reliability figures (sample index within the source mod
N_GROUPS) and the largest per-path H0; per source, each transmitter group's channel. Every path is its own
independent sample (pseudo-random paths): the moments are the usual per-path ones (tally/stats.py).
No CIR and no order split (a map's grid receivers keep neither by default; schemas/outputs.py).
"""

from __future__ import annotations

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.tally.plan import N_GROUPS, TallyPlan
from owcsim.engine.tally.tally import BatchTally


class PackedBuilder:
    """Reduces a packed batch's next-event estimates into a BatchTally with per-link path counts.

    `links` (T * M,): the global link of each (target, source) pair, target-major; `sources` (M,) the
    sources' device indices; `counts` (M,): paths per source, path indices running over the sources in
    order. `add_step` takes what BatchBuilder.add_step takes.
    """

    def __init__(self, plan: TallyPlan, links: IntArray, n_targets: int, sources: IntArray, counts: IntArray):
        self.plan, self.links, self.counts = plan, np.asarray(links, np.int64), np.asarray(counts, np.int64)
        self.sources = np.asarray(sources, np.int64)
        self.n_targets, self.n_paths = n_targets, int(self.counts.sum())
        self.starts = np.concatenate([[0], np.cumsum(self.counts)[:-1]]).astype(np.int64)
        self.abc = np.zeros((3, n_targets * self.n_paths))

    def add_step(self, target, k, s, delay, power, path) -> None:
        if len(power) == 0:
            return
        key = path if self.n_targets == 1 else target * self.n_paths + path
        wt = power * delay
        np.add.at(self.abc[0], key, power)
        np.add.at(self.abc[1], key, wt)
        np.add.at(self.abc[2], key, wt * delay)

    def _per_source(self, x: FloatArray) -> FloatArray:
        """Sums of x (..., n_paths) over each source's paths: (..., M)."""
        return np.add.reduceat(x, self.starts, axis=-1)

    def finish(self, channel_weights: FloatArray | None = None) -> BatchTally:
        """The batch's tally; `channel_weights` (G, T) adds per source the per-path moments of G channels."""
        plan, n_t, m = self.plan, self.n_targets, len(self.counts)
        abc = self.abc.reshape(3, n_t, self.n_paths)
        n_links = n_t * m
        s1 = self._per_source(abc).transpose(1, 2, 0).reshape(n_links, 3)
        s2 = self._per_source(abc[:, None] * abc[None, :]).transpose(2, 3, 0, 1).reshape(n_links, 3, 3)
        source_of_path = np.repeat(np.arange(m), self.counts)
        group = (np.arange(self.n_paths) - np.repeat(self.starts, self.counts)) % N_GROUPS
        cell = source_of_path * N_GROUPS + group  # (source, path group) of each path
        keys = (np.arange(n_t)[:, None] * (m * N_GROUPS) + cell[None, :]).ravel()
        h0_groups = np.bincount(keys, abc[0].ravel(), n_links * N_GROUPS).reshape(n_links, N_GROUPS)
        group_paths = np.bincount(cell, minlength=m * N_GROUPS).reshape(m, N_GROUPS)
        ch_s1 = ch_s2 = None
        if channel_weights is not None and len(channel_weights):
            ch = np.einsum("gt,qtn->qgn", channel_weights, abc)
            ch_s1 = self._per_source(ch).transpose(1, 2, 0)  # (G, M, 3)
            ch_s2 = self._per_source(ch[:, None] * ch[None, :]).transpose(2, 3, 0, 1)  # (G, M, 3, 3)
        n_bins, cells = plan.bins.n, (0, plan.n_orders, plan.n_scatter)
        return BatchTally(
            links=self.links,
            n_paths=self.n_paths,
            s1=s1,
            s2=s2,
            cir_links=np.zeros(0, np.int64),
            cir=np.zeros((0, n_bins)),
            early=np.zeros(0),
            late=np.zeros(0),
            cir_k=None,
            cir_s=None,
            order_links=np.zeros(0, np.int64),
            order_sum=np.zeros(cells),
            order_sumsq=np.zeros(cells),
            order_ssum=np.zeros(cells),
            h0_groups=h0_groups,
            h0_group_paths=np.tile(group_paths, (n_t, 1)),
            h0_sample_max=np.maximum.reduceat(abc[0], self.starts, axis=1).ravel(),
            channel_s1=ch_s1,
            channel_s2=ch_s2,
            link_paths=np.tile(self.counts, n_t),
            sources=self.sources,
        )
