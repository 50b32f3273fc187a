"""The kernel hands the tally one depth k + s at a time, and the per-(sample, cell) squared sums of the order
split (tally.BatchBuilder: a dense (sample, cell) table with few samples, else per step without sorting) match
a plain computation over the whole batch; a sample is a path, or a block of quasi-random paths (engine/core/qmc.py)."""

import dataclasses

import numpy as np
import pytest

from owcsim.engine.integrator.kernel import trace_batch
from owcsim.engine.integrator.path import WorkItem
from owcsim.engine.run.simulate import kernel_settings
from owcsim.engine.scene.scene import build_scene
from owcsim.engine.tally import tally as tally_module
from owcsim.engine.tally.tally import BatchBuilder
from owcsim.schemas import SceneSpec
from tests.scenes import SMOKE, room_doc


def _mirror_floor(**sim):
    doc = room_doc(max_reflections=4, paths=512, **sim)
    doc["room"]["reflectance"]["floor"] = {"type": "mirror", "reflectance": 0.8, "diffuse_fraction": 0.375}
    return doc


CASES = {
    "mirror floor, algorithm 1": lambda: _mirror_floor(),
    "smoke, algorithm 4 (both devices)": lambda: room_doc(medium=SMOKE, algorithm=4, max_reflections=3, paths=512),
    "smoke, algorithm 5 (both devices)": lambda: room_doc(
        medium=SMOKE, algorithm=5, max_reflections=4, max_scattering=3, paths=512
    ),
}


@pytest.mark.parametrize(
    "direct_keys, table", [(4096, 1 << 20), (4096, 0), (0, 0)], ids=["sample table", "one bincount", "rounds"]
)
@pytest.mark.parametrize("quasi_random", [True, False])
@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_one_depth_per_step_and_order_sums_of_squares(case, direction, quasi_random, direct_keys, table, monkeypatch):
    # the three ways of summing per (sample, cell): the dense table (blocks only: 2 samples), one bincount per
    # step (512 paths: the keys span at most 4096), or rounds (no key range is small enough)
    monkeypatch.setattr(tally_module, "SAMPLE_TABLE_MAX", table)
    monkeypatch.setattr(tally_module, "DIRECT_KEYS", direct_keys)
    monkeypatch.setattr(tally_module, "KEYS_PER_ESTIMATE", 4 if direct_keys else 0)
    doc = CASES[case]()
    doc["simulation"]["quasi_random"] = quasi_random
    spec = SceneSpec.model_validate(doc)
    scene = build_scene(spec)
    settings = dataclasses.replace(kernel_settings(spec, scene), qmc_block=256 if quasi_random else 1)  # 512 paths
    calls, tabled = [], set()
    real = BatchBuilder.add_step

    def spy(self, target, k, s, delay, power, path):
        calls.append((k.copy(), s.copy(), power.copy(), path.copy(), target.copy()))
        tabled.add(self.sample_cells is not None)
        return real(self, target, k, s, delay, power, path)

    monkeypatch.setattr(BatchBuilder, "add_step", spy)
    tally = trace_batch(scene, WorkItem(direction, 0, (0,), 0, 512, 3), settings)
    depths = [np.unique(k + s) for k, s, *_ in calls]
    assert all(len(d) == 1 for d in depths)  # one depth per call ...
    assert len({int(d[0]) for d in depths}) == len(depths)  # ... and each depth in one call
    assert tally.block == (256 if quasi_random else 1)  # 512 paths: two blocks of 256, or 512 samples
    assert tabled == {bool(table) and quasi_random}  # the way under test was taken
    # Reference: per-(sample, k, s) sums over the whole batch by sorting, then squared per cell.
    k, s, p, path = (np.concatenate([c[i] for c in calls]) for i in range(4))
    path = path // tally.block
    n_s = settings.tally.n_scatter
    cells = k * n_s + s
    keys, inverse = np.unique(path * (settings.tally.n_orders * n_s) + cells, return_inverse=True)
    per_path = np.bincount(inverse, p, len(keys))
    want = np.bincount(keys % (settings.tally.n_orders * n_s), per_path**2, settings.tally.n_orders * n_s)
    got = tally.order_sumsq[0].reshape(-1)
    several = np.bincount(inverse).max()
    assert several >= 2 or (case.startswith("mirror") and not quasi_random)  # several estimates per (sample, cell)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0.0)
    plain_sum = np.bincount(cells, p, len(want))
    np.testing.assert_allclose(tally.order_sum[0].reshape(-1), plain_sum, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(tally.order_ssum[0].reshape(-1), plain_sum, rtol=1e-12, atol=0.0)
    # power check: squaring each estimate alone (the error this guards against) differs
    assert not np.allclose(np.bincount(cells, p**2, len(want)), want, rtol=1e-6, atol=0.0) or several == 1


@pytest.mark.parametrize(
    "doc",
    [
        lambda: room_doc(max_reflections=3, paths=2048),  # S = 0: the scattering split is the CIR itself
        lambda: room_doc(medium=SMOKE, algorithm=5, max_reflections=3, max_scattering=2, paths=2048),
    ],
    ids=["algorithm 1", "algorithm 5"],
)
def test_cir_split_by_order_sums_to_the_cir(doc, monkeypatch):
    """The CIR and its splits by reflection order and by scattering order against a plain binning of the
    estimates the batch tallied (whether a split is tallied, or the CIR is summed from one, or one order is
    the CIR itself)."""
    d = doc()
    d["outputs"] = {"cir": True, "orders": True}
    spec = SceneSpec.model_validate(d)
    scene = build_scene(spec)
    settings = kernel_settings(spec, scene)
    plan = settings.tally
    assert plan.by_order_cir
    calls = []
    real = BatchBuilder.add_step

    def spy(self, target, k, s, delay, power, path):
        calls.append((k.copy(), s.copy(), delay.copy(), power.copy()))
        return real(self, target, k, s, delay, power, path)

    monkeypatch.setattr(BatchBuilder, "add_step", spy)
    tally = trace_batch(scene, WorkItem("backward", 0, (0,), 0, 2048, 5), settings)
    k, s, delay, power = (np.concatenate([c[i] for c in calls]) for i in range(4))
    b = np.floor((delay - plan.bins.t_min) / plan.bins.dt).astype(np.int64)
    inside = (b >= 0) & (b < plan.bins.n)
    k, s, b, power = k[inside], s[inside], b[inside], power[inside]
    want = np.bincount(b, power, plan.bins.n)
    assert want.sum() > 0
    np.testing.assert_allclose(tally.cir[0], want, rtol=1e-12, atol=1e-300)
    for split, order, n_ord in ((tally.cir_k, k, plan.n_orders), (tally.cir_s, s, plan.n_scatter)):
        ref = np.bincount(order * plan.bins.n + b, power, n_ord * plan.bins.n).reshape(n_ord, plan.bins.n)
        np.testing.assert_allclose(split[0], ref, rtol=1e-12, atol=1e-300)
    assert np.count_nonzero(tally.cir_k[0].sum(axis=1)) >= 3  # several reflection orders (the test can fail)
