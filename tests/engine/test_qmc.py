"""Quasi-random blocks (engine/core/qmc.py) and the standard errors over samples (tally.sample_cov).

The Sobol points are checked against scipy's; the block statistics against a direct computation from the
per-path sums; the whole against the first-bounce integral of the box room (Barry 1993), with the
replicate spread of independent runs as the judge of the reported error bars.
"""

import dataclasses

import numpy as np
import pytest
from scipy.stats import qmc as scipy_qmc

from owcsim.engine.core import qmc
from owcsim.engine.integrator.kernel import trace_batch
from owcsim.engine.integrator.path import WorkItem
from owcsim.engine.run.simulate import kernel_settings
from owcsim.engine.scene.scene import build_scene
from owcsim.engine.tally.stats import per_path_s2, sample_cov
from owcsim.engine.tally.tally import Accumulator, BatchBuilder
from owcsim.schemas import SceneSpec
from tests.scenes import barry_first_bounce, room_doc, within


@pytest.mark.parametrize("m", [1, 2, 64, 256, 1024])
def test_sobol_points_are_scipys_point_set(m):
    ours = qmc.sobol_points(m).astype(np.float64) * 2.0**-32
    ref = scipy_qmc.Sobol(d=qmc.DIMENSIONS, scramble=False).random(m)  # Gray-code order: compare as sets
    np.testing.assert_array_equal(ours[np.lexsort(ours.T)], ref[np.lexsort(ref.T)])


def test_sobol_block_must_be_a_power_of_two():
    with pytest.raises(ValueError, match="power-of-2"):
        qmc.sobol_points(96)


def test_block_rules():
    assert qmc.block_size(512, 256) == 256
    assert qmc.block_size(600, 256) == 1  # not whole blocks: pseudo-random paths
    assert qmc.block_size(128, 256) == 1
    assert qmc.block_size(512, 1) == 1
    assert qmc.whole_blocks(5461, 256) == 5376
    assert qmc.whole_blocks(419, 256) == 419  # rounding would cost 39 % of the batch: pseudo-random instead
    assert qmc.whole_blocks(100, 256) == 100
    assert qmc.whole_blocks(5461, 1) == 5461


def test_jobs_use_blocks_with_enough_samples():
    """Accuracy runs and jobs of at least 64 blocks per source use them; smaller jobs get pseudo-random paths."""
    assert qmc.job_block(True, None) == 256
    assert qmc.job_block(True, 64 * 256) == 256
    assert qmc.job_block(True, 64 * 256 - 1) == 1
    assert qmc.job_block(False, None) == 1
    small = SceneSpec.model_validate(room_doc(paths=4096))
    assert kernel_settings(small, build_scene(small)).qmc_block == 1


def test_shifted_blocks_are_stratified_and_independent():
    u = qmc.shifted_blocks(4 * 256, 256, np.random.default_rng(3))
    assert u.shape == (qmc.DIMENSIONS, 1024) and u.min() >= 0.0 and u.max() < 1.0
    cells = np.floor(u * 256).astype(int).reshape(qmc.DIMENSIONS, 4, 256)
    # every coordinate of every block takes each of the 256 strata once (a digital shift keeps this) ...
    assert all(np.array_equal(np.sort(c), np.arange(256)) for c in cells.reshape(-1, 256))
    # ... while pseudo-random points would not (power of the check)
    plain = np.floor(np.random.default_rng(3).random(256) * 256).astype(int)
    assert not np.array_equal(np.sort(plain), np.arange(256))
    # the blocks have their own shifts: the same stratum holds different points in different blocks
    first = np.argsort(cells[0], axis=1)[:, 0]
    assert len({round(u[0].reshape(4, 256)[b, first[b]], 12) for b in range(4)}) == 4


def test_sample_cov_is_the_cluster_formula():
    """Against the definition: B / (B - 1) sum_b (S_b - n_b H)(S_b - n_b H)^T / n^2, unequal n_b."""
    rng = np.random.default_rng(0)
    n_b = rng.integers(1, 300, size=40)
    S = rng.normal(size=(40, 3)) * n_b[:, None] + n_b[:, None]
    n, B = n_b.sum(), len(n_b)
    H = S.sum(0) / n
    dev = S - n_b[:, None] * H
    want = B / (B - 1) * dev.T @ dev / n**2
    got = sample_cov(
        np.array(n), np.array(B), S.sum(0), S.T @ S, (n_b[:, None] * S).sum(0), np.array((n_b**2).sum(), float)
    )
    np.testing.assert_allclose(got, want, rtol=1e-10)
    # one-path samples: the usual per-path covariance of the mean; per_path_s2 returns their own s2
    x = rng.normal(size=(500, 3))
    ones = (np.array(500), np.array(500), x.sum(0), x.T @ x, x.sum(0), np.array(500.0))
    np.testing.assert_allclose(sample_cov(*ones), np.cov(x.T) / 500, rtol=1e-10)
    assert per_path_s2(*ones) is not None and np.array_equal(per_path_s2(*ones), x.T @ x)


def _first_bounce_scene(**sim):
    rx, fov = (0.5, 1.0, 0.0), 85.0
    spec = SceneSpec.model_validate(room_doc(rx=rx, fov_deg=fov, **{"max_reflections": 1, "paths": 16384, **sim}))
    return build_scene(spec), kernel_settings(spec, build_scene(spec)), barry_first_bounce(rx, fov)


def test_accumulator_moments_come_from_block_sums(monkeypatch):
    """The Accumulator's mean and covariance of (a, b, c) equal the direct formula over the block sums of the
    per-path sums of the estimates the batches tallied (blocks of 256, two batches)."""
    scene, settings, _ = _first_bounce_scene()
    held = []
    real = BatchBuilder.add_step

    def spy(self, target, k, s, delay, power, path):
        held.append((None, path.copy(), power.copy(), delay.copy()))
        return real(self, target, k, s, delay, power, path)

    monkeypatch.setattr(BatchBuilder, "add_step", spy)
    acc = Accumulator(scene.n_links, settings.tally, backward=True)
    per_batch = []
    for b in range(2):
        held.clear()
        acc.add(trace_batch(scene, WorkItem("backward", 0, (0,), b, 2048, 9), settings), b, 0)
        path, p, t = (np.concatenate([h[i] for h in held]) for i in (1, 2, 3))
        per_batch.append(np.stack([np.bincount(path, w, 2048) for w in (p, p * t, p * t * t)]))
    per_path = np.concatenate(per_batch, axis=1)  # (3, 4096): per-path sums a, b, c
    blocks = per_path.reshape(3, -1, 256).sum(axis=2).T  # (16, 3)
    n, B = 4096, len(blocks)
    mean, cov = acc.moments()
    H = blocks.sum(0) / n
    dev = blocks - 256 * H
    np.testing.assert_allclose(mean[0], H, rtol=1e-12)
    np.testing.assert_allclose(cov[0], B / (B - 1) * dev.T @ dev / n**2, rtol=1e-9)
    # the per-path formula on the same paths differs (the check has the power to see it)
    paths = per_path[0]
    assert not np.isclose(cov[0, 0, 0], paths.var(ddof=1) / n, rtol=0.1, atol=0.0)


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_first_bounce_with_blocks_and_honest_error_bars(direction, monkeypatch):
    """k = 1 (driven by the Sobol dimensions) against the patch integral; the reported standard errors
    against the spread of 160 independent runs. The per-path formula on the same runs (what the error bars
    would be if blocks were ignored) falls outside the accepted band: the check has the power to see it."""
    scene, settings, h1 = _first_bounce_scene()
    assert settings.qmc_block == 256
    naive, held = [], []
    real = BatchBuilder.add_step

    def spy(self, target, k, s, delay, power, path):
        held.append((path.copy(), power.copy()))
        return real(self, target, k, s, delay, power, path)

    monkeypatch.setattr(BatchBuilder, "add_step", spy)
    n, runs = 8192, 160
    means, ses = np.empty(runs), np.empty(runs)
    for r in range(runs):
        acc = Accumulator(scene.n_links, settings.tally, backward=direction == "backward")
        held.clear()
        acc.add(trace_batch(scene, WorkItem(direction, 0, (0,), r, n, 5), settings), 0, 0)
        a0 = np.bincount(np.concatenate([h[0] for h in held]), np.concatenate([h[1] for h in held]), n)
        naive.append(a0.var(ddof=1) / n)  # the per-path formula on this run's per-path H0 sums
        mean, cov = acc.moments()
        means[r], ses[r] = mean[0, 0], np.sqrt(cov[0, 0, 0])
    spread = means.std(ddof=1)
    ratio = spread / np.sqrt(np.mean(ses**2))  # 1 for honest error bars, +-6 % (1 sd) with 160 runs
    print(f"spread / reported: {ratio:.3f}")
    assert 0.75 < ratio < 1.3, ratio
    assert min(naive) > 0
    naive_ratio = spread / np.sqrt(np.mean(naive))
    print(f"spread / per-path formula: {naive_ratio:.3f}")
    assert not 0.75 < naive_ratio < 1.3, naive_ratio
    se = spread / np.sqrt(runs)
    assert se < 0.005 * h1  # power: a 2 % bias would fail
    assert within(means.mean(), h1, se, bias=1e-3 * h1), (means.mean(), h1, se)


def test_pseudo_random_paths_when_asked():
    scene, settings, _ = _first_bounce_scene(quasi_random=False)
    assert settings.qmc_block == 1
    tally = trace_batch(scene, WorkItem("backward", 0, (0,), 0, 512, 5), settings)
    assert tally.block == 1
    off = dataclasses.replace(settings, qmc_block=256)
    assert trace_batch(scene, WorkItem("backward", 0, (0,), 0, 512, 5), off).block == 256
