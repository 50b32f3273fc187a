"""The accuracy rule (engine/tally/reliability.py): no stop before a planted rare spike is seen, a prompt stop on
light tails, and `simulation.target_scope` (what the target holds on: channels, links or both)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from owcsim.engine.run.simulate import simulate
from owcsim.engine.tally import reliability as R
from owcsim.schemas import SceneSpec
from tests.scenes import room_doc

N_GROUPS = 16


def first_stop(x: np.ndarray, target: float, new: bool = True, check: int = 16) -> tuple[int, float]:
    """(samples at the stop, estimate) of one run whose independent samples are x, checked every `check`
    samples (groups: sample index mod 16, as engine/tally/tally.py fills them); (len(x), mean) if it never stops."""
    cs, cs2, cmax = np.cumsum(x), np.cumsum(x * x), np.maximum.accumulate(x)
    for n in range(check, len(x) + 1, check):
        mean = cs[n - 1] / n
        rel_se = np.sqrt(max(cs2[n - 1] - n * mean**2, 0.0) / (n - 1) / n) / mean
        g = np.arange(n) % N_GROUPS
        sums, paths = np.bincount(g, x[:n], N_GROUPS), np.bincount(g, minlength=N_GROUPS).astype(float)
        rel = R.group_reliability((sums / paths)[:, None], paths[:, None])
        if new:
            ok = R.ready([rel_se], rel, target, [n], [(cmax[n - 1] - mean) / n])
        else:
            ok = R.ready([rel_se], rel, target)
        if ok[0]:
            return n, float(mean)
    return len(x), float(cs[-1] / len(x))


def test_no_stop_before_a_planted_spike_within_the_floor_is_seen():
    """Light samples (CV 2 %) meet a 1 % target after a few; a spike of 60x the mean at sample 40 carries
    ~1/3 of the mean over the first 100 samples. The old rule (no floor, no shift test) stops blind at
    the first check and misses it (the test's power); the new rule runs past it, and once it has seen it
    goes on until that one sample moves the estimate by at most half the target."""
    rng = np.random.default_rng(3)
    x = 1.0 + 0.02 * rng.standard_normal(40_000)
    x[40] += 60.0
    n_old, est_old = first_stop(x, 0.01, new=False)
    assert n_old <= 40 and abs(est_old - 1.0) < 0.01  # stopped before the spike: it never saw it
    n_new, est_new = first_stop(x, 0.01)
    assert n_new > 40
    # the stop itself: the spike's shift (60 - ~1) / n at most 0.5 % of the estimate, and not long after
    assert (x[40] - est_new) / n_new <= R.SHIFT_FACTOR * 0.01 * est_new
    assert (x[40] - est_new) / (n_new - 16) > R.SHIFT_FACTOR * 0.01 * est_new * 0.98
    assert est_new == pytest.approx(1.0 + 60.0 / n_new, rel=1e-3)


def test_a_spike_in_the_floor_is_seen_wherever_it_lands():
    """Whatever its place among the first MIN_SAMPLES samples, the spike is in the estimate at the stop."""
    rng = np.random.default_rng(4)
    base = 1.0 + 0.02 * rng.standard_normal(20_000)
    for at in range(0, R.MIN_SAMPLES, 7):
        x = base.copy()
        x[at] += 30.0
        n, est = first_stop(x, 0.01)
        assert n > at and est > 1.0 + 0.9 * 30.0 / n


def test_light_tails_stop_promptly():
    """Gamma(4) samples (CV 0.5, skewness 1): at a 2 % target the old rule stops near (0.5 / 0.02)^2 = 625
    samples, far above the floor; the new rule stops at the same check in most runs, never > 1.25x later."""
    rng = np.random.default_rng(5)
    ratios = []
    for _ in range(40):
        x = rng.gamma(4.0, 1.0, 4000)
        n_old, _ = first_stop(x, 0.02, new=False)
        n_new, _ = first_stop(x, 0.02)
        assert n_old >= R.MIN_SAMPLES
        ratios.append(n_new / n_old)
    ratios = np.array(ratios)
    assert np.mean(ratios == 1.0) >= 0.9 and ratios.max() <= 1.25


def test_the_floor_counts_independent_samples():
    """A link below MIN_SAMPLES samples, or whose largest sample moves H0 by more than half the target,
    is not ready; at the floor with a small shift it is."""
    g = np.ones((N_GROUPS, 3))
    rel = R.group_reliability(g, np.full((N_GROUPS, 3), 8.0))
    ok = R.ready([0.005] * 3, rel, 0.01, [R.MIN_SAMPLES - 1, R.MIN_SAMPLES, R.MIN_SAMPLES], [0.0, 0.0, 0.006])
    assert ok.tolist() == [False, True, False]


def test_sample_shift_from_the_tallies(monkeypatch):
    """A batch of 16 blocks has one block per path group, so its group sums are the samples: the tally's
    largest sample (BatchTally.h0_sample_max) and the job's `sample_shift` checked against them."""
    from owcsim.engine.tally.tally import Accumulator

    seen: dict[int, tuple] = {}
    real = Accumulator.add

    def spy(self, batch, batch_index, source):
        seen.setdefault(id(self), (self, []))[1].append(batch)
        return real(self, batch, batch_index, source)

    monkeypatch.setattr(Accumulator, "add", spy)
    doc = room_doc(paths=4 * 4096, batch_size=4096, direction="backward", quasi_random=True)
    simulate(SceneSpec.model_validate(doc))
    (acc, batches), *_ = [v for v in seen.values() if v[1]]
    assert all(b.block == 256 and b.n_paths == 4096 for b in batches)
    samples = np.concatenate([b.h0_groups[0] / 256 for b in batches])  # 64 per-path block means
    for b in batches:
        assert b.h0_sample_max[0] == pytest.approx(b.h0_groups[0].max() / 256, rel=1e-12)
    n, shift = R.sample_shift([acc])
    assert n[0] == 64
    assert shift[0] == pytest.approx((samples.max() - samples.mean()) / 64, rel=1e-9)


# --- simulation.target_scope ----------------------------------------------------------------------------
def _grouped(scope: str) -> dict:
    """Two equal transmitters in one group, forward paths (independent per transmitter), one receiver: the
    group's channel (their mean) has ~1/sqrt(2) of each link's relative error."""
    doc = room_doc(max_reflections=2, paths=None, target_rel_error=1e-3, direction="forward", batch_size=4096, seed=11)
    doc["simulation"]["target_scope"] = scope
    tx = doc["transmitters"][0]
    doc["transmitters"] = [
        {**tx, "id": "a", "position": [2.0, 2.5, 3.0]},
        {**tx, "id": "b", "position": [3.0, 2.5, 3.0]},
    ]
    doc["transmitter_groups"] = [{"name": "ab", "transmitters": ["a", "b"]}]
    return doc


def _errors(res) -> tuple[float, float]:
    """(worst link's, the channel's) stderr(H0) / H0."""
    links = max(link.dc_gain_stderr / link.dc_gain for link in res.links)
    ch = res.channels[0]
    return links, ch.dc_gain_stderr / ch.dc_gain


@pytest.fixture(scope="module")
def scoped():
    return {s: simulate(SceneSpec.model_validate(_grouped(s))) for s in ("channels", "links", "both")}


def test_target_scope_channels_stops_on_the_channel(scoped):
    res = scoped["channels"]
    links, ch = _errors(res)
    assert str(res.run.stop_reason) == "target_reached"
    assert ch <= 1e-3 and links > 1e-3  # the links were not asked to meet it (and do not)
    assert res.run.max_dc_gain_rel_stderr == pytest.approx(ch)


@pytest.mark.parametrize("scope", ["links", "both"])
def test_target_scope_links_and_both_hold_on_every_link(scoped, scope):
    res = scoped[scope]
    links, ch = _errors(res)
    assert str(res.run.stop_reason) == "target_reached"
    assert links <= 1e-3 and ch <= 1e-3
    assert res.run.max_dc_gain_rel_stderr == pytest.approx(max(links, ch) if scope == "both" else links)
    assert res.run.paths_total > scoped["channels"].run.paths_total


def test_target_scope_is_in_the_schema():
    doc = json.loads(json.dumps(_grouped("links")))
    doc["simulation"]["target_scope"] = "every link"
    with pytest.raises(ValueError, match="target_scope"):
        SceneSpec.model_validate(doc)


# --- the 60-seed study (slow) -------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("case", ["far", "near"])
def test_sixty_seeds_at_one_percent(case):
    """benchmarks/stopping_study.py's after rows: the smoky room at g = 0.9, defaults, 1 %: at least 57 of 60
    runs within 2 x the target of a long fixed-budget reference (other seeds; fixed paths have no optional
    stopping), and the mean error below a third of the target. Before the rule (main, same seeds): far 58/60,
    -0.24 % +- 0.12 %; near 57/60, -0.19 % +- 0.12 %: those rows meet these bounds too, barely, so this test
    guards the issue's criteria, it does not tell the rules apart (the fast tests above do, on planted spikes).
    45-60 s per case on an idle core."""
    from benchmarks.stopping_study import TARGET, run, scene

    ref = np.array(
        [
            run(
                scene(
                    case, 1_000_000 + k, algorithm=5, max_reflections=40, max_scattering=40, t_max_s=3e-7, paths=400_000
                )
            )["h0"]
            for k in range(6)
        ]
    )
    h0, ref_se = ref.mean(), ref.std(ddof=1) / np.sqrt(len(ref))
    assert ref_se / h0 < TARGET / 10
    err = np.array([run(scene(case, seed, target_rel_error=TARGET))["h0"] / h0 - 1 for seed in range(60)])
    assert (np.abs(err) <= 2 * TARGET).sum() >= 57
    assert abs(err.mean()) < TARGET / 3
