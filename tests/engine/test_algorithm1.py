"""Algorithm 1 against references derived independently of the engine (physics.md section 6)."""

import math

import numpy as np
import pytest

from tests import reference as ref
from tests.results import simulate_document as simulate
from tests.scenes import BARRY_RHO, room_doc, spec, within


def _link(doc, **kw):
    return simulate(spec(doc), **kw)["links"][0]


@pytest.mark.parametrize(
    "medium,sigma_t",
    [
        (None, 0.0),
        ({"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2}, 0.25),
        ({"type": "homogeneous", "visibility_m": 5.0, "albedo": 0.6}, 3.912 / 5.0),
    ],
)
@pytest.mark.parametrize(
    "rx,normal,fov", [((0.5, 1.0, 0.0), (0, 0, 1), 85.0), ((4.0, 1.5, 1.0), (-0.3, 0.2, 1.0), 60.0)]
)
def test_los_closed_form(medium, sigma_t, rx, normal, fov):
    doc = room_doc(rx=rx, rx_normal=normal, fov_deg=fov, m=2.0, medium=medium, max_reflections=0, paths=64)
    link = _link(doc)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    h, delay = ref.los_gain((2.5, 2.5, 3.0), (0, 0, -1), 2.0, rx, n, 1e-4, math.radians(fov), sigma_t=sigma_t)
    assert h > 0
    assert link["dc_gain"] == pytest.approx(h, rel=1e-12)
    assert link["los_delay_s"] == pytest.approx(delay, rel=1e-12)
    assert link["mean_delay_s"] == pytest.approx(delay, rel=1e-12)
    assert link["dc_gain_stderr"] == 0.0


def test_los_outside_fov_is_zero():
    link = _link(room_doc(rx=(0.2, 0.2, 0.0), fov_deg=30.0, max_reflections=0, paths=64))
    assert link["los_gain"] == 0.0 and link["dc_gain"] == 0.0 and link["mean_delay_s"] is None


def test_los_blocked_by_furniture():
    doc = room_doc(rx=(1.0, 1.0, 0.0), max_reflections=0, paths=64)
    doc["furniture"] = [{"min": [1.2, 1.2, 0.5], "max": [2.0, 2.0, 1.0], "reflectance": 0.5}]
    assert _link(doc)["los_gain"] == 0.0


def test_smoke_box_region_containing_everything_equals_whole_scene():
    whole = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.1}
    box = dict(whole, region={"type": "box", "min": [-1, -1, -1], "max": [6, 6, 4]})
    a = _link(room_doc(medium=whole, paths=4096))
    b = _link(room_doc(medium=box, paths=4096))
    assert a["dc_gain"] == pytest.approx(b["dc_gain"], rel=1e-12)
    assert a["cir"]["total"] == pytest.approx(b["cir"]["total"], rel=1e-12, abs=1e-30)


def test_smoke_layer_only_attenuates_inside_it():
    """A smoke layer above z = 2.9 m: the LOS from the ceiling Tx crosses 0.1 m of it, no more."""
    layer = {
        "type": "homogeneous",
        "sigma_a": 2.0,
        "sigma_s": 0.0,
        "region": {"type": "box", "min": [0, 0, 2.9], "max": [5, 5, 3]},
    }
    clear = _link(room_doc(max_reflections=0, paths=64))
    smoky = _link(room_doc(max_reflections=0, paths=64, medium=layer))
    d_in = 0.1 * math.dist((2.5, 2.5, 3.0), (1.0, 1.0, 0.0)) / 3.0
    assert smoky["dc_gain"] == pytest.approx(clear["dc_gain"] * math.exp(-2.0 * d_in), rel=1e-9)


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_first_bounce_dc_gain_and_cir(direction):
    """k = 1 against deterministic patch integration of the box room (Barry et al. 1993)."""
    rx, fov = (0.5, 1.0, 0.0), 85.0
    doc = room_doc(
        rx=rx,
        fov_deg=fov,
        max_reflections=1,
        paths=150_000,
        batch_size=8192,
        direction=direction,
        time_bin_s=2e-9,
        t_max_s=6e-8,
        seed=11,
    )
    link = _link(doc)
    args = ((5.0, 5.0, 3.0), BARRY_RHO, (2.5, 2.5, 3.0), (0, 0, -1), 1.0, rx, (0, 0, 1), 1e-4, math.radians(fov))
    h1 = ref.first_bounce_box_dc_gain(*args, rel_tol=1e-4)
    k1, k1_err = link["dc_gain_by_reflection_order"][1], link["dc_gain_by_reflection_order_stderr"][1]
    assert k1_err < 0.01 * h1  # the test has power: a 4-sigma band narrower than 4 %
    assert within(k1, h1, k1_err, bias=1e-3 * h1), (k1, h1, k1_err)
    # CIR of the first bounce, bin by bin (2 ns bins), against the patch histogram.
    edges = np.arange(0, 31) * 2e-9
    _, hist = ref.first_bounce_box(*args, t_edges=edges, patch_size=0.01)
    mc = np.asarray(link["cir"]["by_reflection_order"][1])
    se = np.asarray([s or 0.0 for s in link["cir"]["total_stderr"]])
    assert np.all(np.abs(mc - hist) <= 5 * se + 2e-3 * hist.max())
    assert np.abs(mc - hist).max() < 0.05 * hist.max()


def test_forward_and_backward_agree_all_orders():
    base = dict(rx=(0.5, 1.0, 0.0), fov_deg=85.0, max_reflections=6, paths=60_000, seed=3)
    f = _link(room_doc(direction="forward", **base))
    b = _link(room_doc(direction="backward", **base))
    err = math.hypot(f["dc_gain_stderr"], b["dc_gain_stderr"])
    assert err < 0.02 * f["dc_gain"]
    assert within(f["dc_gain"], b["dc_gain"], err)
    for k in range(1, 7):
        ek = math.hypot(f["dc_gain_by_reflection_order_stderr"][k], b["dc_gain_by_reflection_order_stderr"][k])
        assert within(f["dc_gain_by_reflection_order"][k], b["dc_gain_by_reflection_order"][k], ek)
    assert within(
        f["rms_delay_spread_s"],
        b["rms_delay_spread_s"],
        math.hypot(f["rms_delay_spread_s_stderr"], b["rms_delay_spread_s_stderr"]),
    )


def test_reciprocity_swapping_devices():
    """m = 1, FOV = 90 deg: H0(a -> b) = H0(b -> a) (swap positions and normals)."""
    a, na, b, nb = (1.2, 3.4, 2.2), (0.3, -0.2, -1.0), (3.9, 0.8, 0.9), (-0.5, 0.4, 1.0)
    common = dict(m=1.0, fov_deg=90.0, max_reflections=4, paths=40_000, seed=5, direction="forward")
    ab = _link(room_doc(tx=a, tx_normal=na, rx=b, rx_normal=nb, **common))
    ba = _link(room_doc(tx=b, tx_normal=nb, rx=a, rx_normal=na, **common))
    assert ab["los_gain"] == pytest.approx(ba["los_gain"], rel=1e-12)
    assert within(ab["dc_gain"], ba["dc_gain"], math.hypot(ab["dc_gain_stderr"], ba["dc_gain_stderr"]))
    assert ab["dc_gain_stderr"] < 0.02 * ab["dc_gain"]


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_energy_closed_room(rho):
    """Power reaching the surfaces of a closed room with reflectance rho: P (1 - rho^K) / (1 - rho)."""
    K = 60 if rho == 0.5 else 120
    doc = room_doc(
        rho,
        rho,
        rho,
        max_reflections=K,
        paths=20_000,
        direction="forward",
        t_max_s=2e-6,
        time_bin_s=1e-8,
        russian_roulette=False,
    )
    res = simulate(spec(doc))
    expected = (1 - rho**K) / (1 - rho)
    assert res["diagnostics"]["escaped_power"]["tx"] == 0.0
    # Without roulette and with equal reflectances every path carries exactly rho^(k-1): no variance.
    assert res["diagnostics"]["power_on_surfaces"]["tx"] == pytest.approx(expected, rel=1e-9)


def test_russian_roulette_is_unbiased():
    base = dict(
        rx=(0.5, 1.0, 0.0),
        fov_deg=85.0,
        max_reflections=12,
        paths=40_000,
        seed=9,
        direction="backward",
        rr_start_depth=1,
    )
    on = _link(room_doc(russian_roulette=True, **base))
    off = _link(room_doc(russian_roulette=False, **base))
    assert within(on["dc_gain"], off["dc_gain"], math.hypot(on["dc_gain_stderr"], off["dc_gain_stderr"]))
    assert on["dc_gain_stderr"] < 0.01 * on["dc_gain"]


def test_scene_far_from_origin():
    """The same room translated 5 km: same H0 (float32 Embree on re-centred vertices)."""
    shift = np.array([5000.0, -3000.0, 200.0])
    base = dict(max_reflections=3, paths=20_000, seed=4, direction="forward")
    near = _link(room_doc(**base))
    far = _link(room_doc(origin=shift, tx=shift + (2.5, 2.5, 3.0), rx=shift + (1.0, 1.0, 0.0), **base))
    assert far["los_gain"] == pytest.approx(near["los_gain"], rel=1e-9)
    assert within(far["dc_gain"], near["dc_gain"], math.hypot(far["dc_gain_stderr"], near["dc_gain_stderr"]))


def test_receiver_near_wall_is_finite():
    link = _link(room_doc(rx=(0.001, 2.5, 1.5), rx_normal=(1, 0, 0), fov_deg=90.0, paths=20_000, direction="forward"))
    assert np.isfinite(link["dc_gain"]) and link["dc_gain"] > 0 and np.isfinite(link["dc_gain_stderr"])


def test_accuracy_mode_reaches_target():
    doc = room_doc(max_reflections=3, paths=None, target_rel_error=0.01, direction="backward", batch_size=1024)
    res = simulate(spec(doc))
    link = res["links"][0]
    assert res["run"]["stop_reason"] == "target_reached"
    assert link["dc_gain_stderr"] / link["dc_gain"] <= 0.01
    assert link["paths"] < 200_000


def test_accuracy_mode_time_budget():
    doc = room_doc(max_reflections=3, paths=None, target_rel_error=1e-6, time_budget_s=0.3, direction="backward")
    res = simulate(spec(doc))
    assert res["run"]["stop_reason"] == "time_budget"
    assert res["run"]["max_dc_gain_rel_stderr"] > 1e-6


def test_auto_direction_reports_choice():
    res = simulate(spec(room_doc(direction="auto", paths=4096)))
    pilot = res["run"]["direction_choice"]
    assert pilot["rule"].startswith("pilot")
    assert res["links"][0]["direction"] in ("forward", "backward")
    assert pilot["rel_std_per_path_forward"][0] > 0 and pilot["rel_std_per_path_backward"][0] > 0


def test_cir_sums_to_dc_gain_inside_window():
    link = _link(room_doc(paths=10_000, t_max_s=3e-8, time_bin_s=1e-9))
    assert link["late_gain"] > 0  # the window is short on purpose: the tail is reported, not dropped
    total = sum(link["cir"]["total"]) + link["late_gain"] + link["early_gain"]
    assert total == pytest.approx(link["dc_gain"], rel=1e-9)
    assert sum(link["dc_gain_by_reflection_order"]) == pytest.approx(link["dc_gain"], rel=1e-9)
