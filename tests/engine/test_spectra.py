"""Spectral scenes (engine/spectral/spectra.py): bands traced together, each against its own reference.

- flat spectra give the grey result (same paths, ratios exactly 1);
- a two-band run equals two one-band runs with the same seed (the geometry is shared; no roulette);
- the illuminance of a white LED equals K_m int S V / int S x the radiometric LOS irradiance,
  integrated here with numpy on colour-science's CIE 1924 table (not the code under test);
- the first bounce of a room with coloured walls per band against the deterministic integrator of
  tests/reference.py (Barry et al. 1993), within 4 standard errors + 0.1 %;
- algorithm 1 with smoke per band: LOS transmittance exp(-sigma_t,b d) per band in closed form.
"""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
from pydantic import ValidationError

from owcsim.engine.core.errors import SceneError
from owcsim.engine.run.simulate import simulate as _simulate
from tests import reference
from tests.scenes import room_doc, spec

NM = 1e-9


def simulate(scene_spec, **kw) -> dict:
    """The result as its JSON document (the engine returns a dict or a typed result, by version)."""
    res = _simulate(scene_spec, **kw)
    return res if isinstance(res, dict) else json.loads(res.model_dump_json())


def _spectral_room(walls, floor, ceiling, bands, **sim):
    doc = room_doc(**{"russian_roulette": False, "paths": 6000, "batch_size": 2000, **sim})
    doc["room"]["reflectance"] = {"floor": floor, "ceiling": ceiling, "walls": walls}
    doc["spectral"] = bands
    return doc


def _surf(values):
    return {"type": "spectral", "reflectance": values}


def test_flat_spectra_give_the_grey_result():
    grey = simulate(spec(room_doc(rho_walls=0.6, rho_floor=0.3, rho_ceiling=0.8, paths=6000)))
    doc = _spectral_room(
        _surf([0.6, 0.6, 0.6]),
        _surf(0.3),
        0.8,
        {"band_edges": [400 * NM, 500 * NM, 600 * NM, 700 * NM]},
        russian_roulette=True,
    )
    doc["simulation"]["batch_size"] = 16384
    doc["transmitters"][0]["spectrum"] = [1.0, 2.0, 0.5]
    res = simulate(spec(doc))
    g, s = grey["links"][0], res["links"][0]
    assert res["spectral"]["carried_ratios"]
    assert s["dc_gain"] == pytest.approx(g["dc_gain"], rel=1e-12)
    assert s["rms_delay_spread_s"] == pytest.approx(g["rms_delay_spread_s"], rel=1e-10)
    assert np.allclose(s["cir"]["total"], g["cir"]["total"], rtol=1e-12, atol=0)
    band = res["spectral"]["links"][0]
    assert np.allclose(band["dc_gain_by_band"], g["dc_gain"], rtol=1e-12)
    assert band["optical_gain"] == pytest.approx(g["dc_gain"], rel=1e-12)


def test_two_bands_equal_two_single_band_runs():
    walls, floor = [0.2, 0.7], [0.5, 0.1]
    # one direction for all three runs (the automatic choice depends on each run's reflectances)
    bands = {"wavelengths": [450 * NM, 650 * NM]}
    two = simulate(spec(_spectral_room(_surf(walls), _surf(floor), 0.8, bands, direction="backward")))
    gains = two["spectral"]["links"][0]["dc_gain_by_band"]
    rms = two["spectral"]["links"][0]["rms_delay_spread_s_by_band"]
    for b in range(2):
        band = {"wavelengths": [(450, 650)[b] * NM]}
        one = simulate(spec(_spectral_room(_surf([walls[b]]), _surf([floor[b]]), 0.8, band, direction="backward")))
        assert not one["spectral"]["carried_ratios"]
        assert gains[b] == pytest.approx(one["links"][0]["dc_gain"], rel=1e-12)
        assert rms[b] == pytest.approx(one["links"][0]["rms_delay_spread_s"], rel=1e-10)
    # power check: the bands differ by far more than rounding, so a mix-up of bands would fail
    assert abs(gains[0] / gains[1] - 1) > 0.05


def test_two_bands_with_smoke_per_band_equal_single_band_runs():
    medium = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.0}
    doc = _spectral_room(
        _surf([0.2, 0.7]),
        0.3,
        0.8,
        {"wavelengths": [450 * NM, 650 * NM], "medium": {"sigma_a": [0.3, 0.1], "sigma_s": [0.0, 0.0]}},
    )
    doc["medium"] = medium
    two = simulate(spec(doc))
    for b, (rho, sigma) in enumerate([(0.2, 0.3), (0.7, 0.1)]):
        one_doc = _spectral_room(_surf([rho]), 0.3, 0.8, {"wavelengths": [(450, 650)[b] * NM]})
        one_doc["medium"] = {"type": "homogeneous", "sigma_a": sigma, "sigma_s": 0.0}
        one = simulate(spec(one_doc))
        assert two["spectral"]["links"][0]["dc_gain_by_band"][b] == pytest.approx(one["links"][0]["dc_gain"], rel=1e-11)


def test_smoke_per_band_line_of_sight_in_closed_form():
    doc = room_doc(max_reflections=0)
    doc["medium"] = {"type": "homogeneous", "sigma_a": 0.1, "sigma_s": 0.0}
    doc["spectral"] = {
        "band_edges": [400 * NM, 500 * NM, 600 * NM],
        "medium": {"sigma_a": [0.4, 0.1], "sigma_s": [0.0, 0.05]},
    }
    res = simulate(spec(doc))
    d = math.dist((2.5, 2.5, 3.0), (1.0, 1.0, 0.0))
    los, _ = reference.los_gain((2.5, 2.5, 3.0), (0, 0, -1), 1.0, (1.0, 1.0, 0.0), (0, 0, 1), 1e-4, math.pi / 2)
    by_band = res["spectral"]["links"][0]["dc_gain_by_band"]
    assert by_band == pytest.approx([los * math.exp(-0.4 * d), los * math.exp(-0.15 * d)], rel=1e-12)
    assert res["links"][0]["dc_gain"] == pytest.approx(0.5 * sum(by_band), rel=1e-12)  # flat SPD: half per band
    assert [m["sigma_t"] for m in res["spectral"]["medium_bands"]] == pytest.approx([0.4, 0.15])


def _led(lam):
    """A white LED of the test's own: blue chip (448 nm, FWHM 22 nm) + phosphor (565 nm, FWHM 120 nm)."""

    def g(peak, fwhm):
        return np.exp(-0.5 * ((lam - peak) / (fwhm / 2.3548)) ** 2)

    return 1.8 * g(448 * NM, 22 * NM) + g(565 * NM, 120 * NM)


def test_white_led_illuminance_against_a_hand_computation():
    from colour.colorimetry import SDS_LEFS_PHOTOPIC

    lam = np.linspace(380 * NM, 780 * NM, 801)
    power, h = 2.0, 2.5
    doc = room_doc(max_reflections=0, tx=(2.5, 2.5, 3.0), rx=(2.5, 2.5, 0.5), area=1e-4)
    doc["transmitters"][0].update(
        power=power, spectrum={"type": "table", "wavelengths": lam.tolist(), "values": _led(lam).tolist()}
    )
    doc["spectral"] = {"band_edges": np.linspace(380 * NM, 780 * NM, 9).tolist()}
    res = simulate(spec(doc))
    # by hand: K_m int S V / int S on a fine grid, times the irradiance P (m + 1) / (2 pi h^2) below a Lambertian
    fine = np.linspace(380, 780, 40001)
    cie = SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    v = np.interp(fine, cie.wavelengths, cie.values)
    s = _led(fine * NM)
    efficacy = 683.0 * np.trapezoid(s * v, fine) / np.trapezoid(s, fine)
    e_v = efficacy * power * 2 / (2 * math.pi * h * h)
    got = res["spectral"]["links"][0]["illuminance_lx"]
    assert got == pytest.approx(e_v, rel=2e-4)
    assert res["spectral"]["transmitters"][0]["luminous_efficacy_lm_per_w"] == pytest.approx(efficacy, rel=2e-4)
    # power check: the luminous efficacy of a flat SPD over the same range differs by > 5 %
    flat = 683.0 * np.trapezoid(v, fine) / 400
    assert abs(flat / efficacy - 1) > 0.05


def test_coloured_walls_first_bounce_against_the_integrator():
    size, tx, rx = (5.0, 5.0, 3.0), (2.5, 2.5, 3.0), (1.0, 1.0, 0.0)
    walls, floor, ceiling = [0.15, 0.75], [0.4, 0.2], [0.8, 0.8]
    doc = _spectral_room(
        _surf(walls),
        _surf(floor),
        _surf(ceiling),
        {"wavelengths": [470 * NM, 620 * NM]},
        max_reflections=1,
        paths=100_000,
        batch_size=20_000,
    )
    doc["simulation"]["direction"] = "backward"
    res = simulate(spec(doc))
    link = res["spectral"]["links"][0]
    los = res["links"][0]["los_gain"]
    for b in range(2):
        rho = {"floor": floor[b], "ceiling": ceiling[b], **{f: walls[b] for f in reference.FACES[2:]}}
        ref = reference.first_bounce_box_dc_gain(
            size, rho, tx, (0, 0, -1), 1.0, rx, (0, 0, 1), 1e-4, math.pi / 2, rel_tol=1e-3
        )
        h1, se = link["dc_gain_by_band"][b] - los, link["dc_gain_by_band_stderr"][b]
        assert abs(h1 - ref) <= 4 * se + 1e-3 * ref, (b, h1, ref, se)
        assert 4 * se < 0.03 * ref  # a 3 % error in a band would fail
    # the channels' error bars (spread of 16 path groups) agree with the main tally's per-path ones
    assert 0.5 < link["optical_gain_stderr"] / res["links"][0]["dc_gain_stderr"] < 2.0


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_electrical_gain_is_the_responsivity_weighted_sum(direction):
    """Two transmitters with their own SPDs, receivers with their own responsivity and filter, a grid."""
    doc = _spectral_room(
        _surf([0.3, 0.6]), 0.3, 0.8, {"band_edges": [500 * NM, 700 * NM, 900 * NM]}, direction=direction, paths=2000
    )
    doc["transmitters"][0]["spectrum"] = [3.0, 1.0]
    doc["transmitters"].append(
        {"id": "tx2", "position": [1, 4, 3], "normal": [0, 0, -1], "lambertian_order": 2, "spectrum": [1.0, 3.0]}
    )
    doc["receivers"][0].update(responsivity=[0.3, 0.5], filter_transmission=[0.5, 0.9])
    doc["receivers"].append(
        {"id": "rx2", "position": [4, 1, 0], "normal": [0, 0, 1], "area": 1e-4, "responsivity": [0.6, 0.2]}
    )
    doc["receiver_grids"] = [{"origin": [1, 1, 0.8], "size": [1, 1], "spacing": 1.0, "area": 1e-4, "responsivity": 0.4}]
    res = simulate(spec(doc))
    f = {"tx": [0.75, 0.25], "tx2": [0.25, 0.75]}
    e = {"rx": [0.15, 0.45], "rx2": [0.6, 0.2]}
    assert len(res["spectral"]["links"]) == 2 * 6
    for link, main in zip(res["spectral"]["links"], res["links"]):
        h, fb, eb = link["dc_gain_by_band"], f[link["transmitter"]], e.get(link["receiver"], [0.4, 0.4])
        assert link["electrical_gain_a_per_w"] == pytest.approx(fb[0] * eb[0] * h[0] + fb[1] * eb[1] * h[1], rel=1e-12)
        assert link["optical_gain"] == pytest.approx(fb[0] * h[0] + fb[1] * h[1], rel=1e-12)
        assert main["dc_gain"] == pytest.approx(link["optical_gain"], rel=1e-12)


BASE = {
    "room": {"size": [4, 4, 3], "reflectance": {"floor": 0.3, "ceiling": 0.8, "walls": _surf([0.2, 0.7])}},
    "transmitters": [{"position": [2, 2, 3], "normal": [0, 0, -1], "lambertian_order": 1}],
    "receivers": [{"position": [1, 1, 0], "normal": [0, 0, 1], "area": 1e-4}],
    "spectral": {"band_edges": [400e-9, 550e-9, 700e-9]},
}


@pytest.mark.parametrize(
    "change, message",
    [
        (
            lambda d: d.pop("spectral"),
            "room.reflectance.walls.reflectance: a spectral curve needs the scene's wavelength",
        ),
        (lambda d: d["spectral"].update(band_edges=[500e-9, 400e-9]), "strictly increasing: entry 1"),
        (lambda d: d["spectral"].update(band_edges=[400, 500]), "wavelengths are in metres"),
        (
            lambda d: d["room"]["reflectance"].update(walls=_surf([0.2, 1.3])),
            "walls.reflectance: entry 1 value 1.3 outside",
        ),
        (
            lambda d: d["receivers"][0].update(responsivity=[1, 2, 3]),
            "receivers[0].responsivity: 3 values but the scene has 2 band(s)",
        ),
        (
            lambda d: d["transmitters"][0].update(
                spectrum={"type": "table", "wavelengths": [450e-9, 800e-9], "values": [1, 1]}
            ),
            "transmitters[0].spectrum: the table covers",
        ),
        (
            lambda d: d["transmitters"][0].update(spectrum={"type": "named", "name": "white_paint"}),
            "'white_paint' is a reflectance table, not a spectrum",
        ),
        (lambda d: d["transmitters"][0].update(spectrum=[0, 0]), "zero everywhere"),
        (lambda d: d["receivers"][0].update(filter_transmission=[0.5, 1.5]), "filter_transmission: entry 1"),
        (lambda d: d["spectral"].update(medium={"sigma_a": [0.1, 0.1], "sigma_s": [0, 0]}), "the scene has no medium"),
    ],
)
def test_validation_errors_are_located(change, message):
    doc = copy.deepcopy(BASE)
    change(doc)
    with pytest.raises(ValidationError, match=None) as err:
        spec(doc)
    assert message in str(err.value)


def test_scattering_algorithms_in_smoke_per_band_say_what_to_use():
    """Algorithm 5 runs in smoke per band, and automatic settings pick it for scattering smoke; a carrier band that
    does not scatter while others do is refused with what to do."""
    doc = _spectral_room(
        _surf([0.2, 0.7]),
        0.3,
        0.8,
        {"wavelengths": [450 * NM, 650 * NM], "medium": {"sigma_a": [0.05, 0.02], "sigma_s": [0.2, 0.1]}},
        algorithm=5,
        max_scattering=2,
        paths=500,
    )
    doc["medium"] = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2}
    res = simulate(spec(doc))
    assert res["algorithm"] == 5 and res["spectral"]["links"][0]["dc_gain_by_band"][0] > 0
    # automatic settings: the grey rules choose (algorithm 5 for this optically thick, scattering smoke)
    auto = copy.deepcopy(doc)
    auto["simulation"].update(algorithm="auto", max_scattering=None)
    res = simulate(spec(auto))
    assert res["algorithm"] == 5
    assert "varies over the spectral bands" not in res["modeled"]["algorithm_reason"]
    doc["spectral"]["medium"] = {"sigma_a": [0.3, 0.02], "sigma_s": [0.2, 0.0]}  # the carrier (band 1) is clear
    with pytest.raises(SceneError, match="does not scatter while others do"):
        simulate(spec(doc))


@pytest.mark.parametrize("algorithm", [4, 5])
def test_spectral_surfaces_in_grey_smoke_with_scattering_algorithms(algorithm):
    """Algorithms 4 and 5 (both devices, branches, double scattering): flat spectra give the grey result
    (roulette on), and each band of a two-band run equals its one-band run (roulette off)."""
    smoke = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.2, "phase": {"type": "hg", "g": 0.5}}
    sim = {"algorithm": algorithm, "max_reflections": 2, "paths": 1500, "batch_size": 1500, "time_bin_s": 2e-9}
    if algorithm == 5:
        sim["max_scattering"] = 2
    grey = room_doc(rho_walls=0.6, medium=smoke, **sim)
    flat = _spectral_room(
        _surf([0.6, 0.6]), 0.3, 0.8, {"wavelengths": [450 * NM, 650 * NM]}, russian_roulette=True, **sim
    )
    flat["medium"] = smoke
    g, f = simulate(spec(grey)), simulate(spec(flat))
    assert f["spectral"]["carried_ratios"]
    assert f["links"][0]["dc_gain"] == pytest.approx(g["links"][0]["dc_gain"], rel=1e-12)
    assert np.allclose(f["links"][0]["cir"]["total"], g["links"][0]["cir"]["total"], rtol=1e-11, atol=0)
    two = _spectral_room(_surf([0.2, 0.7]), 0.3, 0.8, {"wavelengths": [450 * NM, 650 * NM]}, **sim)
    two["medium"] = smoke
    res = simulate(spec(two))
    for b, rho in enumerate([0.2, 0.7]):
        one = _spectral_room(_surf([rho]), 0.3, 0.8, {"wavelengths": [(450, 650)[b] * NM]}, **sim)
        one["medium"] = smoke
        assert res["spectral"]["links"][0]["dc_gain_by_band"][b] == pytest.approx(
            simulate(spec(one))["links"][0]["dc_gain"], rel=1e-11
        )


def test_particle_smoke_per_band_equals_grey_runs_at_each_wavelength():
    """Mie per band: each band of a two-band soot scene equals the grey scene at that band's wavelength and index."""
    particles = {
        "geometric_mean_diameter": 1.5e-7,
        "geometric_std": 1.8,
        "refractive_index": {"real": 1.57, "imag": 0.56},
        "wavelength": 850 * NM,
    }
    medium = {"type": "particles", "particles": particles, "mass_concentration": 1e-4, "particle_density": 1800.0}
    index = [{"real": 1.55, "imag": 0.50}, {"real": 1.60, "imag": 0.60}]
    doc = _spectral_room(
        _surf([0.3, 0.6]),
        0.3,
        0.8,
        {"wavelengths": [450 * NM, 850 * NM], "medium": {"refractive_index": index}},
        max_reflections=2,
    )
    doc["medium"] = medium
    two = simulate(spec(doc))
    bands = two["spectral"]["medium_bands"]
    assert bands[0]["sigma_t"] > bands[1]["sigma_t"]  # soot attenuates more in the blue
    for b, (lam, rho) in enumerate([(450, 0.3), (850, 0.6)]):
        grey = room_doc(rho_walls=rho, max_reflections=2, russian_roulette=False, paths=6000, batch_size=2000)
        grey["medium"] = {**medium, "particles": {**particles, "wavelength": lam * NM, "refractive_index": index[b]}}
        one = simulate(spec(grey))
        assert one["modeled"]["medium"]["sigma_t"] == pytest.approx(bands[b]["sigma_t"], rel=1e-12)
        assert two["spectral"]["links"][0]["dc_gain_by_band"][b] == pytest.approx(one["links"][0]["dc_gain"], rel=1e-10)


def test_job_memory_estimate_counts_the_channel_sums():
    from owcsim.engine.run.budget import memory_estimate

    doc = room_doc()
    doc["receiver_grids"] = [{"origin": [0.5, 0.5, 0.8], "size": [4, 4], "spacing": 0.1, "area": 1e-4}]
    grey = memory_estimate(spec(doc)).accumulators
    doc["spectral"] = {"band_edges": np.linspace(400e-9, 700e-9, 9).tolist()}
    spectral = memory_estimate(spec(doc)).accumulators
    n_links = 1 + 41 * 41
    assert spectral - grey == 2 * 8 * n_links * ((8 + 10) * 16 + 16)


def _smoke_room(medium, bands, rx=(4.0, 2.5, 1.5), rx_normal=(-1, 0, 0), **sim):
    """A beam along x from (1, 2.5, 1.5) in a dark room with smoke; by default the receiver faces it 3 m away."""
    doc = room_doc(
        rho_walls=0.1,
        rho_floor=0.1,
        rho_ceiling=0.1,
        tx=(1.0, 2.5, 1.5),
        tx_normal=(1, 0, 0),
        m=3.0,
        rx=rx,
        rx_normal=rx_normal,
        medium=medium,
        **{"algorithm": 4, "max_reflections": 1, "paths": 4000, "batch_size": 1000, **sim},
    )
    if bands is not None:
        doc["spectral"] = bands
    return doc


def test_algorithm_4_in_smoke_per_band_against_one_band_runs():
    """Algorithm 4 with coefficients that differ per band: each band agrees with a one-band run of that band's
    smoke within 4 combined standard errors (leaving out the sigma_s,b / sigma_s,c factor fails it)."""
    medium = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.3, "phase": {"type": "hg", "g": 0.6}}
    bands = {"wavelengths": [450 * NM, 850 * NM], "medium": {"sigma_a": [0.2, 0.05], "sigma_s": [0.6, 0.3]}}
    two = simulate(spec(_smoke_room(medium, bands)))["spectral"]["links"][0]
    gains = []
    for b, (sigma_a, sigma_s) in enumerate([(0.2, 0.6), (0.05, 0.3)]):
        one = simulate(spec(_smoke_room({**medium, "sigma_a": sigma_a, "sigma_s": sigma_s}, None, seed=11)))
        one = one["links"][0]
        h, se = two["dc_gain_by_band"][b], two["dc_gain_by_band_stderr"][b]
        assert abs(h - one["dc_gain"]) <= 4 * math.hypot(se, one["dc_gain_stderr"]), (b, h, one["dc_gain"], se)
        gains.append((h, se))
    # power: the two bands' smoke differ by far more than the error bars, so a band mix-up would fail
    assert abs(gains[0][0] - gains[1][0]) > 8 * math.hypot(gains[0][1], gains[1][1])


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", [4, 5])
def test_mie_per_band_carries_the_phase_ratio(monkeypatch, algorithm):
    """Mie per band (phase functions differ: g 0.69 at 450 nm, 0.60 at 850 nm): each band of a two-band run agrees
    with a one-band run at that wavelength within 4 combined standard errors, seen by a receiver below the beam
    (light scattered sideways); without the phase ratio p_b / p_c the blue band misses by more than 4."""
    from owcsim.engine.spectral.spectra import SceneSpectra

    particles = {
        "geometric_mean_diameter": 1.5e-7,
        "geometric_std": 1.8,
        "refractive_index": {"real": 1.5, "imag": 0.01},
        "wavelength": 850 * NM,
    }
    medium = {"type": "particles", "particles": particles, "mass_concentration": 4e-4, "particle_density": 1800.0}
    where = {"rx": (2.5, 2.5, 0.3), "rx_normal": (0, 0, 1), "paths": 40_000, "batch_size": 5000}
    if algorithm == 5:  # free flight: the collisions' sampled directions carry p_b / p_c too
        where.update(algorithm=5, max_scattering=2)
    bands = {"wavelengths": [450 * NM, 850 * NM]}
    two = simulate(spec(_smoke_room(medium, bands, **where)))["spectral"]
    g = [m["g"] for m in two["medium_bands"]]
    assert abs(g[0] - g[1]) > 0.05
    ones = [
        simulate(
            spec(_smoke_room({**medium, "particles": {**particles, "wavelength": lam * NM}}, None, seed=11, **where))
        )["links"][0]
        for lam in (450, 850)
    ]

    def z(link, b):
        return (link["dc_gain_by_band"][b] - ones[b]["dc_gain"]) / math.hypot(
            link["dc_gain_by_band_stderr"][b], ones[b]["dc_gain_stderr"]
        )

    assert all(abs(z(two["links"][0], b)) <= 4 for b in range(2))
    monkeypatch.setattr(SceneSpectra, "phase_ratio", lambda self, cos: np.ones((self.n_bands, len(cos))))
    wrong = simulate(spec(_smoke_room(medium, bands, **where)))["spectral"]["links"][0]
    assert abs(z(wrong, 0)) > 4


def test_algorithm_5_in_smoke_per_band_against_one_band_runs(monkeypatch):
    """Algorithm 5 (free flight, equiangular points, both devices) with coefficients that differ per band: the
    carrier band (the least attenuated, 850 nm) equals its one-band run with the same seed to rounding; the other
    band agrees within 4 combined standard errors with a one-band run of its smoke (another seed) and with
    algorithm 4's (single and double scattering: the same family as S = 2). Power: the bands differ by > 8
    standard errors, and leaving out sigma_s,b / sigma_s,c (a factor 2 here) misses by more than 4."""
    from owcsim.engine.spectral.spectra import SceneSpectra

    medium = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.3, "phase": {"type": "hg", "g": 0.6}}
    bands = {"wavelengths": [450 * NM, 850 * NM], "medium": {"sigma_a": [0.2, 0.05], "sigma_s": [0.6, 0.3]}}
    sim = {"algorithm": 5, "max_scattering": 2, "russian_roulette": False}
    two = simulate(spec(_smoke_room(medium, bands, **sim)))["spectral"]["links"][0]
    assert two["dc_gain_by_band"][1] == pytest.approx(
        simulate(spec(_smoke_room(medium, None, **sim)))["links"][0]["dc_gain"], rel=1e-10
    )
    blue = {**medium, "sigma_a": 0.2, "sigma_s": 0.6}
    h, se = two["dc_gain_by_band"][0], two["dc_gain_by_band_stderr"][0]
    for alg in (5, 4):
        one = simulate(spec(_smoke_room(blue, None, **{**sim, "algorithm": alg, "seed": 11})))["links"][0]
        assert abs(h - one["dc_gain"]) <= 4 * math.hypot(se, one["dc_gain_stderr"]), (alg, h, one["dc_gain"], se)
    assert abs(h - two["dc_gain_by_band"][1]) > 8 * math.hypot(se, two["dc_gain_by_band_stderr"][1])
    scatter = SceneSpectra.scatter

    def without_sigma_s(self, ratio, tau, seg=None):
        keep, self.scatter_scale = self.scatter_scale, None
        try:
            return scatter(self, ratio, tau, seg)
        finally:
            self.scatter_scale = keep

    monkeypatch.setattr(SceneSpectra, "scatter", without_sigma_s)
    wrong = simulate(spec(_smoke_room(medium, bands, **sim)))["spectral"]["links"][0]
    assert abs(wrong["dc_gain_by_band"][0] - one["dc_gain"]) > 4 * math.hypot(se, one["dc_gain_stderr"])


def test_algorithm_5_flat_and_albedo_only_smoke_per_band_equal_grey_runs():
    """Algorithm 5: smoke given per band but flat gives the grey result (roulette on); smoke whose bands share
    sigma_t but not sigma_s samples the same collisions in both bands, so each band equals its grey run with the
    same seed to rounding (band 1 through the ratio sigma_s,1 / sigma_s,0 at every scattering point, the
    equiangular points and the third strategy, events.connect_from_target, included)."""
    smoke = {"type": "homogeneous", "sigma_a": 0.05, "sigma_s": 0.3, "phase": {"type": "hg", "g": 0.6}}
    sim = {"algorithm": 5, "max_scattering": 2, "max_reflections": 1}
    grey = simulate(spec(_smoke_room(smoke, None, russian_roulette=True, **sim)))["links"][0]
    flat = {"wavelengths": [450 * NM, 850 * NM], "medium": {"sigma_a": [0.05, 0.05], "sigma_s": [0.3, 0.3]}}
    res = simulate(spec(_smoke_room(smoke, flat, russian_roulette=True, **sim)))
    assert res["links"][0]["dc_gain"] == pytest.approx(grey["dc_gain"], rel=1e-12)
    assert np.allclose(res["spectral"]["links"][0]["dc_gain_by_band"], grey["dc_gain"], rtol=1e-12)
    albedo = {"wavelengths": [450 * NM, 850 * NM], "medium": {"sigma_a": [0.05, 0.15], "sigma_s": [0.3, 0.2]}}
    two = simulate(spec(_smoke_room(smoke, albedo, russian_roulette=False, **sim)))["spectral"]["links"][0]
    for b, (sigma_a, sigma_s) in enumerate([(0.05, 0.3), (0.15, 0.2)]):
        one = simulate(
            spec(_smoke_room({**smoke, "sigma_a": sigma_a, "sigma_s": sigma_s}, None, russian_roulette=False, **sim))
        )
        assert two["dc_gain_by_band"][b] == pytest.approx(one["links"][0]["dc_gain"], rel=1e-10), b
    # power: the bands differ (the albedo ratio 2/3 acts once or twice) by far more than rounding
    assert two["dc_gain_by_band"][1] < 0.9 * two["dc_gain_by_band"][0]


def test_algorithm_5_in_smoke_per_band_through_reflections(monkeypatch):
    """Algorithm 5 in a bright room (rho 0.8, K = 2) with smoke per band: the attenuated band agrees with its
    one-band run within 4 combined standard errors, the carrier band equals its one-band run with the same seed;
    leaving out T_b / T_c of the flights that reach a surface uncollided misses by more than 4."""
    from owcsim.engine.spectral.spectra import SceneSpectra

    smoke = {"type": "homogeneous", "sigma_a": 0.02, "sigma_s": 0.05, "phase": {"type": "hg", "g": 0.6}}
    bands = {"wavelengths": [450 * NM, 850 * NM], "medium": {"sigma_a": [0.2, 0.02], "sigma_s": [0.1, 0.05]}}
    sim = {"algorithm": 5, "max_scattering": 2, "max_reflections": 2, "paths": 4000, "batch_size": 2000}

    def run(bands, medium, seed=7):
        doc = _spectral_room(0.8, 0.8, 0.8, bands, seed=seed, **sim)
        doc["medium"] = medium
        return simulate(spec(doc))

    two = run(bands, smoke)["spectral"]["links"][0]
    assert two["dc_gain_by_band"][1] == pytest.approx(
        run({"wavelengths": [850 * NM]}, smoke)["links"][0]["dc_gain"], rel=1e-10
    )
    one = run({"wavelengths": [450 * NM]}, {**smoke, "sigma_a": 0.2, "sigma_s": 0.1}, seed=11)["links"][0]
    h, se = two["dc_gain_by_band"][0], two["dc_gain_by_band_stderr"][0]
    tol = 4 * math.hypot(se, one["dc_gain_stderr"])
    assert abs(h - one["dc_gain"]) <= tol, (h, one["dc_gain"], se)
    monkeypatch.setattr(SceneSpectra, "transmit_rows", lambda self, ratio, rows, tau, seg=None: ratio)
    wrong = run(bands, smoke)["spectral"]["links"][0]
    assert abs(wrong["dc_gain_by_band"][0] - one["dc_gain"]) > tol


@pytest.mark.parametrize("carried", [True, False])
def test_channel_builder_sums_against_a_plain_loop(carried):
    """ChannelBuilder.add (sorted by path group, one contraction per group) against sums written out here with
    np.add.at: per target and path group, each band's power, each combination's w, w t, w t^2; per band the
    delay sums; and the optical power it returns. Two targets, estimates in random order."""
    from types import SimpleNamespace

    from owcsim.engine.tally.plan import N_GROUPS
    from owcsim.engine.tally.spectral import ChannelBuilder

    rng = np.random.default_rng(5)
    B, T, m = 3, 2, 500
    sp = SimpleNamespace(
        n_bands=B,
        tx_fraction=np.array([[0.2, 0.5, 0.3]]),
        rx_electrical=rng.random((T, B)),
        tx_luminous=np.array([[100.0, 600.0, 50.0]]),
    )
    builder = ChannelBuilder(sp, "forward", 0, np.arange(T), np.array([4, 9]), 1000)
    target, path = rng.integers(0, T, m), rng.integers(0, 1000, m)
    delay, power = rng.random(m) * 1e-8, rng.random(m)
    ratio = rng.random((B, m)) if carried else np.ones((0, m))
    optical = builder.add(target, delay, power, ratio, path)
    r = ratio if carried else np.ones((B, m))
    sums, bc = np.zeros((B + 9, T, N_GROUPS)), np.zeros((2, B, T))
    for i in range(m):  # the plain reference: one estimate at a time
        j, g = target[i], path[i] % N_GROUPS
        bands = power[i] * r[:, i]
        combo = [bands @ sp.tx_fraction[0], bands @ (sp.tx_fraction[0] * sp.rx_electrical[j])]
        combo.append(bands @ (sp.tx_fraction[0] * sp.tx_luminous[0]))
        sums[:B, j, g] += bands
        for k in range(3):
            sums[B + 3 * k : B + 3 * k + 3, j, g] += np.array(combo) * delay[i] ** k
        bc[0, :, j] += bands * delay[i]
        bc[1, :, j] += bands * delay[i] ** 2
        assert optical[i] == pytest.approx(combo[0], rel=1e-13)
    batch = builder.finish()
    assert np.allclose(batch.sums, sums, rtol=1e-12, atol=0)
    assert np.allclose(batch.band_bc, bc, rtol=1e-12, atol=0)
