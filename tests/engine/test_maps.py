"""Coverage maps: closed-form line of sight, summed transmitter groups, running moments, masks, memory bound."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from owcsim.engine.run import simulate as simulate_module
from owcsim.engine.run.simulate import PATH_TARGET_BUDGET, batch_size, kernel_settings
from owcsim.engine.scene.scene import build_scene
from owcsim.engine.tally.tally import BatchBuilder
from tests.results import simulate_document as simulate
from tests.scenes import EXAMPLES, room_doc, spec, within

LEDS = [(1.25, 1.25), (1.25, 3.75), (3.75, 1.25), (3.75, 3.75)]


def komine_doc(spacing=0.5, **simulation) -> dict:
    doc = json.loads((EXAMPLES / "komine_map.json").read_text())
    doc["receiver_grids"][0]["spacing"] = spacing
    doc["simulation"] = {"seed": 3, **simulation}
    return doc


def _closed_form_los(points, normal, area, fov_deg, half_angle_deg):
    """H_los summed over the 4 LEDs facing down at z = 3: (m+1)/(2 pi) cos^m(phi) A cos(psi) / d^2 (psi <= FOV)."""
    m = -math.log(2) / math.log(math.cos(math.radians(half_angle_deg)))
    out = np.zeros(len(points))
    for x, y in LEDS:
        for k, p in enumerate(points):
            v = np.array([x, y, 3.0]) - p  # receiver -> LED
            d = np.linalg.norm(v)
            cos_phi = v[2] / d  # at the LED, its normal is (0, 0, -1)
            cos_psi = float(np.dot(v, normal)) / d
            if cos_psi >= math.cos(math.radians(fov_deg)) and cos_phi > 0:
                out[k] += (m + 1) / (2 * math.pi) * cos_phi**m * area * cos_psi / d**2
    return out


def test_los_map_equals_the_closed_form_at_every_point():
    doc = komine_doc(spacing=0.35, max_reflections=0)
    res = simulate(spec(doc))
    assert res["run"]["stop_reason"] == "exact" and res["run"]["paths_total"] == 0  # nothing was sampled
    grid = res["maps"][0]
    nu, nv = grid["shape"]
    pts = np.array(grid["origin"]) + grid["spacing"] * (
        np.arange(nu)[:, None, None] * np.array(grid["u"]) + np.arange(nv)[None, :, None] * np.array(grid["v"])
    )
    g = doc["receiver_grids"][0]
    ref = _closed_form_los(pts.reshape(-1, 3), np.array(g["normal"], float), g["area"], g["fov_deg"], 70.0)
    # The group's channel is per watt of the group: the mean of its 4 equal-power members.
    got = np.array(grid["values"]["dc_gain"], float).ravel()
    np.testing.assert_allclose(got, ref / 4, rtol=1e-12)
    e = np.array(grid["values"]["illuminance_lx"], float).ravel()
    m = -math.log(2) / math.log(math.cos(math.radians(70)))
    # Illuminance: no FOV limit, I0 = 2628 cd per lamp; E = I0 cos^m cos psi / d^2 summed over the lamps.
    e_ref = np.zeros(len(e))
    for x, y in LEDS:
        v = np.array([x, y, 3.0]) - pts.reshape(-1, 3)
        d = np.linalg.norm(v, axis=1)
        cos = v[:, 2] / d  # the same angle at the lamp (facing down) and at the receiver (facing up)
        e_ref += 2628.0 * cos**m * cos / d**2
    np.testing.assert_allclose(e, e_ref, rtol=1e-12)


def test_group_channel_equals_the_sum_of_its_members_run_separately():
    """Group of two LEDs at 2 W and 1 W: h_g = (2 h_1 + h_2) / 3, against two separate one-LED runs."""
    base = room_doc(max_reflections=2, paths=20_000, seed=11)
    base["receivers"].append({"id": "rx2", "position": [3.5, 2.0, 0.8], "normal": [0, 0, 1], "area": 1e-4})
    base["transmitters"] = [
        {"id": "a", "position": [1.5, 1.5, 3.0], "normal": [0, 0, -1], "lambertian_order": 1, "power": 2.0},
        {"id": "b", "position": [3.5, 3.0, 3.0], "normal": [0, 0, -1], "lambertian_order": 2, "power": 1.0},
    ]
    doc = copy.deepcopy(base)
    doc["transmitter_groups"] = [{"name": "ab", "transmitters": ["a", "b"]}]
    for direction in ("forward", "backward"):
        doc["simulation"]["direction"] = direction
        res = simulate(spec(doc))
        for j, rx in enumerate(("rx", "rx2")):
            ch = next(c for c in res["channels"] if c["receiver"] == rx)
            parts = []
            for t, seed in (("a", 101), ("b", 202)):  # each member alone, independent paths
                one = copy.deepcopy(base)
                one["transmitters"] = [x for x in one["transmitters"] if x["id"] == t]
                one["simulation"].update(seed=seed, direction=direction)
                parts.append(simulate(spec(one))["links"][j])
            ref = (2 * parts[0]["dc_gain"] + parts[1]["dc_gain"]) / 3
            ref_se = math.hypot(2 * parts[0]["dc_gain_stderr"], parts[1]["dc_gain_stderr"]) / 3
            se = math.hypot(ch["dc_gain_stderr"], ref_se)
            assert within(ch["dc_gain"], ref, se), (direction, rx, ch["dc_gain"], ref, se)
            assert se < 0.02 * ref  # power: a 5 % error (e.g. a member left out at 1/3 weight) would show
            assert ch["received_power_w"] == pytest.approx(3.0 * ch["dc_gain"], rel=1e-12)
            # The channel's CIR is the weighted sum of its members' CIRs (same run: exact).
            members = [lk for lk in res["links"] if lk["receiver"] == rx]
            cir = (2 * np.array(members[0]["cir"]["total"]) + np.array(members[1]["cir"]["total"])) / 3
            np.testing.assert_allclose(ch["cir"]["total"], cir, rtol=1e-12, atol=1e-300)


def test_running_moments_equal_the_moments_of_a_fine_cir():
    doc = room_doc(max_reflections=3, paths=4000, time_bin_s=2e-12, t_max_s=1.2e-7, seed=5)
    res = simulate(spec(doc))
    lk = res["links"][0]
    p = np.array(lk["cir"]["total"])
    t = res["time_bins"]["t_min_s"] + (np.arange(len(p)) + 0.5) * res["time_bins"]["time_bin_s"]
    assert lk["late_gain"] < 1e-3 * lk["dc_gain"]
    h0 = p.sum()
    tau0 = (p * t).sum() / h0
    rms = math.sqrt((p * (t - tau0) ** 2).sum() / h0)
    dt = res["time_bins"]["time_bin_s"]
    assert h0 == pytest.approx(lk["dc_gain"] - lk["late_gain"], rel=1e-9)
    assert abs(tau0 - lk["mean_delay_s"]) <= dt / 2 + 1e-3 * lk["mean_delay_s"] * lk["late_gain"] / lk["dc_gain"]
    assert abs(rms - lk["rms_delay_spread_s"]) <= dt


def test_grid_points_in_furniture_or_on_the_edge_are_masked_not_refused():
    doc = komine_doc(spacing=0.5, max_reflections=0)
    doc["furniture"] = [{"name": "shelf", "min": [0.0, 0.0, 0.0], "max": [0.6, 2.0, 2.0], "reflectance": 0.5}]
    doc["receiver_grids"][0].update(origin=[0.0, 0.0, 0.85], size=[5.0, 5.0])  # edge points lie on the walls
    res = simulate(spec(doc))
    masked = [r for r in res["receivers"] if r["masked"]]
    assert masked and all("shelf" in r["masked"] for r in masked)
    assert all(0 < r["position"][0] < 0.6 and r["position"][1] < 2.0 for r in masked)
    grid = res["maps"][0]
    for r in res["receivers"]:
        value = grid["values"]["dc_gain"][r["i"]][r["j"]]
        assert (value is None) == bool(r["masked"])
    assert any("not simulated" in w for w in res["warnings"])
    # A receiver on the boundary facing into its face is masked; facing along it is simulated.
    doc["receiver_grids"][0].update(origin=[0.0, 0.0, 0.0], normal=[0, 0, -1])
    res = simulate(spec(doc))
    assert all(r["masked"] for r in res["receivers"])


def test_outputs_default_by_receiver_kind_and_tally_budget_ignores_unasked_bins():
    doc = komine_doc(spacing=0.5, algorithm=1, max_reflections=1, paths=256, time_bin_s=1e-12, t_max_s=2e-7)
    doc["receivers"] = [{"id": "desk", "position": [2.5, 2.5, 0.85], "normal": [0, 0, 1], "area": 1e-4}]
    s = spec(doc)  # 4 x 100 grid links x 200 000 bins would be 8e7 cells: not asked, so not counted
    assert s.tally_cells(1, 0, s.simulation.n_bins) == 4 * 200_000 * (1 + 2 + 1) + 4 * 2
    res = simulate(s)
    by_rx = {lk["receiver"]: lk for lk in res["links"]}
    assert by_rx["desk"]["cir"] is not None and by_rx["desk"]["dc_gain_by_reflection_order"] is not None
    assert by_rx["plane[0,0]"]["cir"] is None and by_rx["plane[0,0]"]["dc_gain_by_reflection_order"] is None
    assert by_rx["plane[0,0]"]["rms_delay_spread_s"] is not None  # from running moments
    doc["outputs"] = {"cir": True}
    with pytest.raises(ValueError, match="tally cells"):
        spec(doc)


def test_batches_shrink_with_the_receiver_count():
    s = spec(
        komine_doc(spacing=0.05, algorithm=1, max_reflections=3, paths=10, t_max_s=1e-7)
    )  # 99 x 99 = 9801 receivers
    scene = build_scene(s)
    settings = kernel_settings(s, scene)
    n_rx = len(scene.receivers)
    bs = batch_size(s.simulation, settings, n_rx)
    assert bs * n_rx <= PATH_TARGET_BUDGET < (bs + 1) * n_rx
    assert batch_size(s.simulation, settings, 4) == s.simulation.batch_size  # few targets: the job's size
    # The dense per-path tally of such a batch holds targets x paths numbers, whatever the receiver count.
    builder = BatchBuilder(settings.tally, np.arange(n_rx), bs, several_per_cell=False)
    assert builder.abc.size == 3 * n_rx * bs <= 3 * PATH_TARGET_BUDGET


def test_forward_map_with_a_small_budget_agrees_with_the_default(monkeypatch):
    """The batch cap changes the batches, not the estimate: same map within errors under a tiny budget."""
    doc = komine_doc(spacing=1.2, max_reflections=2, paths=3000, t_max_s=1e-7, direction="forward")
    full = simulate(spec(doc))
    monkeypatch.setattr(simulate_module, "PATH_TARGET_BUDGET", 64)
    small = simulate(spec(doc))
    assert small["run"]["batches"] > full["run"]["batches"]
    for a, b in zip(full["channels"], small["channels"]):
        se = math.hypot(a["dc_gain_stderr"], b["dc_gain_stderr"])
        assert within(a["dc_gain"], b["dc_gain"], se)


def test_komine_example_script_and_python_api(tmp_path, capsys):
    """The example runs through `owcsim.simulate` and writes Komine's four maps (line of sight, coarse grid)."""
    import importlib.util

    path = EXAMPLES / "komine_maps.py"
    mod = importlib.util.spec_from_file_location("komine_maps", path)
    module = importlib.util.module_from_spec(mod)
    mod.loader.exec_module(module)
    files = module.main(["--out", str(tmp_path), "--los", "--spacing", "0.7"])
    assert [f.name for f in files] == [f"komine_{q}.png" for q in module.FIGURES]
    assert all(f.read_bytes()[:4] == b"\x89PNG" for f in files)
    out = capsys.readouterr().out
    assert "illuminance_lx" in out and "snr_db" in out


def test_command_line_prints_a_map_summary_and_writes_map_files(tmp_path, capsys):
    from owcsim.cli import main

    scene = tmp_path / "scene.json"
    doc = komine_doc(spacing=0.7, max_reflections=0)
    scene.write_text(json.dumps(doc))
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "plane/ceiling" in out and "illuminance_lx" in out and "links" in out
    assert out.count("\n") < 30  # a summary, not one line per link
    names = {p.name for p in (tmp_path / "out").iterdir()}
    assert {"result.json", "links.csv", "map_plane.nc", "maps.mat", "map_plane_ceiling_illuminance_lx.svg"} <= names
    assert "cir.csv" not in names  # no link asked for a CIR


def test_memory_estimate_follows_the_batch_cap_and_stays_bounded_for_large_maps():
    """engine/run/budget.py copies the batch caps (it must not import the engine's heavy modules): they agree, and
    a map's estimate grows with receivers only through per-link numbers, not links x bins."""
    from owcsim.engine.run import budget

    assert (budget.PATH_TARGET_BUDGET, budget.ESTIMATE_BUDGET) == (
        simulate_module.PATH_TARGET_BUDGET,
        simulate_module.ESTIMATE_BUDGET,
    )
    small = budget.memory_estimate(spec(komine_doc(spacing=0.5, algorithm=1, max_reflections=20, t_max_s=4e-7)))
    large = budget.memory_estimate(spec(komine_doc(spacing=0.0156, algorithm=1, max_reflections=20, t_max_s=4e-7)))
    assert large.batch <= 2 * small.batch + 2**20  # the batch is capped whatever the receiver count
    assert large.total < 2 * 2**30  # a 99 856-point map in under 2 GB


def test_los_to_a_work_plane_on_a_desk_top_is_not_hidden_by_the_desk():
    """Grazing links (incidence past 60 deg) to points lying on a desk top: the desk must not shadow them.

    (A shadow ray ended along the ray short of the receiver dipped under the desk top past 60 deg.)"""
    doc = komine_doc(spacing=0.2, max_reflections=0)
    doc["furniture"] = [{"name": "desk", "min": [0.8, 0.8, 0.0], "max": [1.2, 1.2, 0.75], "reflectance": 0.5}]
    doc["receiver_grids"][0].update(origin=[0.8, 0.8, 0.75], size=[0.4, 0.4])
    res = simulate(spec(doc))
    grid = res["maps"][0]
    pts = np.array([r["position"] for r in res["receivers"]])
    g = doc["receiver_grids"][0]
    ref = _closed_form_los(pts, np.array(g["normal"], float), g["area"], g["fov_deg"], 70.0)
    got = np.array(grid["values"]["dc_gain"], float).ravel()
    np.testing.assert_allclose(got, ref / 4, rtol=1e-12)
    v = np.array([3.75, 3.75, 3.0]) - pts[0]
    assert math.degrees(math.acos(v[2] / np.linalg.norm(v))) > 60  # the case that failed is in the grid


def test_command_line_summarises_any_map_and_prints_group_channels(tmp_path, capsys):
    from owcsim.cli import main

    doc = komine_doc(spacing=0.7, max_reflections=0)
    doc["receiver_grids"][0]["size"] = [0.0, 0.0]  # a one-point grid is still a map
    scene = tmp_path / "one.json"
    scene.write_text(json.dumps(doc))
    assert main(["run", str(scene), "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "plane/ceiling" in out and "led1 ->" not in out
    doc["receivers"], doc["receiver_grids"] = (
        [{"id": "desk", "position": [2.5, 2.5, 0.85], "normal": [0, 0, 1], "area": 1e-4}],
        [],
    )
    scene.write_text(json.dumps(doc))
    assert main(["run", str(scene), "--out", str(tmp_path / "b")]) == 0
    assert "group ceiling -> desk: H0 =" in capsys.readouterr().out
