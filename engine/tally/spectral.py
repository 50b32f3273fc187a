"""The spectral channel tally: per link, the B bands and the optical, electrical and luminous combinations.

A spectral scene (engine/spectral/spectra.py: `SceneSpectra`) tallies V = B + 3 channels per link
besides the main tally. `ChannelBuilder` sums one batch's estimates per channel, target and path
group (it is the `channels` of tally.BatchBuilder, and its `ChannelBatch` the `spectral` field of
tally.BatchTally); `ChannelAccumulator` merges the batches of a direction (the `spectral` field of
tally.Accumulator, present when the accumulator is made with `n_bands` > 0). Path groups are the
reliability groups of tally.py: sample index mod N_GROUPS (a sample is a path, or a block of
quasi-random paths: engine/core/qmc.py); standard errors come from the spread of the group means.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from owcsim.engine.core.arrays import FloatArray, IntArray
from owcsim.engine.spectral.spectra import SceneSpectra
from owcsim.engine.tally.plan import N_GROUPS
from owcsim.schemas.algorithms import Direction


@dataclass
class ChannelBatch:
    """One batch's channel sums (see ChannelBuilder)."""

    links: IntArray  # (T,) global links of the batch's targets
    n_paths: int
    sums: FloatArray  # (B + 9, T, N_GROUPS): per band w, then per combination w, w t, w t^2
    band_bc: FloatArray  # (2, B, T): per band sums of w t and w t^2
    group_paths: IntArray  # (N_GROUPS,)


class ChannelBuilder:
    """One batch's estimates summed per channel, target and path group (per kernel step, `add`).

    Rows per target and path group: the B bands' power, then the optical, electrical and luminous
    combinations' (w, w t, w t^2). Per band, w t and w t^2 are summed without groups (mean delay and
    delay spread per band, without error bars). Standard errors come from the spread of the N_GROUPS
    path-group means (batch means, 15 degrees of freedom: an error bar good to about 20 %), not from
    per-sample second moments: per-sample sums would cost a scatter per band and estimate, these stay
    small. The whole-spectrum optical gain also has the main tally's per-path error bars (dc_gain)."""

    def __init__(
        self,
        sp: SceneSpectra,
        direction: str,  # a Direction (a str enum) or its value
        source: int,
        tgt: IntArray,
        links: IntArray,
        n_paths: int,
        block: int = 1,
    ):
        self.B, self.T, self.n_paths, self.links = sp.n_bands, len(tgt), n_paths, np.asarray(links, np.int64)
        self.block = block  # paths per independent sample: groups hold whole blocks
        own = np.full(self.T, source, np.int64)
        tx, rx = (own, tgt) if direction == Direction.FORWARD else (tgt, own)
        f = sp.tx_fraction[tx]  # (T, B)
        #: (T, 3, B) weights of the combinations: optical f, electrical f T R, luminous f K_m Vbar
        self.weights = np.stack([f, f * sp.rx_electrical[rx], f * sp.tx_luminous[tx]], axis=1)
        self.sums = np.zeros((self.B + 9) * self.T * N_GROUPS)
        self.band_bc = np.zeros((2, self.B, self.T))

    def add(
        self, target: IntArray, delay: FloatArray, power: FloatArray, ratio: FloatArray, path: IntArray
    ) -> FloatArray:
        """Estimates (m,) of local targets `target`, delays [s], carrier powers, band ratios (B, m) or (0, m)
        (all 1), batch path indices; returns their optical (whole-spectrum) power (m,).

        Per target, the estimates are sorted by path group (a radix sort of m small keys) and each group's
        moments sum_m r_bm p_m t_m^k (k = 0, 1, 2) are one contraction (einsum: no BLAS threads) of its
        ratios with (p, p t, p t^2); the combinations' sums are the weights (3, B) times those band sums
        (they are linear in the bands), and the per-band delay sums are the k = 1, 2 sums over the groups.
        """
        optical = np.zeros(len(power))
        B = self.B
        sums = self.sums.reshape(B + 9, self.T, N_GROUPS)
        for j in range(self.T):  # a loop over target devices
            sel = None if self.T == 1 else np.flatnonzero(target == j)
            p, t, pth = (power, delay, path) if sel is None else (power[sel], delay[sel], path[sel])
            if len(p) == 0:
                continue
            group = ((pth // self.block if self.block > 1 else pth) % N_GROUPS).astype(np.uint8)
            counts = np.bincount(group, minlength=N_GROUPS)
            w = self.weights[j]  # (3, B)
            s = np.zeros((3, B, N_GROUPS))  # sum over a group's estimates of band power x t^k
            if ratio.shape[0]:
                order = np.argsort(group, kind="stable")
                p_o, t_o = p.take(order), t.take(order)
                pt = p_o * t_o
                moments = np.stack([p_o, pt, pt * t_o])  # (3, m)
                r_o = ratio.take(order if sel is None else sel.take(order), axis=1)  # (B, m) by group
                bounds = np.concatenate([[0], np.cumsum(counts)])
                for g in np.flatnonzero(counts):  # a loop over the path groups
                    lo, hi = bounds[g], bounds[g + 1]
                    s[:, :, g] = np.einsum("bm,km->kb", r_o[:, lo:hi], moments[:, lo:hi])
                opt = np.empty(len(p))
                opt[order] = p_o * np.einsum("b,bm->m", w[0], r_o)
            else:  # every ratio 1: each band's sums are the carrier's
                pt = p * t
                for k, x in enumerate((p, pt, pt * t)):
                    s[k] = np.bincount(group, x, N_GROUPS)[None, :]
                opt = p * w[0].sum()
            sums[:B, j] += s[0]
            sums[B:, j] += np.einsum("cb,kbg->kcg", w, s).reshape(9, N_GROUPS)
            self.band_bc[:, :, j] += s[1:].sum(axis=2)
            if sel is None:
                optical = opt
            else:
                optical[sel] = opt
        return optical

    def finish(self) -> ChannelBatch:
        paths = np.bincount(np.arange(self.n_paths) // self.block % N_GROUPS, minlength=N_GROUPS)
        return ChannelBatch(
            self.links, self.n_paths, self.sums.reshape(self.B + 9, self.T, N_GROUPS), self.band_bc, paths
        )


def _group_moments(sums: FloatArray, paths: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Mean per path (Q, L) of Q quantities and the covariance of those means (L, Q, Q) from group sums
    (Q, L, G) and paths per group (L, G): sum_g (m_g - m)(m_g - m)^T / (G (G - 1)) over the groups with paths."""
    n = paths.sum(axis=1)
    live = paths > 0
    g = live.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, sums.sum(axis=2) / np.maximum(n, 1), 0.0)
        dev = np.where(live[None], sums / np.where(live, paths, 1.0)[None] - mean[:, :, None], 0.0)
        cov = np.einsum("qlg,rlg->lqr", dev, dev) / np.maximum(g * (g - 1), 1)[:, None, None]
    return mean, np.where((g >= 2)[:, None, None], cov, np.where((n > 0)[:, None, None], np.nan, 0.0))


class ChannelAccumulator:
    """A direction's channel sums over the job (`Accumulator.spectral`); `moments` as Accumulator's
    (estimates.link_moments)."""

    def __init__(self, n_bands: int, n_links: int):
        self.B, self.L = n_bands, n_links
        self.sums = np.zeros((n_bands + 9, n_links, N_GROUPS))
        self.band_bc = np.zeros((2, n_bands, n_links))
        self.paths = np.zeros((n_links, N_GROUPS))

    def add(self, batch: ChannelBatch, shift: int = 0) -> None:
        """Add a batch whose path group 0 is the job's group `shift` (plan.group_shift)."""
        self.sums[:, batch.links] += np.roll(batch.sums, shift, axis=2)
        self.band_bc[:, :, batch.links] += batch.band_bc
        self.paths[batch.links] += np.roll(batch.group_paths, shift)[None, :]

    def moments(self) -> tuple[FloatArray, FloatArray]:
        """Per virtual link (channel-major, V L): mean per path of (a, b, c) (V L, 3) and its covariance
        (V L, 3, 3); for the bands only the variance of a is known (the rest NaN)."""
        B, L = self.B, self.L
        mean, cov = np.zeros((B + 3, L, 3)), np.full((B + 3, L, 3, 3), np.nan)
        band_a, band_var = _group_moments(self.sums[:B], self.paths)
        n = self.paths.sum(axis=1)
        mean[:B, :, 0] = band_a
        with np.errstate(invalid="ignore", divide="ignore"):
            mean[:B, :, 1:] = np.where(n > 0, self.band_bc / np.maximum(n, 1), 0.0).transpose(1, 2, 0)
        cov[:B, :, 0, 0] = np.diagonal(band_var, axis1=1, axis2=2).T
        for c in range(3):  # optical, electrical, luminous
            m, cv = _group_moments(self.sums[[B + c, B + 3 + c, B + 6 + c]], self.paths)
            mean[B + c], cov[B + c] = m.T, cv
        return mean.reshape(-1, 3), cov.reshape(-1, 3, 3)
