"""How far a reported standard error can itself be trusted, and when an accuracy run may stop.

Monte Carlo error bars are estimates: under heavy tails (connections to point-like
devices, physics.md section 4) a run that has not yet drawn its rare large
contributions reports an error that is too small, and an accuracy run that stops on
it stops on a lucky batch. These functions look at the estimate through G independent
path groups (sample index mod G, filled in turn from the first batch; engine/tally/tally.py) and
report, per link:

- `max_group_share`: the largest single group's share of sum_g n_g |x_g| (x_g the
  group's per-path estimate, n_g its paths); 1/G for identical groups, near 1 when
  one group holds a spike the others lack;
- `effective_groups`: (sum_g n_g x_g)^2 / sum_g (n_g x_g)^2 (Kish 1965), G for
  identical groups, ~1 when one group dominates;
- `group_rel_stderr`: the relative standard error of H0 from the spread of the group
  estimates (batch means; independent of the samples' second moments);
- `stderr_rel_error`: the relative error of that standard error,
      0.5 sqrt(2 / (G - 1) + kappa / G),
  kappa the excess kurtosis of the group estimates (clipped at 0; the variance of a
  sample variance is sigma^4 (2 / (G - 1) + kappa / G), e.g. Cramer 1946 section 27.4,
  and the delta method halves it for the standard error).

`may_stop` is the accuracy rule: the relative standard error (tally.sample_cov) at or below the
target is not enough; the group spread must agree (within `GROUP_SLACK`), enough groups
must be filled, no single group may dominate and the error bar's own relative error
must be small. `warnings` turns the same figures into result warnings.

Optional stopping. A run that stops when its error bar first looks small selects the runs whose
error bar is small by chance; with a heavy right tail those are the runs that have not yet drawn
a rare large sample, so they stop low (issue 22: -0.2 to -0.4 % of H0 at a 1 % target in g = 0.9
smoke, every run stopping at its first check; the bias of such a rule is about minus the skewness
of the estimate at the stop, Woodroofe 1982 ch. 10). In a scene with a medium (estimates.may_stop
`heavy_tails`) two more conditions bound it:
- at least `MIN_SAMPLES` independent samples per direction (the floor fixed-budget runs use for
  their error bars, schemas/simulation.py `quasi_random`): below it nearly every run may stop at
  its first check, and the selection acts on a handful of samples;
- `sample_shift`: no single sample may move H0 by more than `SHIFT_FACTOR` x the target. A rare
  contribution that has been seen once moves the estimate by its whole weight; the run goes on
  until it is one of several, and with it the contributions of its size are resolved.
benchmarks/stopping_study.py measures the rule (docs/smoke-error-bars.md, "Optional stopping").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Fewest non-empty batch groups before an accuracy run may stop (the spread of fewer is itself too noisy).
MIN_GROUPS = 8
#: A group holding more than this multiple of its fair share 1/G of the estimate is a spike.
SHARE_FACTOR = 2.5
#: The group-spread error may exceed the target by this factor (its own noise is ~1/sqrt(2 (G - 1))).
GROUP_SLACK = 1.5
#: Largest relative error of the standard error for a trusted error bar.
MAX_STDERR_REL_ERROR = 0.5
#: Fewest independent samples (paths, or blocks of quasi-random paths: engine/core/qmc.py) of every direction
#: serving a link before an accuracy run may stop.
MIN_SAMPLES = 64
#: The most one independent sample may move H0, as a fraction of the target, when an accuracy run stops.
SHIFT_FACTOR = 0.5


@dataclass(frozen=True)
class Reliability:
    """Per-link reliability figures of the H0 error bar (arrays over links)."""

    groups: np.ndarray  # (L,) non-empty groups
    estimate: np.ndarray  # (L,) H0 from the groups (in-window power + LOS)
    group_rel_stderr: np.ndarray  # (L,)
    max_group_share: np.ndarray  # (L,)
    effective_groups: np.ndarray  # (L,)
    stderr_rel_error: np.ndarray  # (L,)

    def trusted(self) -> np.ndarray:
        """(L,) bool: enough groups, no dominant group, a stable error bar."""
        fair = 1.0 / np.maximum(self.groups, 1)
        return (
            (self.groups >= MIN_GROUPS)
            & (self.max_group_share <= SHARE_FACTOR * fair)
            & (self.stderr_rel_error <= MAX_STDERR_REL_ERROR)
        )


def group_reliability(group_means, group_paths, los=None) -> Reliability:
    """Reliability figures from per-group per-path estimates.

    group_means: (G, L) each group's own per-path estimate of H0 (summed over
    directions, without the exact LOS term); group_paths: (G, L) its paths (weights);
    los: (L,) exact line-of-sight gain added to every group's estimate.
    Groups with no path are ignored.
    """
    x = np.asarray(group_means, float)
    n = np.asarray(group_paths, float)
    if los is not None:
        x = x + np.asarray(los, float)[None, :]
    used = n > 0
    G = used.sum(axis=0)
    w = np.where(used, n, 0.0)
    wsum = np.maximum(w.sum(axis=0), 1e-300)
    mean = (w * x).sum(axis=0) / wsum
    dev = np.where(used, x - mean, 0.0)
    # batch means with unequal weights: var(mean) = sum w^2 (x - m)^2 / (sum w)^2 * G / (G - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        var_mean = (w * w * dev * dev).sum(axis=0) / wsum**2 * G / np.maximum(G - 1, 1)
        rel = np.where(mean > 0, np.sqrt(var_mean) / mean, np.where(var_mean > 0, np.inf, 0.0))
        mass = np.where(used, w * np.abs(x), 0.0)
        share = np.where(mass.sum(axis=0) > 0, mass.max(axis=0) / mass.sum(axis=0), 1.0 / np.maximum(G, 1))
        contrib = w * x
        eff = np.where((contrib**2).sum(axis=0) > 0, contrib.sum(axis=0) ** 2 / (contrib**2).sum(axis=0), G)
        m2 = (np.where(used, dev**2, 0.0)).sum(axis=0) / np.maximum(G, 1)
        m4 = (np.where(used, dev**4, 0.0)).sum(axis=0) / np.maximum(G, 1)
        kurt = np.where(m2 > 0, m4 / m2**2 - 3.0, 0.0)
        se_err = 0.5 * np.sqrt(2.0 / np.maximum(G - 1, 1) + np.maximum(kurt, 0.0) / np.maximum(G, 1))
    se_err = np.where(G >= 2, se_err, np.inf)
    rel = np.where(G >= 2, rel, np.inf)
    return Reliability(
        groups=G,
        estimate=mean,
        group_rel_stderr=rel,
        max_group_share=share,
        effective_groups=eff,
        stderr_rel_error=se_err,
    )


def group_means(accs) -> tuple[np.ndarray, np.ndarray]:
    """Per path group and link (engine/tally/tally.py Accumulator: group_h0, h0_group_paths (G, L)): the group's
    per-path H0 estimate summed over the directions serving the link, and its weight (a group counts for a
    link only when every direction serving the link filled it)."""
    accs = list(accs)
    served = [a for a in accs if a.n_paths.any()]
    if not served:
        n_links = accs[0].n_links if accs else 0
        return np.zeros((1, n_links)), np.zeros((1, n_links))
    means = np.zeros(served[0].group_h0.shape)
    counts = np.zeros(served[0].group_h0.shape)
    for a in served:  # a loop over the (at most two) directions
        means = means + np.where(a.h0_group_paths > 0, a.group_h0 / np.maximum(a.h0_group_paths, 1), 0.0)
        counts = counts + np.where((a.n_paths > 0)[None, :], a.h0_group_paths.astype(float), 0.0)
    filled = np.all([(a.h0_group_paths > 0) | (a.n_paths == 0)[None, :] for a in served], axis=0)
    return means, np.where(filled, counts / len(served), 0.0)


def group_dc_gain(accs, los_gain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per link and path group (n_links, G): the group's H0 estimate, `group_means` plus the exact line of sight
    `los_gain` (n_links,), and the group's weight (0: empty). The groups of runs with one seed hold the same
    samples: the spread of two runs' differences is the error of their difference (engine/results/timeline.py)."""
    means, counts = group_means(accs)
    return (means + los_gain[None, :]).T, counts.T


def from_accumulators(accs, los=None) -> Reliability:
    """`group_reliability` of merged tallies (see `group_means`)."""
    means, counts = group_means(accs)
    return group_reliability(means, counts, los)


def sample_shift(accs) -> tuple[np.ndarray, np.ndarray]:
    """Per link: (fewest samples of the directions serving it, the most one sample moves H0 [W/W]).

    Replacing a direction's largest sample (per-path estimate x_max, engine/tally/tally.py
    Accumulator.sample_max) by that direction's mean x_bar moves its estimate by (x_max - x_bar) / B
    (B its independent samples, all of the same paths); the shift sums this over the directions.
    Links no direction serves: 0 samples, shift 0.
    """
    accs = [a for a in accs if a.n_paths.any()]
    if not accs:
        return np.zeros(0, np.int64), np.zeros(0)
    samples = np.full(accs[0].n_links, np.iinfo(np.int64).max)
    shift = np.zeros(accs[0].n_links)
    for a in accs:  # a loop over the (at most two) directions
        b = a.n_samples
        mean = a.s1[:, 0] / np.maximum(a.n_paths, 1)
        shift = shift + np.where(b > 0, np.maximum(a.sample_max - mean, 0.0) / np.maximum(b, 1), 0.0)
        samples = np.where(b > 0, np.minimum(samples, b), samples)
    return np.where(samples == np.iinfo(np.int64).max, 0, samples), shift


def may_stop(rel_stderr, rel: Reliability, target: float, served=None, samples=None, shift=None) -> bool:
    """The accuracy rule: stop only when every served link meets the target on a trusted error bar.

    rel_stderr: (L,) per-path relative standard error of H0 (estimates._rel of the merged moments);
    served: (L,) bool, links that run (others are ignored); samples: (L,) fewest independent samples
    of a direction serving the link (at least MIN_SAMPLES); shift: (L,) the most one sample moves H0
    [W/W] (`sample_shift`; at most SHIFT_FACTOR x target x H0).
    """
    rel_stderr = np.asarray(rel_stderr, float)
    mask = np.ones(len(rel_stderr), bool) if served is None else np.asarray(served, bool)
    if not mask.any():
        return True
    return bool(ready(rel_stderr, rel, target, samples, shift)[mask].all())


def ready(rel_stderr, rel: Reliability, target: float, samples=None, shift=None) -> np.ndarray:
    """(L,) bool: the links that meet the accuracy rule (`may_stop`, its arguments)."""
    ok = (np.asarray(rel_stderr, float) <= target) & (rel.group_rel_stderr <= GROUP_SLACK * target) & rel.trusted()
    if samples is not None:
        ok &= np.asarray(samples) >= MIN_SAMPLES
    if shift is not None:
        ok &= np.asarray(shift, float) <= SHIFT_FACTOR * target * np.abs(rel.estimate)
    return ok


def warnings(rel: Reliability, ids=None, limit: int = 3, sampled: Reliability | None = None) -> list[str]:
    """Result warnings for links whose H0 error bar is itself unreliable (at most one message).

    `rel`: figures of H0 (exact line of sight included); `sampled`: the same without it, the part the error bar
    comes from (`from_accumulators(accs)`), where a strong line of sight no longer hides a few groups holding it
    all. A traced link (groups > 0) at 0 +- 0 counts too: no path reached it, which is not a zero with certainty
    (links the engine proves unreachable, masked or exact are not traced).
    """
    whole = ~rel.trusted() & (rel.estimate > 0) & (rel.groups > 0)  # groups 0: link not traced
    only_sampled = np.zeros_like(whole)
    if sampled is not None:  # spiky once the exact line of sight is left aside
        only_sampled = ~whole & ~sampled.trusted() & (sampled.estimate > 0) & (sampled.groups > 0)
    spiky = whole | only_sampled
    unreached = (rel.estimate == 0) & (rel.groups > 0)
    bad = np.flatnonzero(spiky | unreached)
    if not len(bad):
        return []
    names = [ids[i] if ids is not None else f"link {i}" for i in bad[:limit]]
    head = f"{len(bad)} link(s) have an unreliable error bar on H0 (e.g. {', '.join(names)})"
    parts = []
    if spiky.any():
        j = np.flatnonzero(spiky)[0]
        fig = sampled if only_sampled[j] and sampled is not None else rel
        parts.append(
            f"{int(fig.groups[j])} batch groups, the largest carries {fig.max_group_share[j]:.0%} of the "
            f"{'estimate' if fig is rel else 'sampled part (line of sight aside)'} "
            f"(fair share {1 / max(int(fig.groups[j]), 1):.0%}), effective groups {fig.effective_groups[j]:.1f}, "
            f"the standard error itself is uncertain by ~{fig.stderr_rel_error[j]:.0%}"
        )
    if unreached.any():
        parts.append(f"{int(unreached.sum())} at 0 +- 0, which no path reached: not a zero with certainty")
    advice = "run more paths (or another seed) before quoting it"
    if unreached.any() or only_sampled.any():
        advice += (
            ", or run from the other side (simulation.direction: a receiver with a narrow field of view or next "
            "to a surface is best sampled from its own side, 'backward')"
        )
    return [f"{head}: {'; '.join(parts)}; {advice}"]
