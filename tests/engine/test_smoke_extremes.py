"""Smoke at the extremes users will hit (physics.md section 5): finite numbers and the right limits."""

import json
import math

import numpy as np
import pytest

from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec, within


def _medium(sigma_a=0.05, sigma_s=0.2, phase=None, **kw):
    return {
        "type": "homogeneous",
        "sigma_a": sigma_a,
        "sigma_s": sigma_s,
        "phase": phase or {"type": "hg", "g": 0.7},
        **kw,
    }


def _finite(res):
    text = json.dumps(res)
    assert "NaN" not in text and "Infinity" not in text
    for link in res["links"]:
        assert link["dc_gain"] >= 0 and np.isfinite(link["dc_gain"])
        assert all(v >= 0 for v in link["cir"]["total"])


EXTREMES = {
    "g=0": dict(medium=_medium(phase={"type": "hg", "g": 0.0})),
    "g=+0.999": dict(medium=_medium(phase={"type": "hg", "g": 0.999})),
    "g=-0.999": dict(medium=_medium(phase={"type": "hg", "g": -0.999})),
    "schlick k=+0.999": dict(medium=_medium(phase={"type": "schlick", "k": 0.999})),
    "schlick k=-0.999": dict(medium=_medium(phase={"type": "schlick", "k": -0.999})),
    "rayleigh mixture": dict(
        medium=_medium(
            phase={
                "type": "mixture",
                "components": [
                    {"weight": 0.7, "phase": {"type": "hg", "g": 0.9}},
                    {"weight": 0.3, "phase": {"type": "rayleigh"}},
                ],
            }
        )
    ),
    "optical depth 50": dict(medium=_medium(sigma_a=10.0, sigma_s=5.0)),
    "m=1000": dict(medium=_medium(), m=1000.0),
    "FOV 1 deg": dict(medium=_medium(), rx=(2.5, 2.5, 0.0), fov_deg=1.0),
    "rx 1 mm from a wall": dict(medium=_medium(), rx=(0.001, 2.5, 1.5), rx_normal=(1, 0, 0)),
}


@pytest.mark.parametrize("algorithm", [2, 3, 4, 5])
@pytest.mark.parametrize("case", sorted(EXTREMES))
def test_extremes_are_finite(case, algorithm):
    kw = dict(EXTREMES[case])
    doc = room_doc(
        algorithm=algorithm,
        paths=2048,
        batch_size=1024,
        max_reflections=2,
        time_bin_s=1e-9,
        t_max_s=1e-7,
        **({"max_scattering": 2} if algorithm in (4, 5) else {}),  # 2-3 count S = 1 (another S is refused)
        **kw,
    )
    _finite(simulate(spec(doc)))


def test_sigma_t_zero_is_vacuum_exactly():
    """sigma_t = 0: no medium at all; every algorithm reduces to the vacuum estimate, bit for bit."""
    vac = {
        d: simulate(spec(room_doc(algorithm=1, direction=d, paths=4096)))["links"][0] for d in ("forward", "backward")
    }
    for algorithm in (2, 3, 4, 5):
        doc = room_doc(algorithm=algorithm, direction="forward", paths=4096, medium=_medium(0.0, 0.0))
        link = simulate(spec(doc))["links"][0]
        if algorithm != 4:  # 2 runs backward, 3 and 5 (as asked) forward; 4 both: same expectation, other paths
            assert link["dc_gain"] == vac["backward" if algorithm == 2 else "forward"]["dc_gain"]
        assert link["dc_gain_by_scattering_order"][1:] == [0.0] * (len(link["dc_gain_by_scattering_order"]) - 1)


def test_sigma_t_tiny_is_vacuum_limit():
    vac = simulate(spec(room_doc(algorithm=1, direction="backward", paths=8192)))["links"][0]
    tiny = simulate(spec(room_doc(algorithm=1, direction="backward", paths=8192, medium=_medium(1e-9, 0.0))))["links"][
        0
    ]
    assert tiny["dc_gain"] == pytest.approx(vac["dc_gain"], rel=1e-7) and tiny["dc_gain"] < vac["dc_gain"]
    five = simulate(spec(room_doc(algorithm=5, direction="backward", paths=8192, medium=_medium(0.0, 1e-9))))["links"][
        0
    ]
    assert within(five["dc_gain"], vac["dc_gain"], math.hypot(five["dc_gain_stderr"], vac["dc_gain_stderr"]))


def test_optical_depth_50_line_of_sight():
    d = math.dist((2.5, 2.5, 3.0), (1.0, 1.0, 0.0))
    sigma_t = 50.0 / d
    vac = simulate(spec(room_doc(max_reflections=0, paths=64)))["links"][0]
    thick = simulate(spec(room_doc(max_reflections=0, paths=64, medium=_medium(sigma_t, 0.0))))["links"][0]
    assert thick["los_gain"] == pytest.approx(vac["los_gain"] * math.exp(-50.0), rel=1e-9)
    assert thick["los_gain"] > 0


def test_hg_g0_is_isotropic_bit_for_bit():
    """g -> 0: Henyey-Greenstein is the isotropic phase function (same samples, same values)."""
    base = dict(algorithm=5, direction="forward", paths=4096, max_scattering=3)
    hg0 = simulate(spec(room_doc(medium=_medium(phase={"type": "hg", "g": 0.0}), **base)))["links"][0]
    iso = simulate(spec(room_doc(medium=_medium(phase={"type": "isotropic"}), **base)))["links"][0]
    assert hg0["dc_gain"] == pytest.approx(iso["dc_gain"], rel=1e-12)


def test_forward_peaked_phase_is_flagged():
    """|g| -> 1: next-event estimates toward point devices are heavy-tailed; the result says so."""
    res = simulate(spec(room_doc(algorithm=5, paths=2048, medium=_medium(phase={"type": "hg", "g": 0.999}))))
    assert any("heavy-tailed" in w for w in res["warnings"])
    calm = simulate(spec(room_doc(algorithm=5, paths=2048, medium=_medium())))
    assert not any("heavy-tailed" in w for w in calm["warnings"])


def test_smoke_far_from_origin():
    shift = np.array([5000.0, -3000.0, 200.0])
    base = dict(algorithm=5, direction="forward", paths=20_000, seed=4, max_scattering=2)
    near = simulate(spec(room_doc(medium=_medium(), **base)))["links"][0]
    far_medium = _medium(region={"type": "box", "min": list(shift), "max": list(shift + (5, 5, 3))})
    far = simulate(
        spec(room_doc(origin=shift, tx=shift + (2.5, 2.5, 3.0), rx=shift + (1.0, 1.0, 0.0), medium=far_medium, **base))
    )["links"][0]
    assert far["los_gain"] == pytest.approx(near["los_gain"], rel=1e-9)
    assert within(far["dc_gain"], near["dc_gain"], math.hypot(far["dc_gain_stderr"], near["dc_gain_stderr"]))


@pytest.mark.parametrize("algorithm", [3, 5])
def test_box_region_containing_everything_equals_whole_scene(algorithm):
    base = dict(algorithm=algorithm, direction="forward", paths=8192, seed=2)
    base.update(max_scattering=2 if algorithm == 5 else 1)  # algorithm 3 counts S = 1 (another S is refused)
    whole = simulate(spec(room_doc(medium=_medium(), **base)))["links"][0]
    boxed = simulate(
        spec(room_doc(medium=_medium(region={"type": "box", "min": [-1, -1, -1], "max": [6, 6, 4]}), **base))
    )["links"][0]
    assert boxed["dc_gain"] == pytest.approx(whole["dc_gain"], rel=1e-9)


def test_uniform_grid_equals_homogeneous():
    base = dict(algorithm=5, direction="forward", paths=8192, seed=2, max_scattering=2)
    homo = simulate(spec(room_doc(medium=_medium(region={"type": "box", "min": [0, 0, 0], "max": [5, 5, 3]}), **base)))[
        "links"
    ][0]
    grid = {
        "type": "grid",
        "min": [0, 0, 0],
        "max": [5, 5, 3],
        "shape": [4, 3, 2],
        "sigma_a": 0.05,
        "sigma_s": [0.2] * 24,
        "phase": {"type": "hg", "g": 0.7},
    }
    gridded = simulate(spec(room_doc(medium=grid, **base)))["links"][0]
    assert within(gridded["dc_gain"], homo["dc_gain"], math.hypot(gridded["dc_gain_stderr"], homo["dc_gain_stderr"]))
    assert gridded["dc_gain"] == pytest.approx(homo["dc_gain"], rel=1e-6)  # same paths up to rounding


def test_smoke_layer_costs_nothing_below_it():
    """Smoke in the top 0.5 m: segments that never enter it are not evaluated (counted, not timed)."""
    layer = _medium(region={"type": "box", "min": [0, 0, 2.5], "max": [5, 5, 3.0]})
    res = simulate(
        spec(
            room_doc(algorithm=1, direction="backward", rx=(1.0, 1.0, 0.0), paths=4096, max_reflections=1, medium=layer)
        )
    )
    clear = simulate(
        spec(room_doc(algorithm=1, direction="backward", rx=(1.0, 1.0, 0.0), paths=4096, max_reflections=1))
    )
    evaluations = res["diagnostics"]["medium_evaluations"]
    segments = res["run"]["rays_intersect"] + res["run"]["rays_occluded"] + 4096  # rays + NEE segments (upper bound)
    assert 0 < evaluations < 0.75 * segments
    assert clear["diagnostics"]["medium_evaluations"] == 0
