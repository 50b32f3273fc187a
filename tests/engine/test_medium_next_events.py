"""Algorithm 5's next-event estimates from scattering points: `uniform_medium.connect_on_segments` (computed on the
segments' equiangular frames, no gathers) against the general `BatchContext.connect` on the same points.

Both draw the same random numbers, so a batch traced either way must give the same tallies to rounding; the
connection itself (measurement equation, balance heuristic of `segments.scattering_point_throughput`, the share of
weights.connection_weight) is thus checked estimate by estimate against the general code, whose statistics
the other tests check against references."""

import dataclasses

import numpy as np
import pytest

from owcsim.engine.integrator import events, uniform_medium
from owcsim.engine.integrator.kernel import trace_batch
from owcsim.engine.integrator.path import WorkItem
from owcsim.engine.run.simulate import kernel_settings
from owcsim.engine.scene.scene import build_scene
from owcsim.schemas import SceneSpec
from tests.scenes import room_doc

REAL = events.connect_on_segments
SMOKE_HG = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.3, "phase": {"type": "hg", "g": 0.6}}


def _trace(doc, direction, both, fused: bool, monkeypatch, targets=(0,)):
    spec = SceneSpec.model_validate(doc)
    scene = build_scene(spec)
    settings = dataclasses.replace(kernel_settings(spec, scene, both_devices=both), qmc_block=1)
    used = []

    def spy(self, *args):
        done = REAL(self, *args) if fused else False
        used.append(done)
        return done

    monkeypatch.setattr(events, "connect_on_segments", spy)
    tally = trace_batch(scene, WorkItem(direction, 0, targets, 0, 1024, 5), settings)
    evaluations = scene.medium.evaluations
    return tally, evaluations, used


@pytest.mark.parametrize("small_step", [1 << 20, -1], ids=["one group", "two groups"])
@pytest.mark.parametrize("both", [True, False], ids=["both devices", "one side"])
@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_segment_frame_connections_equal_the_general_ones(direction, both, small_step, monkeypatch):
    monkeypatch.setattr(uniform_medium, "SMALL_STEP", small_step)  # the points of a step as one group or two
    doc = room_doc(medium=SMOKE_HG, algorithm=5, max_reflections=5, max_scattering=4, paths=1024)
    fused, ev_fused, used = _trace(doc, direction, both, True, monkeypatch)
    plain, ev_plain, _ = _trace(doc, direction, both, False, monkeypatch)
    assert len(used) >= 5 and all(used)  # the frame connections served every step (the first two included)
    np.testing.assert_allclose(fused.s1, plain.s1, rtol=1e-11)
    np.testing.assert_allclose(fused.s2, plain.s2, rtol=1e-11)
    np.testing.assert_allclose(fused.order_sum, plain.order_sum, rtol=1e-11, atol=1e-11 * plain.order_sum.max())
    np.testing.assert_allclose(fused.order_sumsq, plain.order_sumsq, rtol=1e-10, atol=1e-10 * plain.order_sumsq.max())
    np.testing.assert_allclose(fused.cir, plain.cir, rtol=1e-10, atol=1e-11 * plain.cir.max())
    assert plain.s1[0, 0] > 0 and (plain.order_sum[0, :, 1:] > 0).sum() >= 10  # scattering orders reached
    assert ev_fused == ev_plain  # the medium's evaluation count is the same


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_narrow_fov_lambertian_order_and_two_receivers(direction, monkeypatch):
    """Receivers with FOV 50 deg (estimates of zero power dropped), a Lambertian order 3 transmitter, three
    equiangular points per segment, and in forward runs two receivers (the loop over targets): the same
    tallies as the general connection."""
    monkeypatch.setattr(uniform_medium, "SMALL_STEP", -1)
    doc = room_doc(medium=SMOKE_HG, algorithm=5, max_reflections=4, max_scattering=3, paths=1024, m=3.0, fov_deg=50)
    doc["receivers"].append(
        {"id": "rx2", "position": [4.0, 2.0, 1.0], "normal": [-1, 0, 0], "area": 1e-4, "fov_deg": 50}
    )
    doc["simulation"]["equiangular_points"] = 3
    targets = (0, 1) if direction == "forward" else (0,)
    fused, ev_fused, used = _trace(doc, direction, True, True, monkeypatch, targets)
    plain, ev_plain, _ = _trace(doc, direction, True, False, monkeypatch, targets)
    assert len(used) >= 5 and all(used)
    np.testing.assert_allclose(fused.s1, plain.s1, rtol=1e-11)
    np.testing.assert_allclose(fused.order_sum, plain.order_sum, rtol=1e-11, atol=1e-11 * plain.order_sum.max())
    assert (plain.s1[:, 0] > 0).all() and ev_fused == ev_plain


def test_the_comparison_has_power(monkeypatch):
    """A frame connection off by 1 % (here: its phase function value) is seen by the comparison above."""
    doc = room_doc(medium=SMOKE_HG, algorithm=5, max_reflections=5, max_scattering=4, paths=1024)
    plain, *_ = _trace(doc, "forward", True, False, monkeypatch)

    def biased(self, *args):
        phase = self.scene.phase
        phase.eval = lambda c, real=phase.eval: 1.01 * real(c)  # only while the frame path runs
        try:
            return REAL(self, *args)
        finally:
            del phase.eval

    monkeypatch.setattr(events, "connect_on_segments", biased)
    spec = SceneSpec.model_validate(doc)
    scene = build_scene(spec)
    settings = dataclasses.replace(kernel_settings(spec, scene, both_devices=True), qmc_block=1)
    off = trace_batch(scene, WorkItem("forward", 0, (0,), 0, 1024, 5), settings)
    assert not np.allclose(off.s1[0, 0], plain.s1[0, 0], rtol=1e-3)
