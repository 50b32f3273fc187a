"""Algorithms 2-5 against each other and against independent references (physics.md section 6)."""

import math

import numpy as np
import pytest

from tests import reference as ref
from tests.reference_volume import single_scattering
from tests.results import simulate_document as simulate
from tests.scenes import SMOKE, open_doc, room_doc, spec, within


def _link(doc, **kw):
    return simulate(spec(doc), **kw)["links"][0]


_open_doc = open_doc  # the open-medium scene of tests/scenes.py


CIR_EDGES = np.arange(0, 201) * 2e-10  # 0.2 ns bins up to 40 ns


@pytest.fixture(scope="module")
def quadrature():
    return single_scattering(3.0, 1.0, 1e-4, 0.2, 0.25, 0.5, n=96, t_edges=CIR_EDGES)


@pytest.mark.parametrize(
    "algorithm,extra",
    [
        (2, {}),
        (3, {}),
        (4, {"paths": 20_000}),
        (5, {"max_scattering": 1, "direction": "forward", "paths": 200_000}),
        (5, {"max_scattering": 1, "direction": "backward", "paths": 400_000}),
    ],
)
def test_single_scattering_unbounded_medium(quadrature, algorithm, extra):
    """Unbounded medium, no surfaces: s = 1 gain of each algorithm against volume quadrature."""
    h1, hist = quadrature
    link = _link(_open_doc(algorithm=algorithm, **extra))
    s1, s1_err = link["dc_gain_by_scattering_order"][1], link["dc_gain_by_scattering_order_stderr"][1]
    assert s1_err < 0.05 * h1, (s1, s1_err)  # the comparison has power
    assert within(s1, h1, s1_err, bias=2e-4 * h1), (algorithm, extra, s1, h1, s1_err, (s1 - h1) / s1_err)
    los, _ = ref.los_gain((0, 0, 0), (1, 0, 0), 1.0, (3, 0, 0), (-1, 0, 0), 1e-4, math.pi / 2, sigma_t=0.25)
    assert link["dc_gain_by_scattering_order"][0] == pytest.approx(los, rel=1e-12)


def test_single_scattering_cir_matches_quadrature(quadrature):
    """Time-resolved s = 1 response (algorithm 4) against the quadrature's histogram, coarse bins."""
    _, hist = quadrature
    link = _link(_open_doc(algorithm=4, paths=32_768, batch_size=2048, time_bin_s=2e-10, t_max_s=4e-8))
    mc = np.asarray(link["cir"]["by_scattering_order"][1])
    # The LOS bin's stderr is 0 (exact); elsewhere total and s = 1 share their Monte Carlo error.
    se = np.asarray([v or 0.0 for v in link["cir"]["total_stderr"]])
    big = hist > 0.01 * hist.max()
    assert big.sum() >= 8
    assert np.all(np.abs(mc - hist)[big] <= 5 * se[big] + 0.01 * hist[big])
    assert np.abs(mc - hist)[big].max() < 0.05 * hist.max()


@pytest.mark.parametrize("algorithm", [2, 3, 4, 5])
def test_no_scattering_all_algorithms_equal_algorithm_1(algorithm):
    """sigma_s = 0: every algorithm estimates the same (purely absorbing) channel as algorithm 1."""
    medium = {"type": "homogeneous", "sigma_a": 0.15, "sigma_s": 0.0}
    base = dict(rx=(0.5, 1.0, 0.0), fov_deg=85.0, max_reflections=3, paths=30_000, medium=medium, seed=23)
    one = _link(room_doc(algorithm=1, direction="backward", **base))
    other = _link(room_doc(algorithm=algorithm, direction="forward", **base))
    assert other["los_gain"] == pytest.approx(one["los_gain"], rel=1e-12)
    clear = _link(room_doc(**{**base, "medium": None, "max_reflections": 0}, algorithm=1))
    d = math.dist((2.5, 2.5, 3.0), (0.5, 1.0, 0.0))
    assert one["los_gain"] == pytest.approx(clear["los_gain"] * math.exp(-0.15 * d), rel=1e-12)
    err = math.hypot(one["dc_gain_stderr"], other["dc_gain_stderr"])
    assert within(other["dc_gain"], one["dc_gain"], err)
    assert sum(other["dc_gain_by_scattering_order"][1:]) == 0.0


@pytest.mark.parametrize("sigma_s,g", [(0.1, 0.0), (0.5, 0.9), (1.0, -0.7)])
def test_energy_on_surfaces_non_absorbing_medium(sigma_s, g):
    """Closed room, reflectance rho, medium without absorption: surfaces receive P (1 - rho^K)/(1 - rho)."""
    rho, K = 0.5, 40
    medium = {"type": "homogeneous", "sigma_a": 0.0, "sigma_s": sigma_s, "phase": {"type": "hg", "g": g}}
    doc = room_doc(
        rho,
        rho,
        rho,
        medium=medium,
        algorithm=5,
        direction="forward",
        max_reflections=K,
        max_scattering=1000,
        paths=5_000,
        russian_roulette=False,
        t_max_s=1e-6,
        time_bin_s=1e-8,
    )
    res = simulate(spec(doc))
    assert res["diagnostics"]["escaped_power"]["tx"] == 0.0
    # Scattering without absorption keeps every weight: the sum is exact, with no variance.
    assert res["diagnostics"]["power_on_surfaces"]["tx"] == pytest.approx((1 - rho**K) / (1 - rho), rel=1e-9)


def test_algorithm_5_directions_agree_in_smoke():
    base = dict(medium=SMOKE, algorithm=5, max_reflections=3, max_scattering=3, paths=40_000, seed=31)
    f = _link(room_doc(direction="forward", **base))
    b = _link(room_doc(direction="backward", **base))
    assert within(f["dc_gain"], b["dc_gain"], math.hypot(f["dc_gain_stderr"], b["dc_gain_stderr"]))
    for s in (1, 2):
        ef = f["dc_gain_by_scattering_order_stderr"][s]
        eb = b["dc_gain_by_scattering_order_stderr"][s]
        assert within(f["dc_gain_by_scattering_order"][s], b["dc_gain_by_scattering_order"][s], math.hypot(ef, eb))
    assert f["dc_gain_by_scattering_order"][1] > 0.05 * f["dc_gain"]  # smoke matters here


def test_black_room_single_scattering_families_agree():
    """Reflectance 0: only volume paths. Algorithms 2, 3, 4 and 5 (S = 1) agree on s = 1."""
    base = dict(
        rho_walls=0.0,
        rho_floor=0.0,
        rho_ceiling=0.0,
        medium=SMOKE,
        max_reflections=0,
        paths=30_000,
        seed=41,
        rx=(1.5, 1.0, 0.0),
    )
    links = {
        a: _link(room_doc(algorithm=a, direction="backward" if a == 5 else "auto", max_scattering=1, **base))
        for a in (2, 3, 4, 5)
    }
    ref_s1 = links[4]["dc_gain_by_scattering_order"][1]
    ref_err = links[4]["dc_gain_by_scattering_order_stderr"][1]
    assert ref_err < 0.05 * ref_s1
    for a in (2, 3, 5):
        s1, e = links[a]["dc_gain_by_scattering_order"][1], links[a]["dc_gain_by_scattering_order_stderr"][1]
        assert within(s1, ref_s1, math.hypot(e, ref_err)), (a, s1, ref_s1)


def test_algorithm_5_without_equiangular_points_in_a_box_medium():
    """Algorithm 5 from both devices in smoke filling half the room (points outside it do not scatter): the
    free-flight collisions alone (equiangular_points = 0) and with the equiangular points (the balance heuristic
    of weights.py / segments.scattering_point_throughput) estimate the same H0 and s = 1 gain."""
    from tests.results import simulate_two_sided_document as simulate_two_sided

    smoke = dict(SMOKE, region={"type": "box", "min": [0.0, 0.0, 0.0], "max": [5.0, 2.5, 3.0]})
    doc = room_doc(medium=smoke, algorithm=5, max_reflections=3, max_scattering=2, paths=16_000, seed=5)
    with_points = simulate_two_sided(spec(doc))["links"][0]
    collisions = simulate_two_sided(spec(doc), equiangular_points=0)["links"][0]
    se = math.hypot(with_points["dc_gain_stderr"], collisions["dc_gain_stderr"])
    assert within(collisions["dc_gain"], with_points["dc_gain"], se)
    s1 = [x["dc_gain_by_scattering_order"][1] for x in (with_points, collisions)]
    se1 = math.hypot(*(x["dc_gain_by_scattering_order_stderr"][1] for x in (with_points, collisions)))
    assert within(s1[1], s1[0], se1)
    assert s1[0] > 50 * se1  # power: 4 se is < 8 % of the s = 1 gain (measured ~4 %), so such an error fails
