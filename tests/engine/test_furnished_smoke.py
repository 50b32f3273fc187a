"""Algorithm 5 from both devices in a furnished room (issue 22, item 1).

When every shadow ray of a connection step was blocked (a desk between the last vertices and the
receiver), `BatchContext.connect` handed zero connections to weights.connection_weight, whose
`depth.min()` raised "zero-size array to reduction operation minimum": 4 of 8 seeds of a smoky
office crashed, mostly in the automatic settings' pilot (K and S up to 40, few deep paths). The seeds
below crashed before the fix. Each result is checked against an independent estimate of the same
family: algorithm 1 where the smoke only absorbs (the families coincide: no scattering), and
algorithm 5 run from the transmitter alone (no partition of unity, no connection_weight) where it
scatters.
"""

import copy

import numpy as np

from owcsim.api import simulate
from tests.scenes import within

#: A 6 x 4 x 3 m office with four desks (4 cm tops at 0.72-0.76 m), Tx at the ceiling centre, two
#: photodiodes lying on two of the desks.
OFFICE = {
    "room": {"size": [6, 4, 3], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": 0.6}},
    "furniture": [
        {"name": "desk1", "min": [0.8, 0.6, 0.72], "max": [2.4, 1.4, 0.76], "reflectance": 0.5},
        {"name": "desk2", "min": [3.4, 0.6, 0.72], "max": [5.0, 1.4, 0.76], "reflectance": 0.5},
        {"name": "desk3", "min": [0.8, 2.6, 0.72], "max": [2.4, 3.4, 0.76], "reflectance": 0.5},
        {"name": "desk4", "min": [3.4, 2.6, 0.72], "max": [5.0, 3.4, 0.76], "reflectance": 0.5},
    ],
    "transmitters": [{"id": "tx", "position": [3, 2, 3], "normal": [0, 0, -1], "lambertian_order": 1}],
    "receivers": [
        {"id": "rx1", "position": [1.6, 1.0, 0.76], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 70},
        {"id": "rx2", "position": [4.2, 3.0, 0.76], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 70},
    ],
}
SMOKE = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.7}}
ABSORBING = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.0}


def _office(medium, **simulation):
    doc = copy.deepcopy(OFFICE)
    doc["medium"] = medium
    doc["simulation"] = simulation
    return doc


def _compare(result, reference):
    """Every link within 4 combined standard errors of the reference, and a planted 5 % error outside."""
    for link, ref in zip(result.links, reference.links, strict=True):
        assert np.isfinite(link.dc_gain) and link.dc_gain_stderr > 0
        se = float(np.hypot(link.dc_gain_stderr, ref.dc_gain_stderr))
        assert within(link.dc_gain, ref.dc_gain, se), (link.receiver, link.dc_gain, ref.dc_gain, se)
        assert not within(1.05 * link.dc_gain, ref.dc_gain, se)  # the comparison has the power to see 5 %


def test_absorbing_smoke_in_a_furnished_room_agrees_with_algorithm_1():
    """Algorithm 5 (both devices, automatic K) against algorithm 1 at the K it chose (sigma_s = 0)."""
    result = simulate(_office(ABSORBING, algorithm=5, paths=20_000, pilot_paths=1024, seed=0))  # crashed before
    assert result.modeled.max_reflections >= 10
    assert result.run.direction_choice.rule.startswith("algorithm 5 in a medium: every link from both devices")
    reference = simulate(
        _office(
            ABSORBING,
            algorithm=1,
            max_reflections=result.modeled.max_reflections,
            t_max_s=result.modeled.time_window_s[1],
            paths=20_000,
            seed=100,
        )
    )
    _compare(result, reference)


def test_scattering_smoke_in_a_furnished_room_agrees_with_one_sided_algorithm_5():
    """The automatic choice (algorithm 5 from both devices) against algorithm 5 from the transmitter alone at
    the K, S and window it chose."""
    result = simulate(_office(SMOKE, paths=20_000, pilot_paths=1024, seed=0))  # crashed before
    modeled = result.modeled
    assert modeled.algorithm == 5 and modeled.max_scattering >= 5
    reference = simulate(
        _office(
            SMOKE,
            algorithm=5,
            direction="forward",
            max_reflections=modeled.max_reflections,
            max_scattering=modeled.max_scattering,
            t_max_s=modeled.time_window_s[1],
            paths=40_000,
            seed=100,
        )
    )
    assert reference.run.direction_choice is None or "both devices" not in reference.run.direction_choice.rule
    _compare(result, reference)
