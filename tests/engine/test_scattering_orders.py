"""`simulation.max_scattering` S per algorithm (schemas/algorithms.py): algorithm 4 honours S = 1 (no
double-scattering family) and S = 2 (the default); an S an algorithm cannot honour is refused in one sentence.

References: the single-scattering volume quadrature of tests/reference_volume.py and the exact line of sight,
both independent of the engine; algorithm 5 from both devices where the families coincide (no surfaces)."""

import math

import pytest
from pydantic import ValidationError

from tests.reference_volume import single_scattering
from tests.results import simulate_document as simulate
from tests.results import simulate_two_sided_document as simulate_two_sided
from tests.scenes import open_doc, spec, within

# coarse strata: the points need not resolve the 1 ns bins for the DC gain (as test_double_scattering.py)
COARSE = {"segment_time_step_s": 5e-9, "max_strata": 8}
# tests/scenes.SMOKE in the open scene: D = 3 m, m = 1, A = 1e-4 m^2, sigma_s 0.2, sigma_t 0.25, HG g 0.5
D, AREA, SIGMA_S, SIGMA_T, G = 3.0, 1e-4, 0.2, 0.25, 0.5


def _los() -> float:
    """Exact line of sight of the open scene: (m + 1) A / (2 pi D^2) exp(-sigma_t D), m = 1, on axis."""
    return 2.0 * AREA / (2.0 * math.pi * D * D) * math.exp(-SIGMA_T * D)


@pytest.fixture(scope="module")
def h1():
    return single_scattering(D, 1.0, AREA, SIGMA_S, SIGMA_T, G, n=64)[0]


@pytest.fixture(scope="module")
def four_s1():
    return simulate(spec(open_doc(algorithm=4, max_scattering=1, paths=50_000, seed=61, **COARSE)))


@pytest.fixture(scope="module")
def four_s2():
    return simulate(spec(open_doc(algorithm=4, max_scattering=2, paths=50_000, seed=62, **COARSE)))


def test_algorithm_4_with_s_1_counts_single_scattering_only(four_s1, h1):
    """S = 1: orders 0 and 1 only, and H0 = LOS + single scattering (quadrature) within 4 SE; the power check:
    4 SE is under 5 % of the scattered part, and under the s = 2 part the run must leave out."""
    link = four_s1["links"][0]
    assert four_s1["modeled"]["max_scattering"] == 1
    assert len(link["dc_gain_by_scattering_order"]) == 2
    assert any("s >= 2" in x for x in four_s1["modeled"]["left_out"])
    assert "in-then-out" not in four_s1["modeled"]["families"]
    assert link["dc_gain_by_scattering_order"][0] == pytest.approx(_los(), rel=1e-9)
    scattered, se = link["dc_gain"] - _los(), link["dc_gain_stderr"]
    assert 4 * se < 0.05 * h1
    assert within(scattered, h1, se, bias=2e-4 * h1), (scattered, h1, se, (scattered - h1) / se)


def test_algorithm_4_s_1_is_the_s_le_1_part_of_s_2(four_s1, four_s2):
    """The order split: S = 1's H0 equals S = 2's orders 0 + 1 (independent seeds, within 4 SE), and S = 2's
    order 2 is far outside that tolerance (ignoring S = 1 would fail here)."""
    one, two = four_s1["links"][0], four_s2["links"][0]
    assert len(two["dc_gain_by_scattering_order"]) == 3
    s0, s1, s2 = two["dc_gain_by_scattering_order"]
    _, se1, se2 = two["dc_gain_by_scattering_order_stderr"]
    assert s0 == one["dc_gain_by_scattering_order"][0]  # the exact line of sight, the same in both
    err = math.hypot(one["dc_gain_stderr"], se1)
    assert 4 * err < 0.05 * s1  # power: a 5 % error of the single-scattering part would fail
    assert within(one["dc_gain"], s0 + s1, err), (one["dc_gain"], s0 + s1, err)
    assert s2 - 4 * se2 > 4 * err  # the double-scattering order the S = 1 run must not count
    assert two["dc_gain"] == pytest.approx(s0 + s1 + s2, rel=1e-9)


def test_algorithm_4_s_1_agrees_with_algorithm_5_s_1(four_s1):
    """No surfaces: the s <= 1 families of algorithms 4 and 5 coincide (Tx -> p -> Rx); H0 within 4 SE."""
    five = simulate_two_sided(spec(open_doc(algorithm=5, max_scattering=1, paths=40_000, seed=63)))["links"][0]
    four = four_s1["links"][0]
    err = math.hypot(four["dc_gain_stderr"], five["dc_gain_stderr"])
    assert 4 * err < 0.05 * (five["dc_gain"] - _los())
    assert within(four["dc_gain"], five["dc_gain"], err), (four["dc_gain"], five["dc_gain"], err)


def test_algorithm_4_default_s_is_2_bit_for_bit():
    """Leaving S out is S = 2: the same bits (the default estimator is unchanged)."""
    base = dict(algorithm=4, paths=4096, seed=64, **COARSE)
    default = simulate(spec(open_doc(**base)))
    explicit = simulate(spec(open_doc(max_scattering=2, **base)))
    assert default["links"] == explicit["links"]
    assert default["modeled"]["max_scattering"] == 2


@pytest.mark.parametrize(
    "algorithm,S,words",
    [
        (1, 1, "algorithm 1 counts only unscattered light (S = 0)"),
        (2, 2, "algorithm 2 counts single scattering only (S = 1)"),
        (3, 2, "algorithm 3 counts single scattering only (S = 1)"),
        (4, 3, "give 1 or 2, or use algorithm 5 for higher orders"),
        (4, 0, "`max_scattering` 0 cannot be honoured"),
        (5, 0, "algorithm 5 counts scattering orders 1 to S"),
        ("auto", 0, "`max_scattering` 0 (no scattering) needs `algorithm` 1"),
    ],
)
def test_an_s_the_algorithm_cannot_honour_is_refused(algorithm, S, words):
    with pytest.raises(ValidationError) as err:
        spec(open_doc(algorithm=algorithm, max_scattering=S))
    messages = [e["msg"] for e in err.value.errors()]
    assert len(messages) == 1 and words in messages[0], messages


@pytest.mark.parametrize("algorithm,S", [(1, 0), (2, 1), (3, 1), (4, 1), (4, 2), (5, 1), (5, 1000), ("auto", 7)])
def test_an_s_the_algorithm_honours_is_accepted(algorithm, S):
    assert spec(open_doc(algorithm=algorithm, max_scattering=S)).simulation.max_scattering == S


def test_algorithm_4_s_1_holds_through_the_automatic_settings():
    """K and the window chosen by the pilot (engine/run/auto.py): the run and its pilot keep S = 1."""
    res = simulate(
        spec(open_doc(algorithm=4, max_scattering=1, max_reflections=None, t_max_s=None, paths=2048, **COARSE))
    )
    assert res["modeled"]["max_scattering"] == 1 and res["modeled"]["pilot"]["max_scattering"] == 1
    assert len(res["links"][0]["dc_gain_by_scattering_order"]) == 2
