"""Angle-diversity receivers (docs/orientation.md): each photodiode's line of sight and the SC / EGC / MRC combined
SNRs against closed forms written here (Carruthers & Kahn 2000; Chen et al. 2018), exact in line of sight."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.engine.test_orientation import GAMMA, LAMP, B, M, noise_ab
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec

POINT = np.array([2.9, 2.5, 0.8])
TILT, FOV, AREA = 40.0, 50.0, 1e-4
#: a second receiver given photodiode by photodiode, with unequal areas and FOVs (so unequal noise)
CUSTOM = [
    {"normal": [0, 0, 1], "area": 1e-4, "fov_deg": 60},
    {"normal": [-1, -0.5, 1], "area": 4e-5, "fov_deg": 30},
    {"normal": [1, 0, 0.2], "area": 2e-4, "fov_deg": 80},
]


def adr_doc(link_budget: bool = True, **simulation) -> dict:
    doc = room_doc(tx=tuple(LAMP), rx=(1.0, 1.0, 0.8), m=M, **{"max_reflections": 0, **simulation})
    doc["angle_diversity_receivers"] = [
        {"id": "pyr", "position": POINT.tolist(), "pyramid": {"tilt_deg": TILT, "area": AREA, "fov_deg": FOV}},
        {"id": "cus", "position": POINT.tolist(), "photodiodes": CUSTOM},
    ]
    if link_budget:
        doc["link_budget"] = {"bit_rate": B}
    return doc


def los_power(normal, area: float, fov_deg: float) -> float:
    """P = P_t (m+1)/(2 pi) cos^m(phi) A cos(psi) / d^2 for psi <= FOV, lamp facing down, P_t = 1 W."""
    v = LAMP - POINT
    d = float(np.linalg.norm(v))
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    cos_psi = float(n @ v) / d
    if cos_psi < math.cos(math.radians(fov_deg)):
        return 0.0
    return (M + 1) / (2 * math.pi) * (v[2] / d) ** M * area * cos_psi / d**2


def reference(pds: list[dict]) -> dict:
    p = np.array([los_power(pd["normal"], pd["area"], pd["fov_deg"]) for pd in pds])
    a = np.array([noise_ab(pd["area"])[0] for pd in pds])
    b = noise_ab(1.0)[1]
    current, noise = GAMMA * p, a + b * p
    snr = current**2 / noise
    return {
        "power": p,
        "snr": snr,
        "sc": snr.max(),
        "selected": int(np.argmax(snr)),
        "egc": current.sum() ** 2 / noise.sum(),
        "mrc": snr.sum(),
    }


def pyramid_photodiodes() -> list[dict]:
    """4 sides at azimuths 0, 90, 180, 270 deg from +x (the axis is +z), tilted by TILT, then the top one."""
    t = math.radians(TILT)
    sides = [
        {"normal": [math.sin(t) * math.cos(az), math.sin(t) * math.sin(az), math.cos(t)], "area": AREA, "fov_deg": FOV}
        for az in np.radians([0, 90, 180, 270])
    ]
    return sides + [{"normal": [0, 0, 1], "area": AREA, "fov_deg": FOV}]


def db(x: float) -> float:
    return 10 * math.log10(x)


@pytest.mark.parametrize("adr, pds", [("pyr", pyramid_photodiodes()), ("cus", CUSTOM)])
def test_combined_snrs_equal_the_closed_forms_in_line_of_sight(adr, pds):
    res = simulate(spec(adr_doc()))
    (row,) = [r for r in res["angle_diversity"] if r["receiver"] == adr]
    ref = reference(pds)
    assert row["photodiodes"] == [f"{adr}@pd{k}" for k in range(len(pds))]
    np.testing.assert_allclose(row["received_power_w"], ref["power"], rtol=1e-9, atol=1e-20)
    got_snr = [s if s is not None else -np.inf for s in row["snr_db"]]
    with np.errstate(divide="ignore"):
        np.testing.assert_allclose(got_snr, 10 * np.log10(ref["snr"]), rtol=1e-9)
    assert row["selected"] == ref["selected"]
    for key in ("sc", "egc", "mrc"):
        assert row[f"snr_{key}_db"] == pytest.approx(db(ref[key]), rel=1e-9, abs=1e-9)
        assert row[f"snr_{key}_db_stderr"] == 0.0  # line of sight: exact
        assert row[f"snr_{key}_db"] != pytest.approx(db(1.1 * ref[key]), rel=1e-9, abs=1e-9)  # power: 10 % off fails
    # MRC is the optimal linear combiner: SC and EGC never exceed it (EGC may fall below SC: weak branches add noise)
    assert max(ref["sc"], ref["egc"]) <= ref["mrc"]
    # photodiodes are ordinary receivers at the point: their links carry the same powers
    links = {link["receiver"]: link["received_power_w"] for link in res["links"]}
    np.testing.assert_allclose([links[i] for i in row["photodiodes"]], ref["power"], rtol=1e-12, atol=1e-20)


def test_equal_noise_egc_is_the_square_of_summed_root_snrs_over_n():
    """With the signal's shot noise off (b = 0 for equal areas: sigma_i^2 = sigma^2), EGC = (sum sqrt(S_i))^2 / (N
    sigma^2): the form the issue states, from the general (sum I_i)^2 / sum sigma_i^2."""
    from owcsim.engine.results import link_budget as lb
    from owcsim.engine.results.orientation import combined_snr

    budget = lb.LinkBudget(noise_bandwidth=B)
    p = np.array([[1e-6, 3e-6, 0.0, 2e-6]])
    area = np.full(4, 1e-4)
    out = combined_snr(budget, area, p, np.zeros_like(p))
    a, b = noise_ab(1e-4)
    sigma2 = a + b * p  # unequal through the shot noise: the general form
    np.testing.assert_allclose(out["egc"], (GAMMA * p).sum() ** 2 / sigma2.sum(), rtol=1e-12)
    s = (GAMMA * p) ** 2
    equal = (np.sqrt(s).sum()) ** 2 / (4 * sigma2.mean())  # (sum sqrt S_i)^2 / (N sigma^2), sigma^2 the mean noise
    np.testing.assert_allclose(out["egc"], equal, rtol=1e-12)


def test_without_a_link_budget_the_snrs_are_null_and_the_result_says_why():
    res = simulate(spec(adr_doc(link_budget=False)))
    row = res["angle_diversity"][0]
    assert row["snr_mrc_db"] is None and max(row["received_power_w"]) > 0
    assert any("need `link_budget`" in w for w in res["warnings"])


def test_all_orders_the_errors_propagate_from_each_photodiode():
    """With reflections (Monte Carlo), MRC's error bound is sum_i |dSNR_i/dP_i| sigma_i, in dB; a second seed
    agrees within the combined errors."""
    rows = []
    for seed in (1, 2):
        res = simulate(spec(adr_doc(max_reflections=2, paths=4000, seed=seed)))
        rows.append(next(r for r in res["angle_diversity"] if r["receiver"] == "pyr"))
    for key in ("sc", "egc", "mrc"):
        x, y = (r[f"snr_{key}_db"] for r in rows)
        sx, sy = (r[f"snr_{key}_db_stderr"] for r in rows)
        assert 0 < sx < 0.5 and 0 < sy < 0.5
        assert abs(x - y) <= 4 * math.hypot(sx, sy)
    los = reference(pyramid_photodiodes())
    assert rows[0]["snr_mrc_db"] > db(los["mrc"])  # the reflections add power


def test_a_receiver_needs_one_form():
    doc = adr_doc()
    doc["angle_diversity_receivers"][0]["photodiodes"] = CUSTOM
    with pytest.raises(ValueError, match="exactly one of `photodiodes` and `pyramid`"):
        spec(doc)


def test_a_scene_whose_only_receiver_is_an_angle_diversity_one_runs_with_the_automatic_window():
    """The line-of-sight window reaches the angle-diversity receivers (without other receivers it had none)."""
    doc = adr_doc()
    del doc["receivers"]
    for key in ("t_max_s", "time_bin_s"):
        doc["simulation"].pop(key)
    res = simulate(spec(doc))
    (row,) = [r for r in res["angle_diversity"] if r["receiver"] == "pyr"]
    ref = reference(pyramid_photodiodes())
    np.testing.assert_allclose(row["received_power_w"], ref["power"], rtol=1e-9, atol=1e-20)
