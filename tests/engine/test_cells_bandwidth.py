"""3 dB bandwidth of group channels (engine/results/channel_spectrum.py): the two-arrival closed form in line of
sight, and a plain-loop reference of H(f) (exact LOS deltas + binned reflections) with reflections."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from owcsim.engine.results.channel_spectrum import bandwidth_3db
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec

C = 299_792_458.0
AREA = 1e-4


def two_lamp_doc(max_reflections=0, **sim) -> dict:
    doc = room_doc(max_reflections=max_reflections, time_bin_s=2e-11, t_max_s=6e-8, **sim)
    doc["transmitters"] = [
        {"id": "near", "position": [1.0, 1.0, 3.0], "normal": [0, 0, -1], "lambertian_order": 1, "power": 2.0},
        {"id": "far", "position": [3.5, 3.0, 3.0], "normal": [0, 0, -1], "lambertian_order": 1, "power": 1.0},
    ]
    doc["transmitter_groups"] = [{"name": "g", "transmitters": ["near", "far"]}]
    doc["receivers"] = [{"id": "rx", "position": [2.0, 1.5, 0.8], "normal": [0, 0, 1], "area": AREA}]
    doc["receiver_grids"] = [
        {"id_prefix": "m", "origin": [1.0, 1.0, 0.8], "size": [2.0, 2.0], "spacing": 0.5, "area": AREA}
    ]
    doc["outputs"] = {"cir": True}  # the bandwidth needs each point's CIR
    return doc


def closed_form(points, doc):
    """f_3dB of two deltas a_1, a_2 at tau_1, tau_2: |H|^2 = a1^2 + a2^2 + 2 a1 a2 cos(2 pi f dtau) = (a1 + a2)^2 / 2
    at cos = -(a1 - a2)^2 / (4 a1 a2); no crossing when the right side is below -1."""
    txs = doc["transmitters"]
    total = sum(t["power"] for t in txs)
    a, tau = [], []
    for t in txs:
        v = np.asarray(t["position"], float) - points
        d = np.linalg.norm(v, axis=1)
        cos = v[:, 2] / d
        m = t["lambertian_order"]
        a.append(t["power"] / total * (m + 1) / (2 * math.pi) * cos**m * AREA * cos / d**2)
        tau.append(d / C)
    (a1, a2), (t1, t2) = a, tau
    c = -((a1 - a2) ** 2) / (4 * a1 * a2)
    return np.where(c >= -1, np.arccos(np.clip(c, -1, 1)) / (2 * math.pi * np.abs(t2 - t1)), np.nan)


def test_group_bandwidth_equals_the_two_arrival_closed_form_in_line_of_sight():
    doc = two_lamp_doc()
    res = simulate(spec(doc))
    assert res["run"]["stop_reason"] == "exact"
    points = np.array([r["position"] for r in res["receivers"]])
    ref = closed_form(points, doc)
    got = np.array([np.nan if c["bandwidth_3db_hz"] is None else c["bandwidth_3db_hz"] for c in res["channels"]])
    assert np.isfinite(ref).sum() >= 10 and (ref[np.isfinite(ref)] < 1 / (2 * 2e-11)).all()
    np.testing.assert_allclose(got, ref, rtol=1e-9)
    grid = res["maps"][0]
    assert grid["units"]["bandwidth_3db_hz"] == "Hz"
    np.testing.assert_allclose(np.array(grid["values"]["bandwidth_3db_hz"], float).ravel(), ref[1:], rtol=1e-9)
    assert not np.allclose(got, 1.1 * ref, rtol=1e-3)  # power: a reference 10 % off fails


def test_grid_points_without_a_cir_have_no_bandwidth():
    doc = two_lamp_doc()
    del doc["outputs"]
    res = simulate(spec(doc))
    assert res["channels"][0]["bandwidth_3db_hz"] is not None  # the explicit receiver keeps its CIR by default
    assert all(c["bandwidth_3db_hz"] is None for c in res["channels"][1:])
    assert "bandwidth_3db_hz" not in res["maps"][0]["values"]


def test_bandwidth_of_deltas_has_no_crossing_for_one_arrival_or_unequal_pairs():
    gain = np.array([[1.0, 0.0], [1.0, 0.1]])  # one arrival; two with a ratio 10 (outside 0.17..5.83)
    delay = np.array([[1e-8, 2e-8], [1e-8, 2e-8]])
    out = bandwidth_3db(gain, delay, np.zeros((2, 0)), 0.0, 1e-11)
    assert np.isnan(out).all()


def reference_bandwidth(link_rows, weights, t_min, dt):
    """First crossing of |H(f)|^2 = H(0)^2 / 2 below 1/(2 dt): H = sum_i w_i (a_i e^{-2 pi i f tau_i} + sum_k r_ik
    e^{-2 pi i f t_k}), r = the link's CIR with its LOS gain taken out of its bin; a dense scan, then Brent."""
    terms = []
    for row, w in zip(link_rows, weights):
        r = np.array(row["cir"]["total"], float)
        k = int(math.floor((row["los_delay_s"] - t_min) / dt))
        if 0 <= k < len(r):
            r[k] -= row["los_gain"]
        terms.append((w * row["los_gain"], row["los_delay_s"], w * r))
    centres = t_min + dt * (np.arange(len(terms[0][2])) + 0.5)

    def power(f):
        h = sum(
            a * np.exp(-2j * math.pi * f * tau) + (r * np.exp(-2j * math.pi * f * centres)).sum() for a, tau, r in terms
        )
        return abs(h) ** 2

    h0 = sum(a + r.sum() for a, _, r in terms)
    f = np.linspace(0, 1 / (2 * dt), 40_001)
    below = [power(x) - h0**2 / 2 for x in f]
    k = next(i for i, v in enumerate(below) if i > 0 and v <= 0)
    return brentq(lambda x: power(x) - h0**2 / 2, f[k - 1], f[k], xtol=1e-3, rtol=1e-13)


def test_group_bandwidth_with_reflections_equals_a_plain_reference_from_the_links_cirs():
    doc = two_lamp_doc(max_reflections=2, paths=4000, seed=5)
    doc["receiver_grids"] = []
    doc["simulation"]["time_bin_s"] = 2e-10
    res = simulate(spec(doc))
    links = {lk["transmitter"]: lk for lk in res["links"]}
    rows = [links["near"], links["far"]]
    ref = reference_bandwidth(rows, [2 / 3, 1 / 3], res["time_bins"]["t_min_s"], res["time_bins"]["time_bin_s"])
    got = res["channels"][0]["bandwidth_3db_hz"]
    assert got is not None
    assert abs(got - ref) <= 1e-9 * ref


def test_bandwidth_gradient_equals_finite_differences():
    from owcsim.engine.results.channel_spectrum import bin_gradient

    rng = np.random.default_rng(2)
    gain = np.array([[2e-6, 1.5e-6], [1e-6, 1.2e-6]])
    delay = np.array([[10e-9, 11.2e-9], [9e-9, 9.7e-9]])
    binned = rng.uniform(0, 2e-8, size=(2, 60))
    f3 = bandwidth_3db(gain, delay, binned, 5e-9, 2e-10)
    assert np.isfinite(f3).all()
    grad = bin_gradient(f3, gain, delay, binned, 5e-9, 2e-10)
    for k in (0, 17, 45):
        h = np.zeros_like(binned)
        h[:, k] = 1e-10
        fd = (
            bandwidth_3db(gain, delay, binned + h, 5e-9, 2e-10) - bandwidth_3db(gain, delay, binned - h, 5e-9, 2e-10)
        ) / 2e-10
        np.testing.assert_allclose(grad[:, k], fd, rtol=1e-4)


def test_bandwidth_error_matches_the_spread_of_independent_runs():
    """30 seeds with reflections: the reported error of the group's bandwidth against its spread (the spread of
    30 values is known to ~13 %: [0.6, 1.6] is ~4 sigma; an error bar 2x off fails)."""
    values, errors = [], []
    for seed in range(30):
        doc = two_lamp_doc(max_reflections=2, paths=2000, seed=seed, direction="forward")
        doc["receiver_grids"] = []
        doc["simulation"]["time_bin_s"] = 2e-10
        ch = simulate(spec(doc))["channels"][0]
        values.append(ch["bandwidth_3db_hz"])
        errors.append(ch["bandwidth_3db_hz_stderr"])
    ratio = np.std(values, ddof=1) / np.mean(errors)
    assert 0.6 < ratio < 1.6, ratio


def test_a_masked_grid_point_leaves_the_other_points_bandwidth_errors():
    """A masked point's links have no path groups: the others' errors are as without the mask (not all null)."""
    doc = two_lamp_doc(max_reflections=2, paths=2000, seed=3)
    doc["simulation"]["time_bin_s"] = 2e-10
    plain = simulate(spec(doc))["channels"]
    doc["receiver_grids"][0]["exclude"] = [{"min": [0.4, 0.4], "max": [0.6, 0.6]}]  # m[1,1]
    masked = {c["receiver"]: c for c in simulate(spec(doc))["channels"]}
    assert masked["m[1,1]"]["bandwidth_3db_hz_stderr"] is None
    for c in plain:
        if c["receiver"] != "m[1,1]" and c["bandwidth_3db_hz_stderr"] is not None:
            assert masked[c["receiver"]]["bandwidth_3db_hz_stderr"] == c["bandwidth_3db_hz_stderr"]
    assert sum(c["bandwidth_3db_hz_stderr"] is not None for c in masked.values()) >= 10
