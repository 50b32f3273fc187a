"""Multi-cell LiFi (engine/results/cells.py): serving cell, SINR, rates and handover boundaries against closed
forms in line of sight (max_reflections 0: exact gains), and the delta method against finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from owcsim.engine.results import cells as cells_module
from owcsim.engine.results import link_budget as lb
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec

Q, KB = 1.602176634e-19, 1.380649e-23  # C, J/K
AREA = 1e-4
TX = [  # id, position, lambertian order m, power [W]
    ("a1", (1.0, 1.5, 3.0), 1.0, 2.0),
    ("a2", (1.0, 3.5, 3.0), 1.0, 2.0),
    ("b1", (4.0, 2.5, 3.0), 2.0, 3.0),
    ("c", (2.5, 4.5, 3.0), 1.5, 1.0),
]
BUDGET = {"bandwidth": 5e8, "ber_target": 1e-6, "dco_ofdm_subcarriers": 128, "dco_ofdm_bias": 2.5}


def cells_doc(budget=True, groups=True, **grid) -> dict:
    doc = room_doc(max_reflections=0)
    doc["transmitters"] = [
        {"id": i, "position": list(p), "normal": [0, 0, -1], "lambertian_order": m, "power": w} for i, p, m, w in TX
    ]
    doc["receivers"] = [
        {"id": "r1", "position": [1.2, 2.4, 0.8], "normal": [0, 0, 1], "area": AREA},
        {"id": "r2", "position": [3.7, 2.0, 0.8], "normal": [0, 0, 1], "area": AREA},
        {"id": "r3", "position": [2.5, 4.2, 0.8], "normal": [0, 0, 1], "area": AREA},
    ]
    g = {"id_prefix": "g", "origin": [0.3, 0.3, 0.8], "size": [4.4, 4.4], "spacing": 0.4, "area": AREA}
    g.update(grid)
    doc["receiver_grids"] = [g]
    if groups:
        doc["transmitter_groups"] = [{"name": "A", "transmitters": ["a1", "a2"]}, {"name": "B", "transmitters": ["b1"]}]
    if budget:
        doc["link_budget"] = dict(BUDGET)
    return doc


def lambertian_gain(tx_pos, m, rx_pos, area=AREA):
    """H = (m+1)/(2 pi) cos^m(phi) A cos(psi) / d^2, both devices on the axis z (tx down, rx up)."""
    v = np.asarray(tx_pos, float) - np.asarray(rx_pos, float)
    d = np.linalg.norm(v, axis=-1)
    cos = v[..., 2] / d
    return (m + 1) / (2 * math.pi) * cos**m * area * cos / d**2


def reference(points, names_members):
    """Per cell (C, R) received power [W] from the Lambertian formula."""
    by_id = {i: (p, m, w) for i, p, m, w in TX}
    out = []
    for members in names_members:
        out.append(sum(by_id[i][2] * lambertian_gain(by_id[i][0], by_id[i][1], points) for i in members))
    return np.array(out)


def komine_noise(p_total, b, area=AREA, gamma=0.53):
    """sigma_shot^2 + sigma_thermal^2 [A^2] of Komine & Nakagawa 2004, default receiver."""
    shot = 2 * Q * gamma * p_total * b + 2 * Q * 5.1e-3 * 0.562 * b
    kt, cap = KB * 295.0, 1.12e-6 * area
    thermal = 8 * math.pi * kt / 10.0 * cap * 0.562 * b**2 + 16 * math.pi**2 * kt * 1.5 / 0.03 * cap**2 * 0.0868 * b**3
    return shot + thermal


def expected(powers, b=5e8, gamma=0.53, n=128, k=2.5, ber=1e-6):
    """Serving cell, SINR, Shannon, DCO-OFDM and OOK rates computed point by point (plain loops)."""
    from scipy.optimize import brentq
    from scipy.stats import norm

    required = norm.isf(ber) ** 2
    rows = []
    for p in powers.T:
        s = int(np.argmax(p))
        interference = sum((gamma * p[c]) ** 2 for c in range(len(p)) if c != s)
        sinr = (gamma * p[s]) ** 2 / (interference + komine_noise(p.sum(), b))
        sinr_ac = (gamma * p[s]) ** 2 / (interference + k * k * komine_noise(p.sum(), b))
        allowance = (gamma * p[s]) ** 2 / required - interference
        ook = 0.0
        if allowance > 0:
            total = float(p.sum())
            # noise at the bandwidth B = R_b (Komine) equals the allowance: one root, found by Brent's method
            ook = brentq(lambda r, t=total, y=allowance: komine_noise(t, r) - y, 1.0, 1e13, xtol=1e-6, rtol=1e-14)
        rows.append(
            (
                s,
                10 * math.log10(sinr),
                b * math.log2(1 + sinr),
                b * (n - 2) / (2 * n) * math.log2(1 + sinr_ac),
                min(ook, b),  # NRZ at most at the receiver's bandwidth
            )
        )
    return rows


def test_serving_cell_sinr_and_rates_equal_the_closed_form_in_line_of_sight():
    res = simulate(spec(cells_doc()))
    assert res["run"]["stop_reason"] == "exact"
    cells = res["cells"]
    assert cells["cells"] == ["A", "B", "c"] and cells["members"] == [["a1", "a2"], ["b1"], ["c"]]
    points = np.array([r["position"] for r in res["receivers"]])
    powers = reference(points, cells["members"])
    ref = expected(powers)
    rows = cells["receivers"]
    assert len(rows) == len(points) > 100
    got_s = [r["serving_cell_index"] for r in rows]
    assert got_s == [s for s, *_ in ref]
    assert len(set(got_s)) == 3  # every cell serves somewhere
    for key, col in (("sinr_db", 1), ("rate_shannon_bps", 2), ("rate_dco_ofdm_bps", 3), ("rate_ook_bps", 4)):
        np.testing.assert_allclose([r[key] for r in rows], [x[col] for x in ref], rtol=1e-9, err_msg=key)
    np.testing.assert_allclose([r["serving_power_w"] for r in rows], powers.max(axis=0), rtol=1e-12)
    np.testing.assert_allclose(
        [r["interference_power_w"] for r in rows], powers.sum(axis=0) - powers.max(axis=0), rtol=1e-12
    )
    assert all(r["sinr_db_stderr"] == 0.0 for r in rows)  # exact gains: no error
    ook = np.array([x[4] for x in ref])
    assert (ook == 0).any() and ((ook > 0) & (ook < 5e8)).any() and (ook == 5e8).any()  # the OOK rate's 3 branches


def test_the_closed_form_check_has_power():
    """The reference of the test above, 10 % off in one cell's power, moves every compared figure."""
    points = np.array([[1.2, 2.4, 0.8], [3.7, 2.0, 0.8]])
    powers = reference(points, [["a1", "a2"], ["b1"], ["c"]])
    off = powers.copy()
    off[0] *= 1.1
    for a, b in zip(expected(powers), expected(off)):
        assert all(abs(x - y) > 1e-6 * abs(x) for x, y in zip(a[1:4], b[1:4]))


def test_without_groups_each_transmitter_is_a_cell_and_without_budget_sinr_is_null():
    res = simulate(spec(cells_doc(budget=False, groups=False)))
    cells = res["cells"]
    assert cells["cells"] == ["a1", "a2", "b1", "c"]
    assert "link_budget" in cells["note"]
    assert all(r["sinr_db"] is None and r["serving_cell"] is not None for r in cells["receivers"])
    assert cells["maps"][0]["values"] == {}


def test_groups_sharing_a_transmitter_give_no_sinr_and_say_why():
    """An `all` group beside A and B would serve everywhere and count A's own light as interference."""
    doc = cells_doc()
    doc["transmitter_groups"].append({"name": "all", "transmitters": [t[0] for t in TX]})
    cells = simulate(spec(doc))["cells"]
    assert cells["cells"] == ["A", "B", "all"]
    assert "a1, a2, b1 belong to several transmitter groups" in cells["note"]
    assert all(r["sinr_db"] is None and r["rate_shannon_bps"] is None for r in cells["receivers"])
    assert cells["maps"][0]["values"] == {}


def test_one_cell_without_budget_has_no_cells_section():
    doc = cells_doc(budget=False)
    doc["transmitter_groups"] = [{"name": "all", "transmitters": [t[0] for t in TX]}]
    assert simulate(spec(doc))["cells"] is None


def test_boundary_of_two_symmetric_cells_lies_on_the_bisector():
    """Two equal cells at x = 1 and x = 3: the boundary is the plane x = 2; grid points never on it."""
    doc = cells_doc(groups=False)
    doc["transmitters"] = [
        {"id": "L", "position": [1.0, 2.5, 3.0], "normal": [0, 0, -1], "lambertian_order": 1, "power": 1.0},
        {"id": "R", "position": [3.0, 2.5, 3.0], "normal": [0, 0, -1], "lambertian_order": 1, "power": 1.0},
    ]
    doc["receivers"] = []
    doc["receiver_grids"][0].update(origin=[0.1, 0.5, 0.8], size=[3.8, 4.0], spacing=0.2)
    res = simulate(spec(doc))
    m = res["cells"]["maps"][0]
    serving = np.array(m["serving_cell"])
    x = 0.1 + 0.2 * np.arange(serving.shape[0])
    np.testing.assert_array_equal(serving, np.where(x < 2.0, 0, 1)[:, None] * np.ones(serving.shape[1], int))
    segs = m["boundaries"]
    assert len(segs) == serving.shape[1]  # one per row of points along y
    for s in segs:
        assert s["cells"] == ["L", "R"]
        assert abs(s["start"][0] - 2.0) < 1e-12 and abs(s["end"][0] - 2.0) < 1e-12
    ys = sorted(y for s in segs for y in (s["start"][1], s["end"][1]))
    assert ys[0] == pytest.approx(0.5) and ys[-1] == pytest.approx(4.5)  # they cover the grid's extent
    # power: a 10 % stronger left cell moves the boundary right, off the bisector
    doc["transmitters"][0]["power"] = 1.1
    shifted = simulate(spec(doc))["cells"]["maps"][0]["boundaries"]
    xs = [s["start"][0] for s in shifted]
    assert min(xs) > 2.0 - 1e-12 and max(xs) > 2.15


def test_delta_method_gradients_equal_finite_differences():
    rng = np.random.default_rng(4)
    budget = lb.LinkBudget(noise_bandwidth=5e7)
    power = rng.uniform(1e-5, 1e-3, size=(3, 20))
    s = np.argmax(power, axis=0)
    area = np.full(20, AREA)
    for factor in (1.0, 6.25):
        x, grad = cells_module._sinr(budget, area, power, s, factor)
        for c in range(3):
            h = 1e-6 * power[c]
            up, down = power.copy(), power.copy()
            up[c] += h
            down[c] -= h
            fd = (
                cells_module._sinr(budget, area, up, s, factor)[0]
                - cells_module._sinr(budget, area, down, s, factor)[0]
            ) / (2 * h)
            np.testing.assert_allclose(grad[c], fd, rtol=1e-6)


def test_delta_method_errors_match_the_spread_of_independent_runs():
    """40 seeds, reflections (Monte Carlo gains): each figure's reported error against its spread over the runs,
    pooled over the receivers (the spread of z is known to ~7-10 %, so [0.7, 1.35] is ~4 sigma, and an error bar
    off by 1.5x fails). BER target 1e-3: the OOK rate of r1 is then away from its cliff and below B."""
    keys = ("sinr_db", "rate_shannon_bps", "rate_dco_ofdm_bps", "rate_ook_bps")
    runs = []
    for seed in range(40):
        doc = cells_doc()
        doc["receiver_grids"] = []
        doc["link_budget"].update(ber_target=1e-3, bandwidth=5e9)  # r1's OOK rate below B: not capped
        doc["simulation"].update(max_reflections=2, paths=3000, seed=seed, direction="forward")
        doc["outputs"] = {"cir": False, "orders": False}
        rows = simulate(spec(doc))["cells"]["receivers"]
        runs.append([[(r[k], r[k + "_stderr"]) for k in keys] for r in rows])
    a = np.array(runs, float)  # (seed, receiver, key, value / stderr); None -> NaN
    with np.errstate(invalid="ignore"):  # NaN where a figure has no error bar (left out below)
        z = (a[..., 0] - a[..., 0].mean(axis=0)) / a[..., 1].mean(axis=0)
    for k, key in enumerate(keys):
        ok = (a[:, :, k, 1] > 0).all(axis=0)  # receivers where every run gives this figure an error bar
        assert ok.sum() >= (1 if key == "rate_ook_bps" else 3), key
        zz = z[:, ok, k]
        ratio = math.sqrt((zz**2).sum() / (zz.size - ok.sum()))  # one mean taken out per receiver
        assert 0.7 < ratio < 1.35, (key, ratio)


def test_masked_points_have_no_serving_cell_and_no_boundary():
    doc = cells_doc()
    doc["furniture"] = [{"name": "desk", "min": [2.0, 2.0, 0.0], "max": [3.0, 3.0, 1.0], "reflectance": 0.5}]
    res = simulate(spec(doc))
    masked = {r["id"] for r in res["receivers"] if r["masked"]}
    assert masked
    rows = {r["receiver"]: r for r in res["cells"]["receivers"]}
    assert all(rows[i]["serving_cell"] is None and rows[i]["sinr_db"] is None for i in masked)
    for b in res["cells"]["maps"][0]["boundaries"]:  # no segment inside the desk's footprint
        for p in (b["start"], b["end"]):
            assert not (2.0 + 0.2 < p[0] < 3.0 - 0.2 and 2.0 + 0.2 < p[1] < 3.0 - 0.2)


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("dco_ofdm_subcarriers", 63, "must be even"),
        ("dco_ofdm_subcarriers", 2, "greater than or equal to 4"),
        ("ber_target", 0.5, "less than 0.5"),
        ("dco_ofdm_bias", 0, "greater than 0"),
    ],
)
def test_bad_multi_cell_parameters_are_refused_with_a_located_message(field, value, message):
    from pydantic import ValidationError

    doc = cells_doc()
    doc["link_budget"][field] = value
    with pytest.raises(ValidationError, match=message) as err:
        spec(doc)
    assert "link_budget" in str(err.value)


def test_backward_paths_shared_by_cells_give_the_bound_and_say_so():
    doc = cells_doc()
    doc["receiver_grids"] = []
    doc["simulation"].update(max_reflections=1, paths=2000, seed=3, direction="backward")
    cells = simulate(spec(doc))["cells"]
    assert "bound" in cells["note"] and "3 receiver(s)" in cells["note"]
    assert all(r["sinr_db_stderr"] > 0 for r in cells["receivers"])
    grad = np.array([[1.0, -2.0], [3.0, 0.5]])
    sigma = np.array([[0.1, 0.2], [0.3, 0.4]])
    both = cells_module._propagate(grad, sigma, np.array([True, False]))
    assert both[0] == pytest.approx(math.hypot(0.1, 0.9)) and both[1] == pytest.approx(0.4 + 0.2)


def test_one_cell_sinr_is_the_channel_snr():
    doc = cells_doc()
    doc["transmitter_groups"] = [{"name": "all", "transmitters": [t[0] for t in TX]}]
    res = simulate(spec(doc))
    sinr = [r["sinr_db"] for r in res["cells"]["receivers"]]
    snr = [c["snr_db"] for c in res["channels"]]
    np.testing.assert_allclose(sinr, snr, rtol=1e-12)
    assert res["cells"]["maps"][0]["boundaries"] == []
