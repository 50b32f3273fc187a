"""Estimates of every link and of every transmitter group's channel, from the merged tallies.

A link (tx i, rx j) is estimated by the forward paths of transmitter i, the backward paths of
receiver j, or both (algorithm 4): independent estimators of parts of the same quantity, so
their means and covariances add; the exactly known line of sight adds to the mean only.
A group g's channel is the power-weighted sum of its members' links,
    h_gj = sum_i W[g, i] h_ij,  W[g, i] = P_i / sum_{i' in g} P_i'.
Forward estimates of different transmitters are independent (Var adds with W^2); backward
paths from receiver j estimate all its links at once, so the backward part of the channel
has its own per-path moments (tally.BatchBuilder.finish), which carry the correlation.
Means are of the per-path vector (a, b, c) = (sum w, sum w t, sum w t^2): metrics.py turns
them into H0, mean delay and RMS delay spread with standard errors.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from owcsim.engine.tally import reliability
from owcsim.engine.tally.plan import TallyPlan
from owcsim.engine.tally.tally import Accumulator
from owcsim.schemas.algorithms import Direction


def los_moments(los_gain: np.ndarray, los_delay: np.ndarray) -> np.ndarray:
    """(L, 3) exactly known part (a, b, c) = (H, H t, H t^2) of the line of sight."""
    return np.stack([los_gain, los_gain * los_delay, los_gain * los_delay**2], axis=-1)


class Moments(Protocol):
    """A tally of per-link means: Accumulator, or a spectral scene's ChannelAccumulator (one virtual link per
    channel and link)."""

    def moments(self) -> tuple[np.ndarray, np.ndarray]: ...


def link_moments(accs: Mapping[Any, Moments], los_abc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per link: mean (L, 3) and covariance (L, 3, 3) of the estimate, both directions and the LOS."""
    mean, cov = los_abc.copy(), np.zeros(los_abc.shape + (3,))
    for acc in accs.values():
        mu, c = acc.moments()
        mean += mu
        cov += c
    return mean, cov


def channel_moments(
    accs: Mapping[Direction, Accumulator], los_abc: np.ndarray, plan: TallyPlan
) -> tuple[np.ndarray, np.ndarray]:
    """Per (group, receiver): mean (G, R, 3) and covariance (G, R, 3, 3) of the group's channel."""
    w = plan.group_weights
    n_groups, n_tx = w.shape
    n_rx = plan.n_rx
    fwd_mu, fwd_cov = accs[Direction.FORWARD].moments()
    fwd_mu = (fwd_mu + los_abc).reshape(n_tx, n_rx, 3)
    fwd_cov = fwd_cov.reshape(n_tx, n_rx, 3, 3)
    mean = np.einsum("gi,irq->grq", w, fwd_mu)
    cov = np.einsum("gi,irqs->grqs", w * w, fwd_cov)
    bwd_mu, bwd_cov = accs[Direction.BACKWARD].channel_moments()
    if n_groups:
        mean += bwd_mu
        cov += bwd_cov
    return mean, cov


def _rel(mean: np.ndarray, var: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(mean > 0, np.sqrt(np.maximum(var, 0.0)) / mean, 0.0)
    return np.where(np.isnan(var), np.inf, rel)


def reported_rel_stderr(
    accs: Mapping[Direction, Accumulator], los_gain: np.ndarray, scene, plan: TallyPlan, scope: str = "channels"
) -> np.ndarray:
    """Relative standard errors of H0 of what `scope` (simulation.target_scope) names: "channels" every
    group's channel and every link of a transmitter in no group (what the result reports as channels),
    "links" every link, "both" all of them (accuracy mode stops when all are under the target).
    inf where an estimator has fewer than 2 paths; 0 where H0 = 0 exactly."""
    zeros = np.zeros(len(los_gain))
    los_abc = los_moments(los_gain, zeros)
    mean, cov = link_moments(accs, los_abc)
    rel_links = _rel(mean[:, 0], cov[:, 0, 0])
    w = plan.group_weights
    if not w.size or scope == "links":
        return rel_links
    ch_mean, ch_cov = channel_moments(accs, los_abc, plan)
    simulated = scene.masked == ""
    out = [_rel(ch_mean[:, simulated, 0], ch_cov[:, simulated, 0, 0]).ravel()]
    links = np.ones(len(rel_links), bool) if scope == "both" else _solo_links(w, plan.n_rx)
    out.append(rel_links[links])
    return np.concatenate(out)


def _solo_links(w: np.ndarray, n_rx: int) -> np.ndarray:
    """(L,) bool: the links of transmitters in no group (w: (G, n_tx) group weights)."""
    return np.repeat(~(w > 0).any(axis=0), n_rx)


def link_reliability(accs: Mapping[Direction, Accumulator], los_gain: np.ndarray) -> reliability.Reliability:
    """Reliability of every link's H0 error bar (engine/tally/reliability.py), from the batch groups."""
    return reliability.from_accumulators(accs.values(), los_gain)


@dataclass(frozen=True)
class _LinkStats:
    """What the accuracy rule reads of every link: relative standard error of H0, the batch groups' means and
    counts, and the heavy-tail guard's samples and largest-sample shift (reliability.sample_shift)."""

    rel: np.ndarray
    means: np.ndarray
    counts: np.ndarray
    samples: np.ndarray
    shift: np.ndarray

    @classmethod
    def of(cls, accs: Mapping[Direction, Accumulator], los_abc, n_links: int, heavy_tails: bool) -> _LinkStats:
        mean, cov = link_moments(accs, los_abc)
        means, counts = reliability.group_means(accs.values())
        samples, shift = reliability.sample_shift(accs.values())
        if not len(samples) or not heavy_tails:  # nothing traced yet, or no floor and no shift limit
            samples = np.full(n_links, reliability.MIN_SAMPLES if not heavy_tails else 0)
            shift = np.zeros(n_links)
        return cls(_rel(mean[:, 0], cov[:, 0, 0]), means, counts, samples, shift)


@dataclass(frozen=True)
class _ChannelStats:
    """The same of every group's channel, (G, R) each: a channel runs where one of its members' links is served;
    its samples are its fewest among the served members, its shift at most the members' weighted sum."""

    rel: np.ndarray
    group_rel: Any  # reliability.group_reliability of the channels, raveled
    served: np.ndarray
    samples: np.ndarray
    shift: np.ndarray

    @classmethod
    def of(cls, accs, los_abc, los_gain: np.ndarray, plan: TallyPlan, links: _LinkStats, served: np.ndarray):
        w, n_rx = plan.group_weights, plan.n_rx
        n_tx = w.shape[1]
        ch_mean, ch_cov = channel_moments(accs, los_abc, plan)
        means, counts = links.means, links.counts
        g_means = np.einsum("gi,bir->bgr", w, means.reshape(-1, n_tx, n_rx)).reshape(means.shape[0], -1)
        member_counts = np.where(w[:, :, None] > 0, counts.reshape(-1, 1, n_tx, n_rx), np.inf).min(axis=2)
        g_counts = np.where(np.isfinite(member_counts), member_counts, 0.0).reshape(means.shape[0], -1)
        g_los = (w @ los_gain.reshape(n_tx, n_rx)).ravel()
        member = (w > 0)[:, :, None] & served.reshape(1, n_tx, n_rx)
        ch_served = member.any(axis=1)
        ch_samples = np.where(member, links.samples.reshape(1, n_tx, n_rx), np.iinfo(np.int64).max).min(axis=1)
        return cls(
            _rel(ch_mean[..., 0], ch_cov[..., 0, 0]),
            reliability.group_reliability(g_means, g_counts, g_los),
            ch_served,
            np.where(ch_served, ch_samples, 0),
            w @ links.shift.reshape(n_tx, n_rx),
        )


def may_stop(
    accs: Mapping[Direction, Accumulator],
    los_gain: np.ndarray,
    scene,
    plan: TallyPlan,
    target: float,
    served: np.ndarray,
    scope: str = "channels",
    heavy_tails: bool = True,
) -> bool:
    """The accuracy rule (reliability.may_stop) on what `scope` names (see `reported_rel_stderr`): every
    group's channel and every link of a transmitter in no group ("channels"), every link ("links"), or
    both, each on a trusted error bar; `heavy_tails` adds the floor of samples and the largest sample's
    shift (reliability.MIN_SAMPLES, SHIFT_FACTOR: the bounds on optional stopping)."""
    w = plan.group_weights
    los_abc = los_moments(los_gain, np.zeros(len(los_gain)))
    lk = _LinkStats.of(accs, los_abc, len(los_gain), heavy_tails)
    if not w.size or scope == "links":
        rel = reliability.group_reliability(lk.means, lk.counts, los_gain)
        return reliability.may_stop(lk.rel, rel, target, served, lk.samples, lk.shift)
    ch = _ChannelStats.of(accs, los_abc, los_gain, plan, lk, served)
    ok = reliability.may_stop(
        ch.rel.ravel(), ch.group_rel, target, ch.served.ravel(), ch.samples.ravel(), ch.shift.ravel()
    )
    links = np.ones(len(lk.rel), bool) if scope == "both" else _solo_links(w, plan.n_rx)
    if ok and links.any():
        rel = reliability.group_reliability(lk.means[:, links], lk.counts[:, links], los_gain[links])
        ok = reliability.may_stop(lk.rel[links], rel, target, served[links], lk.samples[links], lk.shift[links])
    return ok


def ready_points(
    accs: Mapping[Direction, Accumulator],
    los_gain: np.ndarray,
    scene,
    plan: TallyPlan,
    target: float,
    served: np.ndarray,
    scope: str = "channels",
    heavy_tails: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Per receiver: (ready (R,) bool, worst relative standard error of H0 (R,)) of the quantities `scope` names
    at that receiver (see `reported_rel_stderr`): its links, its group channels, or both. Ready: every one meets
    the accuracy rule of `may_stop` (reliability.ready: the target on a trusted error bar, with the heavy-tail
    floor and shift limit when `heavy_tails`); quantities not served count as ready and as error 0."""
    w = plan.group_weights
    n_rx = plan.n_rx
    n_tx = len(los_gain) // max(n_rx, 1)
    los_abc = los_moments(los_gain, np.zeros(len(los_gain)))
    lk = _LinkStats.of(accs, los_abc, len(los_gain), heavy_tails)
    ready = np.ones(n_rx, bool)
    worst = np.zeros(n_rx)
    links = np.ones(len(lk.rel), bool) if not w.size or scope != "channels" else _solo_links(w, n_rx)
    if links.any():
        rel = reliability.group_reliability(lk.means, lk.counts, los_gain)
        ok = reliability.ready(lk.rel, rel, target, lk.samples, lk.shift) | ~served | ~links
        ready &= ok.reshape(n_tx, n_rx).all(axis=0)
        worst = np.maximum(worst, np.where(served & links, lk.rel, 0.0).reshape(n_tx, n_rx).max(axis=0))
    if w.size and scope != "links":
        ch = _ChannelStats.of(accs, los_abc, los_gain, plan, lk, served)
        ok = reliability.ready(ch.rel.ravel(), ch.group_rel, target, ch.samples.ravel(), ch.shift.ravel())
        ready &= (ok.reshape(ch.rel.shape) | ~ch.served).all(axis=0)
        worst = np.maximum(worst, np.where(ch.served, ch.rel, 0.0).max(axis=0))
    return ready, worst
