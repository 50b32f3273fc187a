"""Tallies: what one batch of paths adds, and the ordered merge of batches.

A batch records every connection (next-event estimate) as a contribution
(target, cell of (target, reflection order k, scattering order s), delay t [s],
power w per watt, path).
It reduces them with `np.bincount` on flat indices into:
- `cir`: power per (link, k, s, time bin) inside the window;
- `early` / `late`: power arriving before t_min / after t_max, per (link, k, s);
- `order_sum`, `order_sumsq`: sum of w and w^2 per (link, k, s) — each path makes
  at most one contribution per (target, k, s), so these are per-path moments;
- `s1`, `s2`: per-path sums a = sum w, b = sum w t, c = sum w t^2 per link, and
  the sums of their outer products (for delta-method standard errors of delays).
Batches are merged in batch order, so results are bit-identical whatever the
number of workers. Groups (batch index mod N_GROUPS) keep per-bin power for
batch-spread standard errors and jackknife.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Number of batch groups kept for per-bin standard errors and the jackknife.
N_GROUPS = 16


@dataclass
class TimeBins:
    """Bins of width `dt` [s] from `t_min` [s]; `n` bins."""

    t_min: float
    dt: float
    n: int

    @property
    def edges(self) -> np.ndarray:
        return self.t_min + self.dt * np.arange(self.n + 1)


@dataclass
class BatchTally:
    """What one batch adds; arrays over the batch's local links (global ids in `links`)."""

    links: np.ndarray  # (L,)
    n_paths: int
    cir: np.ndarray  # (L, K+1, S+1, n_bins)
    early: np.ndarray  # (L, K+1, S+1)
    late: np.ndarray  # (L, K+1, S+1)
    order_sum: np.ndarray  # (L, K+1, S+1)
    order_sumsq: np.ndarray  # (L, K+1, S+1)
    s1: np.ndarray  # (L, 3)
    s2: np.ndarray  # (L, 3, 3)
    rays_intersect: int = 0
    rays_occluded: int = 0
    surface_power: float = 0.0  # incident power on surfaces (forward paths) [W/W]
    escaped_power: float = 0.0  # power of rays that left the scene [W/W]
    medium_evaluations: int = 0


def reduce_contributions(links, n_paths, bins: TimeBins, n_orders: int, n_scatter: int,
                         target, cell, delay, power, path, several_per_cell: bool = False) -> BatchTally:
    """Bin a batch's contributions into a BatchTally.

    1-D arrays of equal length: `target` (local link index), `cell` = (target * n_orders
    + k) * n_scatter + s, `delay` [s], `power` [W/W], `path` (index in the batch).
    `several_per_cell`: a path may add several contributions to one cell (points
    along segments); they are summed per (path, cell) before squaring.
    """
    n_links = len(links)
    shape_kl = (n_links, n_orders, n_scatter)
    n_cells = n_links * n_orders * n_scatter
    b = (delay - bins.t_min) * (1.0 / bins.dt)
    inside = (b >= 0) & (b < bins.n)
    if inside.all():
        cir = np.bincount(cell * bins.n + b.astype(np.int64), power, n_cells * bins.n)
        early = late = np.zeros(n_cells)
    else:  # only bins inside the window are cast (a far arrival's index may not fit an int64)
        sel = np.flatnonzero(inside)
        cir = np.bincount(cell.take(sel) * bins.n + b.take(sel).astype(np.int64), power.take(sel), n_cells * bins.n)
        early = np.bincount(cell, np.where(b < 0, power, 0.0), n_cells)
        late = np.bincount(cell, np.where(b >= bins.n, power, 0.0), n_cells)
    order_sum = np.bincount(cell, power, n_cells)
    if several_per_cell and len(cell):
        keys, inverse = np.unique(path * n_cells + cell, return_inverse=True)
        per_path_cell = np.bincount(inverse, power, len(keys))
        order_sumsq = np.bincount(keys % n_cells, per_path_cell * per_path_cell, n_cells)
    else:
        order_sumsq = np.bincount(cell, power * power, n_cells)
    # Per-path sums per link, then their first and second moments over paths.
    key = target * n_paths + path
    wt = power * delay
    abc = np.stack([np.bincount(key, w, n_paths * n_links) for w in (power, wt, wt * delay)])
    abc = abc.reshape(3, n_links, n_paths).transpose(1, 0, 2)  # (L, 3, paths)
    s1 = abc.sum(axis=2)
    s2 = np.matmul(abc, abc.transpose(0, 2, 1))
    return BatchTally(
        links=np.asarray(links), n_paths=n_paths,
        cir=cir.reshape(*shape_kl, bins.n), early=early.reshape(shape_kl), late=late.reshape(shape_kl),
        order_sum=order_sum.reshape(shape_kl), order_sumsq=order_sumsq.reshape(shape_kl), s1=s1, s2=s2)


@dataclass
class Accumulator:
    """Sums of batch tallies over the whole job, per global link."""

    n_links: int
    n_orders: int
    n_scatter: int
    bins: TimeBins
    n_paths: np.ndarray = field(init=False)
    cir: np.ndarray = field(init=False)
    groups: np.ndarray = field(init=False)  # (N_GROUPS, n_links, n_bins), summed over k, s
    group_paths: np.ndarray = field(init=False)  # (N_GROUPS, n_links)
    rays_intersect: int = 0
    rays_occluded: int = 0
    medium_evaluations: int = 0

    def __post_init__(self):
        kl = (self.n_links, self.n_orders, self.n_scatter)
        self.n_paths = np.zeros(self.n_links, np.int64)
        self.cir = np.zeros((*kl, self.bins.n))
        self.early = np.zeros(kl)
        self.late = np.zeros(kl)
        self.order_sum = np.zeros(kl)
        self.order_sumsq = np.zeros(kl)
        self.s1 = np.zeros((self.n_links, 3))
        self.s2 = np.zeros((self.n_links, 3, 3))
        self.groups = np.zeros((N_GROUPS, self.n_links, self.bins.n))
        self.group_paths = np.zeros((N_GROUPS, self.n_links), np.int64)
        self.surface_power: dict[int, float] = {}
        self.escaped_power: dict[int, float] = {}

    def add(self, batch: BatchTally, batch_index: int, source: int | None = None) -> None:
        """Add one batch; call in batch order for bit-identical sums."""
        ln = batch.links
        self.n_paths[ln] += batch.n_paths
        for name in ("cir", "early", "late", "order_sum", "order_sumsq", "s1", "s2"):
            getattr(self, name)[ln] += getattr(batch, name)
        g = batch_index % N_GROUPS
        self.groups[g, ln] += batch.cir.sum(axis=(1, 2))
        self.group_paths[g, ln] += batch.n_paths
        self.rays_intersect += batch.rays_intersect
        self.rays_occluded += batch.rays_occluded
        self.medium_evaluations += batch.medium_evaluations
        if source is not None:
            self.surface_power[source] = self.surface_power.get(source, 0.0) + batch.surface_power
            self.escaped_power[source] = self.escaped_power.get(source, 0.0) + batch.escaped_power

    def per_path(self, x: np.ndarray) -> np.ndarray:
        """A per-link sum divided by the link's path count (0 for links this accumulator does not serve)."""
        n = self.n_paths.astype(float).reshape((-1,) + (1,) * (x.ndim - 1))
        return np.where(n > 0, x / np.maximum(n, 1.0), 0.0)

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Per link: mean of the per-path (a, b, c) (L, 3) and the covariance of that mean (L, 3, 3).

        Links with no path here get zeros (they add nothing when accumulators combine);
        links with one path get NaN covariance (no error estimate).
        """
        n = self.n_paths.astype(float)[:, None, None]
        mu = self.per_path(self.s1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cov = (self.s2 - n * mu[:, :, None] * mu[:, None, :]) / np.maximum(n - 1, 1) / np.maximum(n, 1)
        cov = np.where(n >= 2, cov, np.where(n > 0, np.nan, 0.0))
        return mu, cov

    def order_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Per (link, k, s): mean gain per path and the variance of that mean."""
        n = self.n_paths.astype(float)[:, None, None]
        mean = self.per_path(self.order_sum)
        var = np.maximum(self.per_path(self.order_sumsq) - mean**2, 0.0) / np.maximum(n - 1, 1)
        return mean, np.where(n >= 2, var, np.where(n > 0, np.nan, 0.0))


def combined_rel_stderr(accs, los: np.ndarray) -> np.ndarray:
    """Relative standard error of H0 per link over independent accumulators.

    inf where a serving accumulator has fewer than 2 paths; 0 where H0 = 0 exactly.
    """
    mean = los.astype(float).copy()
    var = np.zeros_like(mean)
    for acc in accs:
        mu, cov = acc.moments()
        mean += mu[:, 0]
        var += cov[:, 0, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(mean > 0, np.sqrt(np.maximum(var, 0.0)) / mean, 0.0)
    return np.where(np.isnan(var), np.inf, rel)
