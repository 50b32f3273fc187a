"""Per-bin standard errors of the binned CIR (`cir.total_stderr`) for runs of a single batch.

A run of one batch has one batch group; its per-bin errors come from the batch's path groups (sample index
mod 16, tally.TallyPlan.first_batch_groups). The check is independent of the code's error formula: the
reported per-bin variance, averaged over seeds, against the spread of the per-bin values over those seeds."""

import numpy as np
import pytest

from tests.results import simulate_document as simulate
from tests.scenes import SMOKE, open_doc, room_doc, spec

SEEDS = 60
# backward from the receiver, K = 3: next-event estimates toward the ceiling transmitter carry cos^m at the
# transmitter (no 1/d^2 peak on the ceiling), so the per-bin values are light-tailed and 60 seeds measure
# their spread to about 5 % (the bootstrap below)
ONE_BATCH = dict(algorithm=1, max_reflections=3, paths=4096, time_bin_s=1e-9, t_max_s=6e-8, direction="backward")


def _cir(res):
    link = res["links"][0]
    c = link["cir"]
    se = np.array([np.nan if x is None else x for x in c["total_stderr"]])
    return link, np.asarray(c["total"]), se


@pytest.fixture(scope="module")
def replicas():
    runs = [simulate(spec(room_doc(seed=200 + i, **ONE_BATCH))) for i in range(SEEDS)]
    assert all(r["run"]["batches"] == 1 for r in runs)  # one batch per run: the case under test
    return [_cir(r) for r in runs]


def _variance_ratio(x, se, rows):
    """sum over bins of the mean reported variance / sum over bins of the variance over seeds (rows: seeds)."""
    return (se[rows] ** 2).mean(axis=0).sum() / x[rows].var(axis=0, ddof=1).sum()


def test_one_batch_per_bin_errors_match_the_spread_over_seeds(replicas):
    """Reported per-bin variance / spread over 60 seeds within 4 bootstrap SE of 1 (sampled bins above 1 % of the
    peak);
    the power check: 4 SE < 0.25, so per-bin errors 13 % off would fail."""
    x = np.array([r[1] for r in replicas])
    se = np.array([r[2] for r in replicas])
    sampled = x - x.min(axis=0)  # the line of sight is exact: its bin has no spread and a zero error
    bins = (sampled.max(axis=0) > 0) & (x.mean(axis=0) > 0.01 * x.mean(axis=0).max())
    assert bins.sum() >= 20 and np.isfinite(se[:, bins]).all() and (se[:, bins] > 0).all()
    x, se = x[:, bins], se[:, bins]
    ratio = _variance_ratio(x, se, np.arange(SEEDS))
    rng = np.random.default_rng(1)
    boot = [_variance_ratio(x, se, rng.integers(0, SEEDS, SEEDS)) for _ in range(400)]
    spread = float(np.std(boot))
    assert 4 * spread < 0.25, spread
    print(f"variance ratio {ratio:.3f} +- {spread:.3f}")
    assert abs(ratio - 1.0) < 4 * spread, (ratio, spread)


def test_one_batch_bins_sum_to_h0(replicas):
    """sum(cir.total) + early_gain + late_gain = dc_gain, and the binned errors' derived figures exist."""
    for link, total, _ in replicas[:3]:
        assert total.sum() + link["early_gain"] + link["late_gain"] == pytest.approx(link["dc_gain"], rel=1e-12)
        assert link["rms_delay_spread_h2_s_stderr"] is not None


@pytest.mark.parametrize(
    "doc",
    [
        pytest.param(lambda: open_doc(algorithm=4, paths=2048, segment_time_step_s=5e-9, max_strata=8), id="4 both"),
        pytest.param(
            lambda: room_doc(algorithm=5, medium=SMOKE, max_reflections=2, max_scattering=2, paths=2048, t_max_s=6e-8),
            id="5 both",
        ),
        pytest.param(lambda: room_doc(algorithm=1, paths=2048, direction="forward", t_max_s=6e-8), id="1 forward"),
    ],
)
def test_one_batch_runs_have_per_bin_errors_in_every_direction(doc):
    """Runs from one side or from both devices (two accumulators summed per group): every bin with power has
    a finite error, and the bins still sum to H0."""
    res = simulate(spec(doc()))
    assert res["run"]["batches"] <= 2  # one batch per source (both devices: one each)
    link, total, se = _cir(res)
    lit = (total > 0) & (np.arange(len(total)) != int(link["los_delay_s"] // res["time_bins"]["time_bin_s"]))
    assert lit.any() and np.isfinite(se[lit]).all() and (se[lit] > 0).all()
    assert total.sum() + link["early_gain"] + link["late_gain"] == pytest.approx(link["dc_gain"], rel=1e-12)


def test_a_one_batch_cir_too_large_for_path_groups_says_so_by_null_errors():
    """Over tally.CIR_GROUPS_MAX (16 groups x bins) the first batch is not binned per group: null errors, as
    documented in docs/results.md, never a made-up number."""
    res = simulate(spec(room_doc(paths=1024, time_bin_s=1e-12, t_max_s=7e-8)))  # 70 000 bins
    _, total, se = _cir(res)
    assert len(total) == 70_000 and np.isnan(se).all()


def test_an_accuracy_run_that_stops_after_one_batch_has_per_bin_errors():
    """Accuracy runs may stop after their first round: their first batches are binned per path group too."""
    doc = room_doc(target_rel_error=0.05, t_max_s=6e-8, direction="backward")
    doc["simulation"].pop("paths")
    res = simulate(spec(doc))
    assert res["run"]["batches"] == 1 and res["run"]["stop_reason"] == "target_reached"
    link, total, se = _cir(res)
    sampled = (total > 0) & (np.arange(len(total)) != int(link["los_delay_s"] // res["time_bins"]["time_bin_s"]))
    assert sampled.any() and np.isfinite(se[sampled]).all() and (se[sampled] > 0).all()
