"""Tallies: what one batch of paths adds, and the ordered merge of batches.

Only what the job asks is tallied (schemas/outputs.py), so memory and time scale with it:

- every link: the per-path sums a = sum w, b = sum w t, c = sum w t^2 (w the power per
  watt of a next-event estimate, t its delay [s]) accumulated in dense (3, targets, paths)
  arrays while the batch runs, then their first and second moments over paths, `s1`
  (L, 3) and `s2` (L, 3, 3): H0, mean delay and RMS delay spread with delta-method
  standard errors need nothing else (metrics.delay_metrics);
- links with a CIR (`TallyPlan.cir_slot` >= 0): power per time bin, power before t_min
  (`early`) and after t_max (`late`), per batch group for per-bin errors, and split by
  reflection order k and by scattering order s when the order split is asked too;
- links with the order split (`order_slot` >= 0): sum of w and of the squared per-path
  sums per (k, s) cell.
- backward batches (paths from a receiver, next-event estimates to transmitters): the
  per-path sums of each transmitter group's channel, sum_i W[g, i] a_i, whose moments give
  the summed channel's standard error (its links share paths there, so their errors are
  correlated; forward links of different transmitters are independent and combine later).
The dense per-path arrays hold targets x paths numbers: the plan caps the batch so that
this product stays under `simulate.PATH_TARGET_BUDGET` whatever the number of receivers.

Each path adds to a (target, k, s) cell only in one call of `BatchBuilder.add_step` (the kernel
hands over the estimates of one depth k + s at a time, estimates of deeper cells made early
waiting for their step), so per-(path, cell) sums are formed step by step; with few samples
(quasi-random blocks) a dense (sample, cell) table holds those sums and they are squared once per batch.
Samples. Standard errors need independent samples. A pseudo-random path is one; the paths of a
quasi-random block (engine/core/qmc.py: Sobol points with one random shift per block) are not, the blocks
are. So a batch of n paths in blocks of m reduces its per-path sums to n / m block sums before the
second moments, and every covariance comes from `sample_cov`, the variance of a mean over independent
samples of unequal path counts (one-path samples give the usual per-path formula, bit for bit).

Batches are merged in batch order, so results are bit-identical whatever the number of
workers. Batch groups (batch index mod N_GROUPS) keep per-bin power and per-link H0 for
batch-spread standard errors, the jackknife, and the reliability of the error bars. A run of
one batch has one batch group: where the plan says so (`TallyPlan.first_batch_groups`), the first
batch of each source also bins its CIR per path group (sample index mod N_GROUPS, as the H0 path
groups), and the per-bin errors of a one-batch run come from those (result_parts._group_estimates).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from owcsim.engine.tally.plan import N_GROUPS, TallyPlan, group_shift
from owcsim.engine.tally.spectral import ChannelAccumulator, ChannelBatch, ChannelBuilder
from owcsim.engine.tally.stats import mean_cov, per_path_s2, sample_cov

__all__ = [
    "CIR_GROUPS_MAX",
    "DIRECT_KEYS",
    "KEYS_PER_ESTIMATE",
    "SAMPLE_TABLE_MAX",
    "Accumulator",
    "BatchBuilder",
    "BatchTally",
]

_GROUP_RANGE = np.arange(N_GROUPS)
#: The order split's per-(sample, cell) sums take one bincount when their keys span at most this many
#: (or KEYS_PER_ESTIMATE per estimate), else rounds over the estimates (BatchBuilder._add_squared_path_sums).
DIRECT_KEYS = 4096
KEYS_PER_ESTIMATE = 4
#: Most entries of the order split's dense (sample, cell) table: with few samples (blocks of quasi-random
#: paths) each estimate adds to its (sample, cell) sum with one `np.add.at`, and the squares are taken once
#: per batch (`BatchBuilder.finish`); 2^20 float64 = 8 MiB per batch. Larger splits sum step by step.
SAMPLE_TABLE_MAX = 1 << 20
#: Most entries of the first batch's CIR per path group (N_GROUPS x CIR links x bins, float64: 8 MiB);
#: a larger CIR keeps batch groups only (no per-bin errors from a one-batch run).
CIR_GROUPS_MAX = 1 << 20


@dataclass
class BatchTally:
    """What one batch adds; per-link arrays over the batch's targets (global ids in `links`)."""

    links: np.ndarray  # (T,)
    n_paths: int
    s1: np.ndarray  # (T, 3)
    s2: np.ndarray  # (T, 3, 3)
    cir_links: np.ndarray  # (Tc,) global link ids of the targets with a CIR
    cir: np.ndarray  # (Tc, n_bins)
    early: np.ndarray  # (Tc,)
    late: np.ndarray  # (Tc,)
    cir_k: np.ndarray | None  # (Tc, K+1, n_bins) when the order split is asked too
    cir_s: np.ndarray | None  # (Tc, S+1, n_bins)
    order_links: np.ndarray  # (To,)
    order_sum: np.ndarray  # (To, K+1, S+1)
    order_sumsq: np.ndarray  # (To, K+1, S+1)
    order_ssum: np.ndarray  # (To, K+1, S+1) the sum of the sample sums squared in order_sumsq
    h0_groups: np.ndarray | None = None  # (T, N_GROUPS) sum of per-path H0 estimates per path group
    h0_group_paths: np.ndarray | None = None  # (N_GROUPS,) paths per path group
    #: (N_GROUPS, Tc, n_bins) the CIR per path group (first batch with TallyPlan.first_batch_groups), or None
    cir_groups: np.ndarray | None = None
    #: (T,) the largest per-path H0 estimate of one independent sample (its sum / its paths): the tail
    #: diagnostic of the accuracy rule (engine/tally/reliability.py, `sample_shift`)
    h0_sample_max: np.ndarray | None = None
    #: paths per independent sample (engine/core/qmc.py): s2, order_sumsq and channel_s2 are sums over samples
    #: of the outer products of their sums
    block: int = 1
    channel_s1: np.ndarray | None = None  # (G, 3) backward batches: the groups' channels
    channel_s2: np.ndarray | None = None  # (G, 3, 3)
    rays_intersect: int = 0
    rays_occluded: int = 0
    surface_power: float = 0.0  # incident power on surfaces (forward paths) [W/W]
    escaped_power: float = 0.0  # power of rays that left the scene [W/W]
    medium_evaluations: int = 0
    #: a spectral scene's channel sums (tally/spectral.py), None when grey
    spectral: ChannelBatch | None = None
    #: a packed batch (tally/packed.py): paths per link (T,) and its sources (M,); every path one sample,
    #: h0_group_paths (T, N_GROUPS) per link, channel_s1 (G, M, 3) and channel_s2 (G, M, 3, 3) per source
    link_paths: np.ndarray | None = None
    sources: np.ndarray | None = None
    #: frames of a time-varying medium reweighted from one carrier (engine/media/frame_ratios.py): frame f's tally
    #: of the same paths (the estimates x the frame's ratio row), None otherwise
    frames: list[BatchTally] | None = None


def _accumulate(out: np.ndarray, idx: np.ndarray, weights: np.ndarray) -> None:
    """out[idx] += weights, repeated indices adding up (`np.add.at`).

    A kernel step's estimates touch few cells of large tallies (the CIR split by order is K + 1 orders
    x bins); `np.add.at` (fast since numpy 1.25) costs what the estimates cost, while `np.bincount` would zero and add
    the whole tally, or a band of it after two reductions for its bounds (2-10x slower per step, measured
    with numpy 2.4 for 16 to 65 536 estimates).
    """
    np.add.at(out, idx, weights)


class BatchBuilder:
    """Reduces a batch's next-event estimates, step by step, into a BatchTally.

    `links` (T,) are the global links of the batch's targets; `add_step` takes one kernel
    step's contributions as 1-D arrays: local target index, reflection order k, scattering
    order s, delay [s], power [W/W], path index in the batch.
    """

    def __init__(
        self,
        plan: TallyPlan,
        links: np.ndarray,
        n_paths: int,
        several_per_cell: bool,
        block: int = 1,
        first_batch: bool = False,
        channels: ChannelBuilder | None = None,
    ):
        self.plan, self.links, self.n_paths = plan, np.asarray(links, np.int64), n_paths
        #: a spectral scene's per-(target, channel) sums (tally/spectral.py; the kernel adds its estimates,
        #: `finish` puts them in BatchTally.spectral), None when grey
        self.channels = channels
        #: paths per independent sample (engine/core/qmc.py); n_paths is a multiple of it
        self.block = block
        #: a sample may add several estimates to one order cell in one step: sum them before squaring
        self.several_per_cell = several_per_cell or block > 1
        n_t = len(self.links)
        self.abc = np.zeros((3, n_t * n_paths))
        bins = plan.bins
        cs = plan.cir_slots(self.links)
        self.cir_local = np.full(n_t, -1, np.int64)
        self.cir_local[cs >= 0] = np.arange(int((cs >= 0).sum()))
        self.n_cir = int((cs >= 0).sum())
        self.cir = np.zeros(self.n_cir * bins.n)
        #: the first batch's CIR per path group (sample index mod N_GROUPS), flat (group, slot, bin)
        self.cir_groups = (
            np.zeros(N_GROUPS * self.n_cir * bins.n) if first_batch and plan.first_batch_groups and self.n_cir else None
        )
        self.early = np.zeros(self.n_cir)
        self.late = np.zeros(self.n_cir)
        split = plan.by_order_cir
        # one order (K = 0, or S = 0): that split is the CIR itself (`finish`), not tallied twice
        self.cir_k = np.zeros(self.n_cir * plan.n_orders * bins.n) if split and plan.n_orders > 1 else None
        self.cir_s = np.zeros(self.n_cir * plan.n_scatter * bins.n) if split and plan.n_scatter > 1 else None
        os_ = plan.order_slots(self.links)
        self.order_local = np.full(n_t, -1, np.int64)
        self.order_local[os_ >= 0] = np.arange(int((os_ >= 0).sum()))
        self.n_ord = int((os_ >= 0).sum())
        n_cells = self.n_ord * plan.n_orders * plan.n_scatter
        self.order_sum = np.zeros(n_cells)
        self.order_sumsq = np.zeros(n_cells)
        #: with few samples (blocks), the per-(sample, cell) sums themselves, (n_samples * n_cells,): squared
        #: and summed over samples once, in `finish` (SAMPLE_TABLE_MAX); else None and the sums are formed
        #: per step (`_add_squared_path_sums`)
        n_samples = n_paths // block
        table = block > 1 and 0 < n_samples * n_cells <= SAMPLE_TABLE_MAX
        self.sample_cells = np.zeros(n_samples * n_cells) if table else None
        self._block_shift = block.bit_length() - 1 if block & (block - 1) == 0 else None  # path >> shift = sample
        stepwise = self.several_per_cell and not table
        #: every target has an order slot in target order: the per-sample H0 sums are the table's (`finish`)
        self.h0_from_table = table and np.array_equal(self.order_local, np.arange(n_t))
        #: the CIR is the sum of a tallied split over its orders (`finish`), not tallied a third time
        self._cir_from = next(
            ((t, n) for t, n in ((self.cir_k, plan.n_orders), (self.cir_s, plan.n_scatter)) if t is not None), None
        )
        #: sum of the same per-sample sums that order_sumsq squares, so the variance takes both from one
        #: rounding (with one estimate per sample and cell, order_sum is that sum)
        self.order_ssum = np.zeros(n_cells if stepwise else 0)
        #: scratch of `_add_squared_path_sums`: one representative cell per owner (path, order-split target)
        self._cell_of_owner = np.zeros(n_samples * self.n_ord if stepwise else 0, np.int64)

    def add_step(self, target, k, s, delay, power, path) -> None:
        if len(power) == 0:
            return
        plan, n = self.plan, self.n_paths
        # --- per-path moments of every link ------------------------------------------------
        key = path if len(self.links) == 1 else target * n + path  # (one target: every index is 0)
        wt = power * delay
        if not self.h0_from_table:
            _accumulate(self.abc[0], key, power)
        _accumulate(self.abc[1], key, wt)
        _accumulate(self.abc[2], key, wt * delay)
        # --- binned CIR -----------------------------------------------------------------------
        if self.n_cir:
            slot, sel = self._ranked(self.cir_local, target)
            if sel is None:
                self._bin(slot, k, s, delay, power, path)
            elif len(sel):
                grouped = path.take(sel) if self.cir_groups is not None else None  # (first batch only)
                self._bin(slot.take(sel), k.take(sel), s.take(sel), delay.take(sel), power.take(sel), grouped)
        # --- order split ----------------------------------------------------------------------
        if self.n_ord:
            slot, sel = self._ranked(self.order_local, target)
            if sel is not None:
                if len(sel) == 0:
                    return
                slot, k, s, power, path = slot.take(sel), k.take(sel), s.take(sel), power.take(sel), path.take(sel)
            if plan.n_scatter == 1 and np.ndim(slot) == 0:  # one cell per k (algorithm 1, one target)
                cell = k + int(slot) * plan.n_orders if slot else k
            else:
                cell = (slot * plan.n_orders + k) * plan.n_scatter + s
            if self.sample_cells is not None:  # few samples: their (sample, cell) sums, squared in `finish`
                sample = path >> self._block_shift if self._block_shift is not None else path // self.block
                sample *= len(self.order_sum)
                sample += cell
                _accumulate(self.sample_cells, sample, power)
                return
            _accumulate(self.order_sum, cell, power)
            if self.several_per_cell:  # several estimates of one sample in one cell: sum before squaring
                sample = path // self.block if self.block > 1 else path
                self._add_squared_path_sums(sample * self.n_ord + slot, cell, power)
            else:
                _accumulate(self.order_sumsq, cell, power * power)  # its sample sums: order_sum itself

    def _ranked(self, local, target):
        """(slot of each estimate, the estimates with a slot or None for all): `local` maps the batch's
        targets to CIR or order-split slots (-1: none); one target (the usual batch) needs no gathers."""
        if len(local) == 1:
            return local[0], (None if local[0] >= 0 else np.zeros(0, np.int64))
        slot = local.take(target)
        sel = np.flatnonzero(slot >= 0)
        return slot, (None if len(sel) == len(slot) else sel)

    def _add_squared_path_sums(self, owner, cell, p) -> None:
        """order_sumsq[c] += (sum of the p of each owner (sample, target) in cell c)^2, without sorting.

        Rounds: every owner with estimates left picks one of its cells (the last one written to a
        scratch indexed by owner); the estimates in that cell are summed per owner with `np.bincount`
        and squared; the others wait for the next round. An owner has estimates in one to three cells
        per step (the cells of one depth k + s: surface, medium and segment-point estimates), so a
        step costs a few passes over its estimates instead of a sort (np.unique) of them. With few owners
        (blocks of quasi-random paths), one bincount over (owner, s) keys does it at once.
        """
        # One depth k + s per call: within it a cell of an owner is fixed by its scattering order s, so
        # (owner, s) keys every (owner, cell). When those keys span a small range (blocks of quasi-random
        # paths: few owners), one bincount sums them all.
        n_s = self.plan.n_scatter
        key = owner * n_s + cell % n_s
        lo, hi = int(key.min()), int(key.max()) + 1
        if hi - lo <= max(KEYS_PER_ESTIMATE * len(key), DIRECT_KEYS):
            key -= lo
            sums = np.bincount(key, p, hi - lo)
            cell_of = np.empty(hi - lo, np.int64)
            cell_of[key] = cell
            touched = np.flatnonzero(sums)  # estimates are >= 0: an owner summing to 0 adds 0 anyway
            cells, owner_sums = cell_of.take(touched), sums.take(touched)
            _accumulate(self.order_sumsq, cells, owner_sums**2)
            _accumulate(self.order_ssum, cells, owner_sums)
            return
        scratch = self._cell_of_owner
        while len(owner):
            scratch[owner] = cell
            mine = scratch.take(owner) == cell
            if mine.all():
                o, w = owner, p
                owner = cell = p = owner[:0]
            else:
                rest = ~mine
                o, w = owner[mine], p[mine]
                owner, cell, p = owner[rest], cell[rest], p[rest]
            lo, hi = int(o.min()), int(o.max()) + 1
            sums = np.bincount(o - lo, w, hi - lo)
            touched = np.flatnonzero(sums)  # estimates are >= 0: an owner summing to 0 adds 0 anyway
            cells, owner_sums = scratch.take(touched + lo), sums.take(touched)
            _accumulate(self.order_sumsq, cells, owner_sums**2)
            _accumulate(self.order_ssum, cells, owner_sums)

    def _bin(self, slot, k, s, delay, power, path) -> None:
        bins, plan = self.plan.bins, self.plan
        b = delay - bins.t_min
        b *= 1.0 / bins.dt
        if not (b.min() >= 0 and b.max() < bins.n):  # only bins inside the window are cast (a far arrival's
            inside = (b >= 0) & (b < bins.n)  # index may not fit an int64)
            early, late = np.where(b < 0, power, 0.0), np.where(b >= bins.n, power, 0.0)
            sel = np.flatnonzero(inside)
            if np.ndim(slot) == 0:  # one slot (`add_step` with one target)
                self.early[slot] += early.sum()
                self.late[slot] += late.sum()
            else:
                self.early += np.bincount(slot, early, self.n_cir)
                self.late += np.bincount(slot, late, self.n_cir)
                slot = slot.take(sel)
            k, s, b, power = k.take(sel), s.take(sel), b.take(sel), power.take(sel)
            if self.cir_groups is not None:
                path = path.take(sel)
        ib = b.astype(np.int64)
        if self.cir_groups is not None:  # (group, slot, bin) of each estimate: its sample's path group
            group = path // self.block if self.block > 1 else path.copy()
            group %= N_GROUPS
            group *= self.n_cir
            group += slot
            group *= bins.n
            group += ib
            _accumulate(self.cir_groups, group, power)
        splits = ((self.cir_k, k, plan.n_orders), (self.cir_s, s, plan.n_scatter))
        if np.ndim(slot) == 0:  # one slot: its offsets are numbers (fewer passes over the estimates)
            if self._cir_from is None:
                _accumulate(self.cir, ib + int(slot) * bins.n if slot else ib, power)
            for table, order, n_ord in splits:
                if table is not None:
                    idx = order * bins.n
                    idx += ib
                    if slot:
                        idx += int(slot) * n_ord * bins.n
                    _accumulate(table, idx, power)
            return
        if self._cir_from is None:
            _accumulate(self.cir, slot * bins.n + ib, power)
        for table, order, n_ord in splits:
            if table is not None:
                _accumulate(table, (slot * n_ord + order) * bins.n + ib, power)

    def _split_cir(self, table: np.ndarray | None, n_ord: int, cir: np.ndarray) -> np.ndarray | None:
        """(Tc, n_ord, n_bins) CIR split by an order, None without the split; one order: the CIR itself."""
        if not self.plan.by_order_cir:
            return None
        n_bins = self.plan.bins.n
        if table is None:  # one order holds every estimate
            return cir.reshape(self.n_cir, 1, n_bins).copy()
        return table.reshape(self.n_cir, n_ord, n_bins)

    def finish(self, channel_weights: np.ndarray | None = None) -> BatchTally:
        """The batch's tally; `channel_weights` (G, T) adds the per-path moments of G channels."""
        plan, n_t = self.plan, len(self.links)
        m = self.block
        n_samples = self.n_paths // m
        abc = self.abc.reshape(3, n_t, n_samples, m).sum(axis=3) if m > 1 else self.abc.reshape(3, n_t, n_samples)
        if self.h0_from_table and self.sample_cells is not None:  # per-sample H0: the table's sums per target
            abc[0] = self.sample_cells.reshape(n_samples, n_t, -1).sum(axis=2).T
        cir = self.cir
        if self._cir_from is not None:  # the CIR: a split summed over its orders
            table, n_ord = self._cir_from
            cir = table.reshape(self.n_cir, n_ord, plan.bins.n).sum(axis=1).reshape(-1)
        s1 = abc.sum(axis=2).T
        # Path groups (sample index mod N_GROUPS): independent sub-samples of this batch for the reliability
        # figures (engine/tally/reliability.py), filled from the first batch whatever the batch count.
        # Summed by reshaping, not by a product with a one-hot matrix: that product went to BLAS, whose
        # threads took 30-120 ms instead of 0.2 ms on a loaded host.
        n_full = n_samples - n_samples % N_GROUPS
        h0_groups = abc[0, :, :n_full].reshape(n_t, -1, N_GROUPS).sum(axis=1)
        h0_groups[:, : n_samples - n_full] += abc[0, :, n_full:]
        h0_group_paths = np.bincount(np.arange(n_samples) % N_GROUPS, minlength=N_GROUPS) * m
        h0_sample_max = abc[0].max(axis=1) / m if n_samples else np.zeros(n_t)
        s2 = np.einsum("qtn,rtn->tqr", abc, abc)
        ch_s1 = ch_s2 = None
        if channel_weights is not None and len(channel_weights):
            ch = np.einsum("gt,qtn->qgn", channel_weights, abc)
            ch_s1 = ch.sum(axis=2).T
            ch_s2 = np.einsum("qgn,rgn->gqr", ch, ch)
        bins = plan.bins
        order_sum, order_sumsq = self.order_sum, self.order_sumsq
        order_ssum = self.order_ssum if len(self.order_ssum) else order_sum
        if self.sample_cells is not None:  # the per-(sample, cell) sums: their sum and the sum of their squares
            sums = self.sample_cells.reshape(n_samples, -1)
            order_sum = order_ssum = sums.sum(axis=0)
            order_sumsq = np.einsum("ic,ic->c", sums, sums)
        cir_sel = np.flatnonzero(self.cir_local >= 0)
        ord_sel = np.flatnonzero(self.order_local >= 0)
        return BatchTally(
            links=self.links,
            n_paths=self.n_paths,
            s1=s1,
            s2=s2,
            cir_links=self.links.take(cir_sel),
            cir=cir.reshape(self.n_cir, bins.n),
            early=self.early,
            late=self.late,
            cir_k=self._split_cir(self.cir_k, plan.n_orders, cir),
            cir_s=self._split_cir(self.cir_s, plan.n_scatter, cir),
            order_links=self.links.take(ord_sel),
            order_sum=order_sum.reshape(self.n_ord, plan.n_orders, plan.n_scatter),
            order_sumsq=order_sumsq.reshape(self.n_ord, plan.n_orders, plan.n_scatter),
            order_ssum=order_ssum.reshape(self.n_ord, plan.n_orders, plan.n_scatter),
            channel_s1=ch_s1,
            channel_s2=ch_s2,
            h0_groups=h0_groups,
            h0_group_paths=h0_group_paths,
            cir_groups=None if self.cir_groups is None else self.cir_groups.reshape(N_GROUPS, self.n_cir, bins.n),
            h0_sample_max=h0_sample_max,
            block=m,
            spectral=self.channels.finish() if self.channels is not None else None,
        )


@dataclass
class Accumulator:
    """Sums of batch tallies over the whole job for one estimator direction, per global link."""

    n_links: int
    plan: TallyPlan
    backward: bool = False
    rays_intersect: int = 0
    rays_occluded: int = 0
    medium_evaluations: int = 0
    #: bands of a spectral scene (0: grey); with bands, `spectral` sums their channels (tally/spectral.py)
    n_bands: int = 0

    def __post_init__(self):
        plan, bins = self.plan, self.plan.bins
        #: a spectral scene's channel sums over the job, None when grey
        self.spectral = ChannelAccumulator(self.n_bands, self.n_links) if self.n_bands else None
        n_tx = self.n_links // max(plan.n_rx, 1)
        self.n_paths = np.zeros(self.n_links, np.int64)
        #: independent samples (paths, or blocks of quasi-random paths) and their sums (`sample_cov`):
        #: s1 = sum S_b, s2_samples = sum S_b S_b^T, q1 = sum n_b S_b, q0 = sum n_b^2
        self.n_samples = np.zeros(self.n_links, np.int64)
        self.s1 = np.zeros((self.n_links, 3))
        self.s2_samples = np.zeros((self.n_links, 3, 3))
        self.q1 = np.zeros((self.n_links, 3))
        self.q0 = np.zeros(self.n_links)
        n_cir = n_tx * plan.n_cir_rx
        self.cir = np.zeros((n_cir, bins.n))
        self.early = np.zeros(n_cir)
        self.late = np.zeros(n_cir)
        split = plan.by_order_cir
        self.cir_k = np.zeros((n_cir, plan.n_orders, bins.n)) if split else None
        self.cir_s = np.zeros((n_cir, plan.n_scatter, bins.n)) if split else None
        n_ord = n_tx * plan.n_order_rx
        self.order_sum = np.zeros((n_ord, plan.n_orders, plan.n_scatter))
        self.order_sumsq = np.zeros((n_ord, plan.n_orders, plan.n_scatter))  # sum over samples of S_b^2
        self.order_ssum = np.zeros((n_ord, plan.n_orders, plan.n_scatter))  # sum of S_b, rounded as order_sumsq
        self.order_q1 = np.zeros((n_ord, plan.n_orders, plan.n_scatter))  # sum of n_b S_b
        self.groups = np.zeros((N_GROUPS, n_cir, bins.n))  # per batch group, summed over k, s
        self.group_paths = np.zeros((N_GROUPS, self.n_links), np.int64)
        #: the first batch's CIR per path group and its paths per group (TallyPlan.first_batch_groups): the
        #: per-bin errors of a link that ran one batch
        self.first_groups = np.zeros((N_GROUPS, n_cir, bins.n)) if plan.first_batch_groups and n_cir else None
        self.first_group_paths = np.zeros((N_GROUPS, self.n_links), np.int64)
        #: per path group (sample index mod N_GROUPS, groups filled in turn: group_shift): sum of per-path H0
        #: estimates, and paths
        self.group_h0 = np.zeros((N_GROUPS, self.n_links))
        self.h0_group_paths = np.zeros((N_GROUPS, self.n_links), np.int64)
        #: the largest per-path H0 estimate of one independent sample so far (BatchTally.h0_sample_max)
        self.sample_max = np.zeros(self.n_links)
        n_groups = plan.group_weights.shape[0]
        self.channel_n = np.zeros((n_groups, plan.n_rx), np.int64)
        self.channel_samples = np.zeros((n_groups, plan.n_rx), np.int64)
        self.channel_s1 = np.zeros((n_groups, plan.n_rx, 3))
        self.channel_s2 = np.zeros((n_groups, plan.n_rx, 3, 3))
        self.channel_q1 = np.zeros((n_groups, plan.n_rx, 3))
        self.channel_q0 = np.zeros((n_groups, plan.n_rx))
        self.surface_power: dict[int, float] = {}
        self.escaped_power: dict[int, float] = {}

    def add(self, batch: BatchTally, batch_index: int, source: int) -> None:
        """Add one batch of `source` (a transmitter forward, a receiver backward); call in batch order."""
        if batch.link_paths is not None:
            self._add_packed(batch, batch_index)
            return
        ln, m = batch.links, batch.block
        n_samples = batch.n_paths // m
        self.n_paths[ln] += batch.n_paths
        self.n_samples[ln] += n_samples
        self.s1[ln] += batch.s1
        self.s2_samples[ln] += batch.s2
        self.q1[ln] += m * batch.s1
        self.q0[ln] += n_samples * m * m
        g = batch_index % N_GROUPS
        assert batch.h0_groups is not None and batch.h0_group_paths is not None  # set by BatchBuilder.finish
        self.group_paths[g, ln] += batch.n_paths
        turn = (_GROUP_RANGE - group_shift(batch_index, n_samples)) % N_GROUPS  # np.roll's order, as an index
        self.group_h0[:, ln] += batch.h0_groups.T.take(turn, axis=0)
        self.h0_group_paths[:, ln] += batch.h0_group_paths.take(turn)[:, None]
        if batch.h0_sample_max is not None:
            self.sample_max[ln] = np.maximum(self.sample_max[ln], batch.h0_sample_max)
        if len(batch.cir_links):
            cs = self.plan.cir_slots(batch.cir_links)
            self.cir[cs] += batch.cir
            self.early[cs] += batch.early
            self.late[cs] += batch.late
            self.groups[g, cs] += batch.cir
            if batch.cir_groups is not None and self.first_groups is not None:
                self.first_groups[:, cs] += batch.cir_groups
                self.first_group_paths[:, ln] += batch.h0_group_paths[:, None]
            if batch.cir_k is not None:
                assert self.cir_k is not None and self.cir_s is not None and batch.cir_s is not None
                self.cir_k[cs] += batch.cir_k
                self.cir_s[cs] += batch.cir_s
        if len(batch.order_links):
            os_ = self.plan.order_slots(batch.order_links)
            self.order_sum[os_] += batch.order_sum
            self.order_sumsq[os_] += batch.order_sumsq
            self.order_ssum[os_] += batch.order_ssum
            self.order_q1[os_] += m * batch.order_ssum
        if batch.channel_s1 is not None:
            assert batch.channel_s2 is not None
            self.channel_n[:, source] += batch.n_paths
            self.channel_samples[:, source] += n_samples
            self.channel_s1[:, source] += batch.channel_s1
            self.channel_s2[:, source] += batch.channel_s2
            self.channel_q1[:, source] += m * batch.channel_s1
            self.channel_q0[:, source] += n_samples * m * m
        if batch.spectral is not None:
            assert self.spectral is not None, "a spectral batch merged into a grey accumulator"
            self.spectral.add(batch.spectral, group_shift(batch_index, n_samples))
        self.rays_intersect += batch.rays_intersect
        self.rays_occluded += batch.rays_occluded
        self.medium_evaluations += batch.medium_evaluations
        if not self.backward:
            self.surface_power[source] = self.surface_power.get(source, 0.0) + batch.surface_power
            self.escaped_power[source] = self.escaped_power.get(source, 0.0) + batch.escaped_power

    def _add_packed(self, batch: BatchTally, batch_index: int) -> None:
        """Add a packed batch (tally/packed.py): per-link path counts, every path one sample, receivers' paths."""
        assert self.backward and batch.link_paths is not None and batch.sources is not None
        assert batch.h0_groups is not None and batch.h0_group_paths is not None and batch.h0_sample_max is not None
        ln, n = batch.links, batch.link_paths
        self.n_paths[ln] += n
        self.n_samples[ln] += n
        self.s1[ln] += batch.s1
        self.s2_samples[ln] += batch.s2
        self.q1[ln] += batch.s1
        self.q0[ln] += n
        self.group_paths[batch_index % N_GROUPS, ln] += n
        self.group_h0[:, ln] += batch.h0_groups.T
        self.h0_group_paths[:, ln] += batch.h0_group_paths.T
        self.sample_max[ln] = np.maximum(self.sample_max[ln], batch.h0_sample_max)
        if batch.channel_s1 is not None:
            assert batch.channel_s2 is not None
            src, per_source = batch.sources, n[: len(batch.sources)]
            self.channel_n[:, src] += per_source
            self.channel_samples[:, src] += per_source
            self.channel_s1[:, src] += batch.channel_s1
            self.channel_s2[:, src] += batch.channel_s2
            self.channel_q1[:, src] += batch.channel_s1
            self.channel_q0[:, src] += per_source
        self.rays_intersect += batch.rays_intersect
        self.rays_occluded += batch.rays_occluded
        self.medium_evaluations += batch.medium_evaluations

    @property
    def s2(self) -> np.ndarray:
        """(L, 3, 3) per-path second moments of (a, b, c), or their equivalent for blocks (`per_path_s2`)."""
        return per_path_s2(self.n_paths, self.n_samples, self.s1, self.s2_samples, self.q1, self.q0)

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Per link: mean of the per-path (a, b, c) (L, 3) and the covariance of that mean (L, 3, 3)."""
        return mean_cov(self.n_paths, self.s1, self.s2)

    def channel_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Per (group, receiver) of backward runs: mean (G, R, 3) and covariance (G, R, 3, 3) of the channel."""
        s2 = per_path_s2(
            self.channel_n, self.channel_samples, self.channel_s1, self.channel_s2, self.channel_q1, self.channel_q0
        )
        return mean_cov(self.channel_n, self.channel_s1, s2)

    def order_moments(self, order_links: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per order-split slot (links given in slot order): mean gain per (k, s) and the variance of that mean."""
        cell = (slice(None), None, None)
        n, n_samples = self.n_paths.take(order_links)[cell], self.n_samples.take(order_links)[cell]
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(n > 0, self.order_sum / np.maximum(n, 1), 0.0)
        var = sample_cov(
            n,
            n_samples,
            self.order_ssum[..., None],
            self.order_sumsq[..., None, None],
            self.order_q1[..., None],
            self.q0.take(order_links)[cell],
        )[..., 0, 0]
        return mean, np.where(np.isnan(var), var, np.maximum(var, 0.0))
