"""Model only what the scene requires: automatic algorithm, orders and window, and the modeled report."""

import warnings

import pytest

from owcsim.engine.core.errors import SceneError
from tests.results import simulate_document as simulate
from tests.scenes import barry_doc, room_doc, spec

SMOKE = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.7}}


def _auto_doc(medium=None, **simulation):
    doc = barry_doc()
    doc["simulation"] = {"paths": 20_000, "seed": 3, **simulation}
    if medium is not None:
        doc["medium"] = medium
    return doc


@pytest.mark.parametrize(
    "medium,algorithm,reason,keeps_medium",
    [
        (None, 1, "no medium", False),
        ({"type": "homogeneous", "sigma_a": 0.0, "sigma_s": 0.0}, 1, "sigma_t = 0", False),
        ({"type": "homogeneous", "sigma_a": 0.2, "sigma_s": 0.0}, 1, "sigma_s = 0", True),
        (SMOKE, 5, "scattering medium", True),
    ],
)
def test_auto_algorithm_per_scene_type(medium, algorithm, reason, keeps_medium):
    res = simulate(spec(_auto_doc(medium, max_reflections=3, t_max_s=2e-7)))
    assert res["algorithm"] == algorithm
    assert reason in res["modeled"]["algorithm_reason"]
    assert (res["diagnostics"]["medium_evaluations"] > 0) == keeps_medium
    assert res["scene"]["simulation"]["algorithm"] == "auto"  # the input is echoed as given


def test_explicit_settings_win():
    res = simulate(spec(_auto_doc(SMOKE, algorithm=3, max_reflections=2, t_max_s=1e-7, paths=2048)))
    assert res["algorithm"] == 3 and res["modeled"]["max_reflections"] == 2
    assert res["modeled"]["pilot"] is None and res["time_bins"]["n_bins"] == 400
    assert "algorithm 3 requested" in res["modeled"]["algorithm_reason"]


def test_automatic_window_over_the_bin_budget_is_a_located_error():
    # The window is chosen by the pilot; a bin width it cannot afford is the user's to fix, said plainly.
    with pytest.raises(SceneError, match=r"automatic time window 0\.\.[0-9.e-]+ s at 1e-15 s per bin .*`t_max_s`"):
        simulate(spec(_auto_doc(max_reflections=2, time_bin_s=1e-15, t_max_s=None, paths=256)))


def test_window_far_after_every_arrival_counts_them_early_without_warnings():
    # Every arrival (LOS included) precedes the window: all of it is early power, no bin index overflows.
    doc = _auto_doc(algorithm=1, max_reflections=1, t_min_s=0.5, t_max_s=0.5 + 1e-10, time_bin_s=1e-15, paths=2048)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = simulate(spec(doc))
    link = res["links"][0]
    assert link["dc_gain"] > 0 and sum(link["cir"]["total"]) == 0
    assert link["early_gain"] == pytest.approx(link["dc_gain"], rel=1e-12)


def test_auto_truncation_within_its_bound_of_a_long_run():
    """Same seed, same paths: the long run differs from the auto one by exactly the truncated orders.

    K also bounds the shifts of tau0 and tau_rms (a late tail weighted by its delay), which needs
    more orders than the power alone: at 3e-2, K stays low enough for 40 000 paths to reach past it."""
    auto = simulate(spec(_auto_doc(paths=40_000, truncation_tolerance=3e-2)))
    K = auto["modeled"]["max_reflections"]
    allowed = auto["modeled"]["pilot"]["allowed_truncation_per_watt"]
    assert 3 < K < 60 and f"capped at {K}" in auto["modeled"]["max_reflections_reason"]
    long = simulate(spec(_auto_doc(paths=40_000, max_reflections=100, t_max_s=auto["modeled"]["time_window_s"][1])))
    missing = long["links"][0]["dc_gain"] - auto["links"][0]["dc_gain"]
    assert 0 <= missing <= allowed
    assert missing > 0  # the long run does carry orders above K: the check has something to check
    assert auto["links"][0]["truncated_gain_estimate"] <= allowed
    lk, la = long["links"][0], auto["links"][0]
    for key in ("mean_delay_s", "rms_delay_spread_s"):  # each within half the tolerance x tau_rms
        assert abs(lk[key] - la[key]) <= 0.5 * 3e-2 * lk["rms_delay_spread_s"], key
    assert "RMS delay spread" in auto["modeled"]["max_reflections_reason"]
    assert f"reflection orders above K = {K}" in auto["modeled"]["left_out"]


@pytest.mark.parametrize("medium", [None, SMOKE])
def test_auto_window_keeps_late_power_under_its_bound(medium):
    res = simulate(spec(_auto_doc(medium, paths=20_000)))
    allowed = res["modeled"]["pilot"]["allowed_truncation_per_watt"]
    link = res["links"][0]
    assert link["late_gain"] <= allowed / 2
    assert res["time_bins"]["n_bins"] * res["time_bins"]["time_bin_s"] == pytest.approx(
        res["modeled"]["time_window_s"][1]
    )
    assert "window ends at" in res["modeled"]["time_window_reason"]


def test_accuracy_target_sets_the_tolerance():
    res = simulate(spec(_auto_doc(target_rel_error=0.01, paths=None)))
    assert res["run"]["stop_reason"] == "target_reached"
    allowed = res["modeled"]["pilot"]["allowed_truncation_per_watt"]
    h0 = res["links"][0]["dc_gain"]
    assert allowed == pytest.approx(0.1 * 0.01 * h0, rel=0.1)  # a tenth of the target standard error


def test_unreachable_receiver_is_reported_not_simulated():
    doc = room_doc(paths=4096)
    doc["furniture"] = [{"name": "cabinet", "min": [3.0, 1.0, 0.0], "max": [4.0, 2.0, 1.5], "reflectance": 0.5}]
    doc["receivers"].append({"id": "stuck", "position": [3.0, 1.5, 0.7], "normal": [1, 0, 0], "area": 1e-4})
    res = simulate(spec(doc))
    stuck = res["links"][1]
    assert stuck["receiver"] == "stuck" and stuck["paths"] == 0 and stuck["dc_gain"] == 0.0
    assert stuck["direction"] == "none"
    assert res["modeled"]["unreachable_receivers"][0]["receiver"] == "stuck"
    assert res["links"][0]["paths"] == 4096 and res["links"][0]["dc_gain"] > 0


@pytest.mark.parametrize("stopping", [{"paths": 4096}, {"paths": None, "target_rel_error": 0.05, "time_budget_s": 5.0}])
def test_every_receiver_unreachable_ends_at_once_with_zero_gain(stopping):
    # Used to crash (no tally to combine) with a fixed budget and loop forever in accuracy mode.
    doc = room_doc(**stopping)
    doc["furniture"] = [{"name": "cabinet", "min": [3.0, 1.0, 0.0], "max": [4.0, 2.0, 1.5], "reflectance": 0.5}]
    doc["receivers"] = [{"id": "stuck", "position": [3.0, 1.5, 0.7], "normal": [1, 0, 0], "area": 1e-4}]
    res = simulate(spec(doc))
    assert res["run"]["stop_reason"] == "nothing_to_simulate" and res["run"]["paths_total"] == 0
    link = res["links"][0]
    assert link["dc_gain"] == 0.0 and link["dc_gain_stderr"] == 0.0 and link["direction"] == "none"
    assert res["modeled"]["unreachable_receivers"][0]["receiver"] == "stuck"


def test_receiver_on_the_floor_with_a_grazing_normal_is_simulated():
    # Half its field of view looks into the floor, half into the room: the transmitter is in view.
    doc = barry_doc(paths=8192, max_reflections=1)
    doc["receivers"][0]["normal"] = [1.0, 0.0, 1e-13]
    res = simulate(spec(doc))
    link = res["links"][0]
    assert res["modeled"]["unreachable_receivers"] == []
    assert link["los_gain"] > 0 and link["dc_gain"] > link["los_gain"]


def test_clear_scene_pays_nothing_for_smoke_support():
    res = simulate(spec(_auto_doc(max_reflections=3, t_max_s=2e-7)))
    assert res["diagnostics"]["medium_evaluations"] == 0 and res["algorithm"] == 1
    assert res["modeled"]["families"].startswith("vacuum")


def test_receiver_too_large_for_the_point_model_is_warned():
    # A 1 cm receiver 0.1 mm from the transmitter: A cos / d^2 exceeds 1; the result says why.
    doc = barry_doc(paths=1024, max_reflections=1)
    doc["room"]["size"] = [1e-4, 1e-4, 1e-4]
    doc["transmitters"][0]["position"] = [5e-5, 5e-5, 1e-4]
    doc["receivers"][0]["position"] = [2e-5, 2e-5, 0.0]
    res = simulate(spec(doc))
    assert res["links"][0]["dc_gain"] > 1
    assert any("too large for the point-receiver model" in w for w in res["warnings"])
    assert not any("point-receiver" in w for w in simulate(spec(barry_doc(paths=1024)))["warnings"])


def test_paths_total_counts_paths_traced_and_a_narrow_window_is_warned():
    doc = room_doc(paths=2048, direction="forward", t_min_s=1.4e-8, t_max_s=2e-8)
    doc["transmitters"].append({"id": "tx2", "position": [1.0, 4.0, 3.0], "normal": [0, 0, -1], "lambertian_order": 1})
    doc["receivers"].append({"id": "rx2", "position": [4.0, 1.0, 0.0], "normal": [0, 0, 1], "area": 1e-4})
    res = simulate(spec(doc))
    # two transmitters x 2048 forward paths, each serving both receivers: 4096 paths, not 8192 path-link pairs
    assert res["run"]["paths_total"] == 4096 and all(lk["paths"] == 2048 for lk in res["links"])
    assert any("outside the time window" in w for w in res["warnings"])
    assert not any("outside the time window" in w for w in simulate(spec(room_doc(paths=2048)))["warnings"])
