"""Automatic truncation of S when the medium does not absorb (sigma_a = 0), and true `modeled` statements."""

import math

import numpy as np

from owcsim.engine.results.truncation import tail_ratio
from owcsim.engine.run.tail import delay_shift, tail_moments
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec

WHITE_SMOKE = {"type": "homogeneous", "sigma_a": 0.0, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.9}}


def test_tail_ratio_fit_by_hand():
    """Gains 2^-j measured to 1 %: the fitted ratio is 1/2 (plus 2 se of the slope); bound 1 -> the fit is used."""
    g = 0.5 ** np.arange(12)
    r, how = tail_ratio(g, 0.01 * g, 1.0)
    x = np.arange(4, 12, dtype=float)  # orders 1..11 measured to 1 %; the last 8 are fitted
    se = math.sqrt(0.01**2 / ((x - x.mean()) ** 2).sum())  # var(log g) = 0.01^2 per order
    assert abs(r - np.exp(np.log(0.5) + 2 * se)) < 1e-12
    assert "fit" in how
    assert tail_ratio(g, 0.01 * g, 0.3)[0] == 0.3  # an a-priori bound below the fit wins
    assert math.isinf(tail_ratio(np.ones(12), 0.01 * np.ones(12), 1.0)[0])  # no decay: no finite bound


def test_tail_moments_and_delay_shift_by_hand():
    """One geometric tail: P = g_L r / (1 - r) past the last order; the delay shift of dropping power p at time t."""
    g = np.array([1.0, 0.5, 0.25])
    t1 = np.array([1.0, 2.0, 3.0])
    p, p1, p2 = tail_moments(2, g, np.zeros(3), t1, t1**2, 0.5)
    assert p == 0.25 * 1.0  # sum r^i = 1 for r = 1/2
    assert p1 == 0.25 * (3.0 * 1.0 + 1.0 * 2.0)  # base 3, step 1: sum i r^i = 2
    # drop power 1 at t = 3 from a link of gain 2, mean delay 2, spread 1 (moments: 2, 4, 10)
    d0, d_rms = delay_shift(2.0, 2.0, 1.0, 1.0, 3.0, 9.0)
    assert d0 == 1.0 and d_rms == 1.0  # what remains: gain 1 at t = 1 (mean 1, spread 0)


def test_non_absorbing_smoke_room_gets_a_finite_stated_bound():
    """sigma_a = 0 (albedo 1): S is chosen from the pilot's measured decay and the bound is finite and stated;
    the long run's power above the chosen S stays within it (plus 4 of its standard errors)."""
    doc = room_doc(medium=WHITE_SMOKE, paths=20_000)
    doc["simulation"] = {"paths": 20_000, "seed": 3, "max_reflections": 8}
    auto = simulate(spec(doc))
    modeled = auto["modeled"]
    S = modeled["max_scattering"]
    assert "per order" in modeled["max_scattering_reason"] and "inf" not in modeled["max_scattering_reason"]
    assert modeled["truncation_estimate_per_watt"] is not None and modeled["truncation_estimate_per_watt"] >= 0
    bound = modeled["truncation_estimate_per_watt"]
    long = simulate(
        spec(
            room_doc(
                medium=WHITE_SMOKE,
                algorithm=5,
                max_reflections=8,
                max_scattering=S + 30,
                paths=20_000,
                seed=4,
                t_max_s=modeled["time_window_s"][1],
            )
        )
    )["links"][0]
    above = sum(long["dc_gain_by_scattering_order"][S + 1 :])
    above_se = math.sqrt(sum(e**2 for e in long["dc_gain_by_scattering_order_stderr"][S + 1 :]))
    assert above <= bound + 4 * above_se, (S, above, bound, above_se)


def test_unbounded_non_absorbing_medium_says_no_bound():
    """No walls and sigma_a = 0: the per-order gains decay too slowly for a geometric bound; the result says so."""
    doc = {
        "transmitters": [{"id": "tx", "position": [0, 0, 0], "normal": [1, 0, 0], "lambertian_order": 1}],
        "receivers": [{"id": "rx", "position": [3, 0, 0], "normal": [-1, 0, 0], "area": 1e-4, "fov_deg": 90}],
        "medium": {**WHITE_SMOKE, "phase": {"type": "hg", "g": 0.0}},
        "simulation": {"paths": 4096, "seed": 3, "pilot_paths": 2048},
    }
    res = simulate(spec(doc))
    reason = res["modeled"]["max_scattering_reason"]
    assert res["modeled"]["truncation_estimate_per_watt"] is None
    assert "no finite bound" in reason and f"capped at {res['modeled']['pilot']['max_scattering']}" in reason
    assert res["links"][0]["truncated_gain_estimate"] is None
