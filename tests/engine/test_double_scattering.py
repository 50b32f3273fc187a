"""Algorithm 4's double-scattering family (report section 9) and algorithm 5 from both devices,
against independent references (tests/reference_double.py, tests/reference_volume.py)."""

import math

import pytest

from tests.reference_double import double_scattering
from tests.reference_volume import single_scattering
from tests.results import simulate_document as simulate
from tests.results import simulate_two_sided_document as simulate_two_sided
from tests.scenes import SMOKE, open_doc, room_doc, spec, within

# coarse strata: the s = 2 points need not resolve the 1 ns bins for the DC gain (faster per path)
COARSE = {"segment_time_step_s": 5e-9, "max_strata": 8}


_open_doc = open_doc  # the open-medium scene of tests/scenes.py


@pytest.fixture(scope="module")
def h2_ref():
    return double_scattering(3.0, 1.0, 1e-4, 0.2, 0.25, 0.5, n=1_000_000, seed=5)


def _order(link, s):
    return link["dc_gain_by_scattering_order"][s], link["dc_gain_by_scattering_order_stderr"][s]


def test_algorithm_4_double_scattering_against_independent_integral(h2_ref):
    """Unbounded medium: algorithm 4's s = 2 order (Tx -> p_in -> p_out -> Rx) against the plain integrator."""
    h2, h2_se, _ = h2_ref
    link = simulate(spec(_open_doc(algorithm=4, paths=160_000, batch_size=16_384, **COARSE)))["links"][0]
    assert len(link["dc_gain_by_scattering_order"]) == 3
    s2, se = _order(link, 2)
    err = math.hypot(se, h2_se)
    assert err < 0.0125 * h2, (s2, se, h2, h2_se)  # power: a 5 % bias would fail
    assert within(s2, h2, err), (s2, h2, err, (s2 - h2) / err)


def test_algorithm_4_s2_equals_algorithm_5_s2_unbounded():
    """Where the families coincide (no surfaces), algorithm 4's s = 2 is algorithm 5's s = 2 (from both sides)."""
    four = simulate(spec(_open_doc(algorithm=4, paths=60_000, seed=3, **COARSE)))["links"][0]
    five = simulate_two_sided(spec(_open_doc(algorithm=5, max_scattering=2, paths=60_000, seed=4)))["links"][0]
    (a, ea), (b, eb) = _order(four, 2), _order(five, 2)
    assert math.hypot(ea, eb) < 0.05 * b
    assert within(a, b, math.hypot(ea, eb)), (a, b, ea, eb)
    (a1, ea1), (b1, eb1) = _order(four, 1), _order(five, 1)
    assert within(a1, b1, math.hypot(ea1, eb1))


def test_algorithm_4_s2_equals_algorithm_5_s2_black_room():
    """Black room (rho = 0): only volume paths; algorithm 4's s = 2 against algorithm 5's (S = 2)."""
    base = dict(rho_walls=0.0, rho_floor=0.0, rho_ceiling=0.0, medium=SMOKE, max_reflections=0, rx=(1.5, 1.0, 0.0))
    four = simulate(spec(room_doc(algorithm=4, paths=30_000, seed=8, **COARSE, **base)))["links"][0]
    five = simulate_two_sided(spec(room_doc(algorithm=5, max_scattering=2, paths=60_000, seed=9, **base)))["links"][0]
    (a, ea), (b, eb) = _order(four, 2), _order(five, 2)
    assert math.hypot(ea, eb) < 0.05 * b
    assert within(a, b, math.hypot(ea, eb)), (a, b, ea, eb)


def test_algorithm_4_keeps_single_scattering_families():
    """The s <= 1 families of algorithm 4 are unchanged by the s = 2 family (no double counting)."""
    h1, _ = single_scattering(3.0, 1.0, 1e-4, 0.2, 0.25, 0.5, n=64)
    link = simulate(spec(_open_doc(algorithm=4, paths=20_000, **COARSE)))["links"][0]
    s1, se = _order(link, 1)
    assert se < 0.05 * h1
    assert within(s1, h1, se, bias=2e-4 * h1)
    assert link["dc_gain"] == pytest.approx(sum(link["dc_gain_by_scattering_order"]), rel=1e-9)


def test_two_sided_algorithm_5_against_references(h2_ref):
    """Algorithm 5 from both devices (partition of unity): s = 1 against quadrature, s = 2 against the integrator."""
    h1, _ = single_scattering(3.0, 1.0, 1e-4, 0.2, 0.25, 0.5, n=64)
    h2, h2_se, _ = h2_ref
    link = simulate_two_sided(spec(_open_doc(algorithm=5, max_scattering=2, paths=100_000, seed=12)))["links"][0]
    assert link["direction"] == "both"
    s1, se1 = _order(link, 1)
    s2, se2 = _order(link, 2)
    assert se1 < 0.0125 * h1 and math.hypot(se2, h2_se) < 0.025 * h2
    assert within(s1, h1, se1, bias=2e-4 * h1), (s1, h1, se1)
    assert within(s2, h2, math.hypot(se2, h2_se)), (s2, h2, se2)


def test_two_sided_algorithm_5_room_agrees_with_one_sided():
    """Smoke room with reflections: the two-sided estimator and the forward one estimate the same H0."""
    base = dict(medium=SMOKE, algorithm=5, max_reflections=3, max_scattering=3)
    one = simulate(spec(room_doc(direction="backward", paths=40_000, seed=31, **base)))["links"][0]
    two = simulate_two_sided(spec(room_doc(paths=20_000, seed=32, **base)))["links"][0]
    err = math.hypot(one["dc_gain_stderr"], two["dc_gain_stderr"])
    assert err < 0.02 * one["dc_gain"]
    assert within(two["dc_gain"], one["dc_gain"], err)
    for s in (1, 2):
        (a, ea), (b, eb) = _order(two, s), _order(one, s)
        assert within(a, b, math.hypot(ea, eb)), (s, a, b)


@pytest.mark.parametrize("algorithm", [2, 3])
def test_two_sided_single_scattering_families_agree_with_one_sided(algorithm):
    """Algorithms 2 and 3 from both devices (points on one side, scattering branch on the other, partition of
    unity) estimate the same family, reflection order by reflection order, as the one-sided estimator."""
    base = dict(medium=SMOKE, algorithm=algorithm, max_reflections=2, **COARSE)
    side = {2: "backward", 3: "forward"}[algorithm]  # the one-sided estimator of each family
    one = simulate_two_sided(spec(room_doc(paths=40_000, seed=51, **base)), direction=side)["links"][0]
    two = simulate(spec(room_doc(paths=20_000, seed=52, **base)))["links"][0]  # the planner: both devices
    assert two["direction"] == "both" and one["direction"] != "both"
    (a, ea), (b, eb) = _order(two, 1), _order(one, 1)
    assert math.hypot(ea, eb) < 0.03 * b
    assert within(a, b, math.hypot(ea, eb)), (a, b, ea, eb)
    assert within(two["dc_gain"], one["dc_gain"], math.hypot(two["dc_gain_stderr"], one["dc_gain_stderr"]))
    for k in (1, 2):
        ka, kb = two["dc_gain_by_reflection_order"][k], one["dc_gain_by_reflection_order"][k]
        kea, keb = two["dc_gain_by_reflection_order_stderr"][k], one["dc_gain_by_reflection_order_stderr"][k]
        assert within(ka, kb, math.hypot(kea, keb)), (k, ka, kb)


def test_two_sided_with_several_devices_per_link():
    """Two transmitters x two receivers: every link of the two-sided estimators equals the one-sided one."""
    doc = room_doc(medium=SMOKE, max_reflections=2, **COARSE)
    doc["transmitters"].append({"id": "tx2", "position": [1.0, 4.0, 3.0], "normal": [0, 0, -1], "lambertian_order": 2})
    doc["receivers"].append(
        {"id": "rx2", "position": [4.0, 2.0, 0.8], "normal": [0, 0.6, 0.8], "area": 1e-4, "fov_deg": 70}
    )
    for algorithm, extra in ((5, {"max_scattering": 2}), (3, {})):
        one = simulate(
            spec(
                {
                    **doc,
                    "simulation": {
                        **doc["simulation"],
                        "algorithm": algorithm,
                        "paths": 30_000,
                        "seed": 61,
                        "direction": "forward",
                        **extra,
                    },
                }
            )
        )["links"]
        two = simulate_two_sided(
            spec(
                {
                    **doc,
                    "simulation": {**doc["simulation"], "algorithm": algorithm, "paths": 15_000, "seed": 62, **extra},
                }
            )
        )["links"]
        assert len(one) == len(two) == 4
        for a, b in zip(one, two):
            assert (a["transmitter"], a["receiver"]) == (b["transmitter"], b["receiver"])
            err = math.hypot(a["dc_gain_stderr"], b["dc_gain_stderr"])
            assert err < 0.03 * a["dc_gain"], (algorithm, a["receiver"], err / a["dc_gain"])
            assert within(b["dc_gain"], a["dc_gain"], err), (algorithm, a["transmitter"], a["receiver"])
            (x, ex), (y, ey) = _order(b, 1), _order(a, 1)
            assert within(x, y, math.hypot(ex, ey)), (algorithm, a["receiver"], x, y)


def test_two_sided_without_medium_counts_each_path_once():
    """Algorithm 5 from both devices in a clear room: each side counts half of the surface paths."""
    doc = room_doc(algorithm=5, max_scattering=2, max_reflections=3)
    one = simulate(spec({**doc, "simulation": {**doc["simulation"], "paths": 20_000, "seed": 71}}))["links"][0]
    two = simulate_two_sided(spec({**doc, "simulation": {**doc["simulation"], "paths": 20_000, "seed": 72}}))
    link = two["links"][0]
    err = math.hypot(one["dc_gain_stderr"], link["dc_gain_stderr"])
    assert err < 0.01 * one["dc_gain"] and within(link["dc_gain"], one["dc_gain"], err)
