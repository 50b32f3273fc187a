"""Total illuminance (direct + every reflection order) and one luminous flux per transmitter (issue 24 item 1).

References built here: the direct illuminance in closed form (exact, 1e-9); the reflected illuminance
Phi_v (H0 - H_los) / A of an empty box of one reflectance from the radiosity solve of tests/reference_radiosity.py
(all orders, no engine code) with its first order replaced by the exact patch integral of tests/reference.py
(as tests/engine/test_bright_room.py; the coarse radiosity is within 0.3 % there: a budget of 1 % of the
reflected part on top of 4 standard errors), and a power check that the same comparison fails at 10 % off.
"""

from __future__ import annotations

import base64
import math
from pathlib import Path

import numpy as np
import pytest

from tests.reference import first_bounce_box_dc_gain
from tests.reference_radiosity import box_dc_gain
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec

SIZE, TX, RHO = (5.0, 5.0, 3.0), (2.5, 2.5, 3.0), 0.5
POINTS = ((1.0, 1.0, 0.85), (2.5, 2.5, 0.85))
FLUX = 1000.0  # [lm]
AREA = 1e-4
BUDGET = 0.01  # relative accuracy of the radiosity reference on the reflected part
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def direct_lx(flux, m, tx, tx_n, p, p_n=(0, 0, 1)) -> float:
    """E = Phi (m + 1) / (2 pi) cos^m(phi) cos(psi) / d^2 of one Lambertian source [lx] (Komine & Nakagawa 2004)."""
    d = np.subtract(p, tx)
    r = float(np.linalg.norm(d))
    cos_phi, cos_psi = float(d @ np.asarray(tx_n)) / r, -float(d @ np.asarray(p_n)) / r
    return flux * (m + 1) / (2 * math.pi) * max(cos_phi, 0.0) ** m * max(cos_psi, 0.0) / r**2


@pytest.fixture(scope="module")
def radiosity() -> list[float]:
    """Reflected illuminance [lx] at POINTS of the box of reflectance RHO lit by FLUX lm (m = 1 at the ceiling)."""
    faces = ("floor", "ceiling", "wall_x_min", "wall_x_max", "wall_y_min", "wall_y_max")
    out = []
    for p in POINTS:
        ((h0, h1),) = box_dc_gain(SIZE, [RHO], TX, (0, 0, -1), 1.0, p, (0, 0, 1), AREA)
        exact_h1 = first_bounce_box_dc_gain(
            SIZE, dict.fromkeys(faces, RHO), TX, (0, 0, -1), 1.0, p, (0, 0, 1), AREA, math.pi / 2, rel_tol=1e-4
        )
        los = direct_lx(1.0, 1.0, TX, (0, 0, -1), p) * AREA  # H_los of the point [-]
        out.append(FLUX * (h0 - h1 + exact_h1 - los) / AREA)
    return out


def _box_doc(**simulation) -> dict:
    doc = room_doc(RHO, RHO, RHO, rx=POINTS[0], **simulation)
    doc["receivers"].append({"id": "centre", "position": list(POINTS[1]), "normal": [0, 0, 1], "area": AREA})
    doc["transmitters"][0]["luminous_output"] = {"luminous_flux": FLUX}
    return doc


def _agrees(total, se, direct, reflected_ref) -> bool:
    return abs(total - (direct + reflected_ref)) <= 4 * se + BUDGET * reflected_ref


def test_total_illuminance_of_a_box_matches_radiosity(radiosity):
    """Every order of an empty box (rho 0.5, K = 40 leaves < 1e-12 of it): total = exact direct + reflected within
    4 sigma + 1 %; the direct part exact; a 10 % error in the reflected part fails the same comparison."""
    res = simulate(spec(_box_doc(max_reflections=40, paths=20_000, seed=3, t_max_s=1e-6)))
    for link, p, ref in zip(res["links"], POINTS, radiosity):
        direct = direct_lx(FLUX, 1.0, TX, (0, 0, -1), p)
        assert link["illuminance_direct_lx"] == pytest.approx(direct, rel=1e-9)
        total, se = link["illuminance_lx"], link["illuminance_lx_stderr"]
        assert 0 < se < 0.02 * ref
        assert _agrees(total, se, direct, ref), (total, se, direct, ref)
        assert not _agrees(total, se, direct, 1.1 * ref)  # power: 10 % more reflected light is seen
        assert not _agrees(total, se, direct, 0.9 * ref)
        # the reflected part is Phi (H0 - H_los) / A of the link's own gain and error
        assert total - direct == pytest.approx(FLUX * (link["dc_gain"] - link["los_gain"]) / AREA, rel=1e-9)
        assert se == pytest.approx(FLUX * link["dc_gain_stderr"] / AREA, rel=1e-9)
    assert not any("fov_deg < 90" in w for w in res["warnings"])


def test_line_of_sight_run_gives_direct_light_only_and_no_error():
    res = simulate(spec(_box_doc(max_reflections=0)))
    for link, p in zip(res["links"], POINTS):
        assert link["illuminance_lx"] == pytest.approx(direct_lx(FLUX, 1.0, TX, (0, 0, -1), p), rel=1e-9)
        assert link["illuminance_lx_stderr"] == 0.0


def test_filter_and_concentrator_do_not_change_the_illuminance():
    """E_refl = Phi H_nlos / (A T_s g): the receiver's gain cancels (same seed, same paths)."""
    plain = simulate(spec(_box_doc(max_reflections=3, paths=4000)))
    doc = _box_doc(max_reflections=3, paths=4000)
    doc["receivers"][1].update(filter_gain=0.5, concentrator_index=1.5)
    other = simulate(spec(doc))
    a, b = plain["links"][1], other["links"][1]
    assert b["dc_gain"] == pytest.approx(a["dc_gain"] * 0.5 * 1.5**2, rel=1e-9)
    assert b["illuminance_lx"] == pytest.approx(a["illuminance_lx"], rel=1e-9)
    assert b["illuminance_lx_stderr"] == pytest.approx(a["illuminance_lx_stderr"], rel=1e-9)


def test_narrow_fov_warns_with_the_share_it_may_miss():
    doc = _box_doc(max_reflections=2, paths=2000)
    doc["receivers"][1]["fov_deg"] = 60.0
    res = simulate(spec(doc))
    (w,) = [w for w in res["warnings"] if "fov_deg < 90" in w]
    assert "centre" in w and "25.00% at 60 deg" in w and "fov_deg = 90" in w


# --- one luminous flux -------------------------------------------------------------------------------------------


def _photometric_tx(**extra) -> dict:
    data = base64.b64encode((EXAMPLES / "downlight_batwing.ies").read_bytes()).decode()
    return {"id": "lum", "position": [2.5, 2.5, 3.0], "normal": [0, 0, -1], "power": 1.0,
            "photometry": {"data_base64": data, "format": "ies"}, **extra}  # fmt: skip


def test_flux_precedence_source_and_disagreement_warning():
    """luminous_output > photometric file: the result names the source, lists both, warns past 5 %; the direct
    light scales with the flux used."""
    doc = room_doc(max_reflections=0)
    doc["transmitters"] = [_photometric_tx()]
    alone = simulate(spec(doc))
    (row,) = alone["lighting"]["transmitters"]
    assert row["luminous_flux_source"] == "photometry" and row["candidates_lm"].keys() == {"photometry"}
    file_flux = row["luminous_flux_lm"]
    doc["transmitters"] = [_photometric_tx(luminous_output={"luminous_flux": 3600.0})]
    given = simulate(spec(doc))
    (row,) = given["lighting"]["transmitters"]
    assert row["luminous_flux_source"] == "luminous_output" and row["luminous_flux_lm"] == 3600.0
    assert row["candidates_lm"]["photometry"] == pytest.approx(file_flux)
    pct = abs(file_flux - 3600.0) / 3600.0
    assert pct > 0.05
    msg = f"lum: luminous_output 3600 lm differs from the photometry's {file_flux:.0f} lm by {pct:.0%}; 3600 lm is used"
    assert msg in given["warnings"]
    ratio = given["links"][0]["illuminance_lx"] / alone["links"][0]["illuminance_lx"]
    assert ratio == pytest.approx(3600.0 / file_flux, rel=1e-12)
    assert not any("differs from" in w for w in alone["warnings"])


def _spectral_doc(luminous_flux=None) -> dict:
    doc = room_doc(max_reflections=2, paths=4000)
    doc["spectral"] = {"band_edges": [380e-9, 480e-9, 580e-9, 680e-9, 780e-9]}
    doc["transmitters"][0]["power"] = 10.0
    if luminous_flux is not None:
        doc["transmitters"][0]["luminous_output"] = {"luminous_flux": luminous_flux}
    return doc


def test_spectral_flux_is_overridden_by_a_given_flux_everywhere():
    """Spectrum flux P x K_m sum f_b Vbar_b; a given flux wins and scales every luminous figure by the same ratio."""
    base = simulate(spec(_spectral_doc()))
    (row,) = base["lighting"]["transmitters"]
    assert row["luminous_flux_source"] == "spectrum"
    spectrum_flux = row["luminous_flux_lm"]
    assert spectrum_flux == pytest.approx(base["spectral"]["transmitters"][0]["luminous_flux_lm"], rel=1e-12)
    given = simulate(spec(_spectral_doc(luminous_flux=2.0 * spectrum_flux)))
    assert given["lighting"]["transmitters"][0]["luminous_flux_source"] == "luminous_output"
    assert any("luminous_output" in w and "50%" in w for w in given["warnings"])
    a, b = base["links"][0], given["links"][0]
    for key in ("illuminance_lx", "illuminance_direct_lx", "illuminance_lx_stderr"):
        assert b[key] == pytest.approx(2.0 * a[key], rel=1e-9)
    sa, sb = base["spectral"]["links"][0], given["spectral"]["links"][0]
    for key in ("illuminance_lx", "illuminance_direct_lx", "illuminance_lx_stderr"):
        assert sb[key] == pytest.approx(2.0 * sa[key], rel=1e-9)
    # the total of the links is the spectral luminous channel's reflected part plus the exact direct light
    assert a["illuminance_lx"] - a["illuminance_direct_lx"] == pytest.approx(
        sa["illuminance_lx"] - sa["illuminance_direct_lx"], rel=1e-9
    )
    assert a["illuminance_lx_stderr"] == pytest.approx(sa["illuminance_lx_stderr"], rel=1e-9)


# --- channels and maps ---------------------------------------------------------------------------------------------


def _office(**simulation) -> dict:
    """Komine's four lamps (one group) over a 5 x 5 grid of the 0.85 m plane; lamp 4 dimmed to half its flux."""
    lamps = [(1.25, 1.25), (1.25, 3.75), (3.75, 1.25), (3.75, 3.75)]
    tx = [
        {"id": f"led{k + 1}", "position": [x, y, 3.0], "normal": [0, 0, -1], "half_power_semi_angle_deg": 70,
         "power": 72.0, "luminous_output": {"center_luminous_intensity": 2628.0}}
        for k, (x, y) in enumerate(lamps)
    ]  # fmt: skip
    sim = {"algorithm": 1, "max_reflections": 3, "paths": 4000, "seed": 5, "t_max_s": 2e-7}
    sim.update(simulation)
    return {
        "room": {"size": [5.0, 5.0, 3.0], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": 0.8}},
        "transmitters": tx,
        "transmitter_groups": [{"name": "ceiling", "transmitters": [t["id"] for t in tx]}],
        "receiver_grids": [{"id_prefix": "plane", "origin": [0.5, 0.5, 0.85], "size": [4.0, 4.0], "spacing": 1.0,
                            "normal": [0, 0, 1], "area": 1e-4}],
        "simulation": sim,
    }  # fmt: skip


def test_group_channel_and_map_illuminance_sum_the_members():
    res = simulate(spec(_office()))
    n_rx = len(res["receivers"])
    links = res["links"]
    (m,) = res["maps"]
    assert m["units"]["illuminance_lx"] == "lx" and "illuminance_lx" in m["stderr"]
    for c in res["channels"]:
        j = c["receiver_index"]
        members = [links[i * n_rx + j] for i in range(4)]
        for key in ("illuminance_lx", "illuminance_direct_lx"):
            assert c[key] == pytest.approx(sum(x[key] for x in members), rel=1e-12)
        # one luminous efficacy in the group: the channel's error bar, exactly (k P_g se(H_g) / A)
        k = res["lighting"]["transmitters"][0]["luminous_flux_lm"] / 72.0
        assert c["illuminance_lx_stderr"] == pytest.approx(k * 4 * 72.0 * c["dc_gain_stderr"] / 1e-4, rel=1e-9)
        i, jj = res["receivers"][j]["i"], res["receivers"][j]["j"]
        assert m["values"]["illuminance_lx"][i][jj] == pytest.approx(c["illuminance_lx"], rel=1e-12)
        assert m["stderr"]["illuminance_lx"][i][jj] == pytest.approx(c["illuminance_lx_stderr"], rel=1e-12)


def test_a_group_with_a_member_without_flux_warns_that_its_light_is_left_out():
    doc = _office(max_reflections=0)
    del doc["transmitters"][3]["luminous_output"]  # a grey scene: led4 has no flux at all
    res = simulate(spec(doc))
    (warning,) = [w for w in res["warnings"] if "leaves out" in w]
    assert "ceiling" in warning and "led4" in warning and "led1" not in warning
    assert not [w for w in simulate(spec(_office(max_reflections=0)))["warnings"] if "leaves out" in w]


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_members_of_different_efficacy_bound_the_channel_error(direction):
    """Forward paths: the members' errors are independent, so the channel's is the root sum of squares; backward
    paths are shared by the members of a point: their errors add (an upper bound). A member without light adds
    nothing to the channel's illuminance nor to its error."""
    doc = _office(direction=direction)
    doc["transmitters"][3]["luminous_output"] = {"center_luminous_intensity": 1314.0}
    del doc["transmitters"][2]["luminous_output"]
    res = simulate(spec(doc))
    n_rx = len(res["receivers"])
    assert res["lighting"]["transmitters"][2]["luminous_flux_lm"] is None
    for c in res["channels"]:
        rows = [res["links"][i * n_rx + c["receiver_index"]] for i in range(4)]
        assert rows[2]["illuminance_lx"] is None and rows[0]["illuminance_lx_stderr"] > 0
        lit = [r for k, r in enumerate(rows) if k != 2]
        assert c["illuminance_lx"] == pytest.approx(sum(r["illuminance_lx"] for r in lit), rel=1e-12)
        se = [r["illuminance_lx_stderr"] for r in lit]
        expected = math.sqrt(sum(s * s for s in se)) if direction == "forward" else sum(se)
        assert c["illuminance_lx_stderr"] == pytest.approx(expected, rel=1e-9)
