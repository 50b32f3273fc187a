"""Mie optics of particle smoke (engine/media/mie.py) and the particle medium spec.

References:
- Wiscombe, W. J. (1979), "Mie scattering calculations: advances in technique and fast,
  vector-speed computer codes", NCAR Tech. Note TN-140+STR, test cases (Qext, Qsca and
  g Qsca to 7 digits), as listed with his MIEV0 code (test driver and the self-test TESTMI
  of MIEV0.f, whose case x = 10, m = 1.5 - 0.1i "may be found among the test cases at the
  end of reference (1)"). Wiscombe writes m = n - ik; here m = n + ik, k >= 0 absorbs.
- Bohren, C. F. & Huffman, D. R. (1983), "Absorption and Scattering of Light by Small
  Particles", Appendix A, BHMIE sample output: m = 1.55, radius 0.525 um, wavelength
  0.6328 um: Qsca = Qext = 3.10543, Qback = 2.92534.
- Rayleigh limit (B&H eqs. 5.7-5.8): Qsca = 8/3 x^4 |K|^2, Qabs = 4 x Im K, K = (m^2-1)/(m^2+2),
  phase 3 (1 + mu^2) / (16 pi); log-normal moments <D^k> = D_g^k exp(k^2 ln^2 sigma_g / 2).
- Size averaging: direct adaptive quadrature (scipy.integrate.quad) of miepython's
  single-sphere results written here.
"""

from __future__ import annotations

import functools
import math
import warnings

import miepython
import numpy as np
import pytest
from pydantic import ValidationError
from scipy import integrate

from owcsim.engine.core.errors import SceneError
from owcsim.engine.media import mie, report
from owcsim.engine.media.media import HomogeneousMedium
from owcsim.engine.media.phase import MiePhase, Tabulated, phase_from_spec
from owcsim.engine.media.registry import medium_from_spec
from owcsim.engine.scene.scene import build_scene
from owcsim.schemas.medium import KOSCHMIEDER, ParticleMediumSpec, ParticlesSpec
from tests.results import simulate_document as simulate
from tests.scenes import room_doc, spec

# (m = n + ik, x, Qext, Qsca, g Qsca): Wiscombe (1979) test cases; the x = 10, m = 1.5 + 0.1i
# row is TESTMI's self-test of MIEV0.
WISCOMBE = [
    (0.75 + 0j, 0.101, 8.033542e-06, 8.033542e-06, 1.211000e-08),
    (0.75 + 0j, 10.0, 2.232265, 2.232265, 2.001164),
    (1.33 + 1e-5j, 1.0, 9.395198e-02, 9.392330e-02, 1.733048e-02),
    (1.33 + 1e-5j, 100.0, 2.101321, 2.096594, 1.821854),
    (1.5 + 1j, 0.055, 1.014910e-01, 1.131687e-05, 5.558541e-09),
    (1.5 + 1j, 1.0, 2.336321, 6.634538e-01, 1.274736e-01),
    (1.5 + 1j, 100.0, 2.097502, 1.283697, 1.091466),
    (10 + 10j, 1.0, 2.532993, 2.049405, -2.267961e-01),
    (10 + 10j, 100.0, 2.071124, 1.836785, 1.021648),
    (1.5 + 0.1j, 10.0, 2.459791, 1.235144, 1.139235),
]


@pytest.mark.parametrize("m, x, qext, qsca, gqsc", WISCOMBE, ids=[f"m={c[0]},x={c[1]}" for c in WISCOMBE])
def test_efficiencies_against_wiscombe_1979(m, x, qext, qsca, gqsc):
    e, s, _, g = (float(v[0]) for v in mie.efficiencies(m, x))
    # published to 7 significant digits (single precision code): 2e-6 relative, 1 unit in the last digit
    assert e == pytest.approx(qext, rel=2e-6, abs=0)
    assert s == pytest.approx(qsca, rel=2e-6, abs=0)
    assert g * s == pytest.approx(gqsc, rel=2e-6, abs=0)
    # the sums over the coefficients that the size averaging uses (B&H 4.61, 4.62, 4.74)
    xs = np.array([x])
    e2, s2, gs2 = (float(v[0]) for v in mie._efficiencies_ab(*mie._coefficients(m, xs), xs))
    assert (e2, s2, gs2) == pytest.approx((qext, qsca, gqsc), rel=2e-6, abs=0)


def test_efficiencies_against_bohren_huffman_appendix_a():
    x = 2 * math.pi * 0.525 / 0.6328
    qext, qsca, qback, _ = (float(v[0]) for v in mie.efficiencies(1.55, x))
    assert (qext, qsca, qback) == pytest.approx((3.10543, 3.10543, 2.92534), abs=6e-6)


def test_efficiencies_have_power():
    e, s, _, _ = mie.efficiencies(1.5 + 0.1j, 10.05)
    assert float(e[0]) != pytest.approx(2.459791, rel=2e-6)  # a 0.5 % size error is seen
    e, s, _, _ = mie.efficiencies(1.5 + 0.101j, 10.0)
    assert float(s[0]) != pytest.approx(1.235144, rel=2e-6)  # and a 1 % error in the absorption index


def _rayleigh_k(m):
    return (m * m - 1) / (m * m + 2)


def test_small_particle_limit_is_rayleigh():
    m, x = 1.5 + 0.1j, 0.005
    qext, qsca, _, g = (float(v[0]) for v in mie.efficiencies(m, x))
    K = _rayleigh_k(m)
    assert qsca == pytest.approx(8 / 3 * x**4 * abs(K) ** 2, rel=1e-4, abs=0)
    assert qext - qsca == pytest.approx(4 * x * K.imag, rel=1e-4, abs=0)
    mu = np.linspace(-1, 1, 21)
    np.testing.assert_allclose(mie.phase_single(m, x, mu), 3 * (1 + mu**2) / (16 * np.pi), rtol=1e-4)
    assert abs(g) < 1e-4


def test_distribution_in_the_rayleigh_regime_against_lognormal_moments():
    """Every size scatters like Rayleigh: sigma/N from <D^6> and <D^3> in closed form, phase 3(1+mu^2)/16pi."""
    lam, dg, sg = 1e-6, 2e-9, 1.5
    m = 1.5 + 0.1j
    p = ParticlesSpec(
        geometric_mean_diameter=dg, geometric_std=sg, refractive_index={"real": 1.5, "imag": 0.1}, wavelength=lam
    )
    o = mie.particle_optics(p, n_angles=201)
    s2 = math.log(sg) ** 2
    K = _rayleigh_k(m)
    c_sca = 2 * math.pi**5 / 3 * abs(K) ** 2 * dg**6 * math.exp(18 * s2) / lam**4
    c_abs = math.pi**2 * K.imag * dg**3 * math.exp(4.5 * s2) / lam
    # (cross sections are ~1e-26 m^2: compare ratios, pytest.approx's default abs=1e-12 would pass anything)
    assert abs(o.c_sca / c_sca - 1) < 5e-4  # measured: 3e-5 and 8e-5 (x^2 corrections)
    assert abs(o.c_abs / c_abs - 1) < 5e-4
    assert abs(o.mean_d3 / (dg**3 * math.exp(4.5 * s2)) - 1) < 1e-12
    np.testing.assert_allclose(o.phase, 3 * (1 + o.cos_theta**2) / (16 * np.pi), rtol=1e-3)
    # power: the monodisperse value (sigma_g ignored) is far off
    assert abs(o.c_sca / (c_sca / math.exp(18 * s2)) - 1) > 1.0


def test_single_sphere_intensity_matches_miepython_angular_sums():
    mu = np.array([-1.0, -0.7660444, -0.2, 0.0, 0.5, 0.9, 0.999, 1.0])
    for m, x in ((1.5 + 0.1j, 10.0), (1.33 + 0j, 30.0), (1.57 + 0.56j, 2.0)):
        ref = miepython.i_unpolarized(complex(m.real, -m.imag), x, mu, norm="wiscombe")
        np.testing.assert_allclose(mie.intensity(m, x, mu)[0], ref, rtol=1e-10)


@pytest.mark.parametrize("m, x", [(1.5 + 0.1j, 10.0), (1.33 + 0j, 30.0), (1.57 + 0.56j, 0.7)])
def test_single_sphere_table_is_normalised_with_mean_cosine_g(m, x):
    mu = mie._table_mu(mie.DEFAULT_ANGLES)
    table = Tabulated(mu, mie.phase_single(m, x, mu))
    g = float(mie.efficiencies(m, x)[3][0])
    assert table.normalisation == pytest.approx(1.0, abs=2e-4)
    assert table.mean_cosine == pytest.approx(g, abs=2e-4)


def _lognormal(y, mu, s):
    return math.exp(-0.5 * ((y - mu) / s) ** 2) / (s * math.sqrt(2 * math.pi))


def _direct(p: ParticlesSpec, fun):
    """int fun(D) n(D) dD by adaptive quadrature in ln D over +-10 ln sigma_g."""
    mu, s = math.log(p.geometric_mean_diameter), math.log(p.geometric_std)
    val, _ = integrate.quad(
        lambda y: fun(math.exp(y)) * _lognormal(y, mu, s), mu - 10 * s, mu + 10 * s, limit=400, epsrel=1e-8, epsabs=0.0
    )
    return val


@pytest.mark.parametrize(
    "index, dg, sg", [((1.57, 0.56), 0.3e-6, 1.6), ((1.33, 0.0), 0.4e-6, 1.4)], ids=["soot", "water"]
)
def test_size_averaging_against_direct_quadrature(index, dg, sg):
    lam = 0.65e-6
    p = ParticlesSpec(
        geometric_mean_diameter=dg,
        geometric_std=sg,
        refractive_index=dict(zip(("real", "imag"), index)),
        wavelength=lam,
    )
    mp_m = complex(index[0], -index[1])

    @functools.cache
    def q(d):
        return [float(np.ravel(v)[0]) for v in miepython.efficiencies_mx(mp_m, math.pi * d / lam)]

    c_ext = _direct(p, lambda d: q(d)[0] * math.pi * d * d / 4)
    c_sca = _direct(p, lambda d: q(d)[1] * math.pi * d * d / 4)
    g_sca = _direct(p, lambda d: q(d)[3] * q(d)[1] * math.pi * d * d / 4)
    o = mie.particle_optics(p, n_angles=401)
    # (cross sections ~1e-13 m^2: ratios, not pytest.approx with its abs=1e-12)
    assert abs(o.c_ext / c_ext - 1) < 1e-6  # measured: 2e-8
    assert abs(o.c_sca / c_sca - 1) < 1e-6
    assert abs(o.g / (g_sca / c_sca) - 1) < 1e-6
    # the averaged phase function at a few angles (miepython's own angular sums, per sphere)
    for mu in (-0.9, 0.0, 0.8):

        def weighted(d, mu=mu):
            x = math.pi * d / lam
            return float(miepython.i_unpolarized(mp_m, x, np.array([mu]), norm="one")[0]) * q(d)[1] * d * d

        ref = _direct(p, weighted) / _direct(p, lambda d: q(d)[1] * d * d)
        assert float(np.interp(mu, o.cos_theta, o.phase)) == pytest.approx(ref, rel=1e-4)
    table = MiePhase(o.cos_theta, o.phase)
    assert table.normalisation == pytest.approx(1.0, abs=1e-4)
    assert table.mean_cosine == pytest.approx(o.g, abs=1e-4)


SOOT = {
    "geometric_mean_diameter": 1.5e-7,
    "geometric_std": 1.8,
    "refractive_index": {"real": 1.57, "imag": 0.56},
    "wavelength": 8.5e-7,
}


def _medium(**kw):
    return {"type": "particles", "particles": SOOT, "mass_concentration": 5e-5, "particle_density": 1800.0, **kw}


def test_mass_concentration_to_number_by_quadrature():
    med = ParticleMediumSpec.model_validate(_medium())
    p = med.particles
    d3 = _direct(p, lambda d: d**3)
    assert mie.number_concentration(med) == pytest.approx(5e-5 / (1800.0 * math.pi / 6 * d3), rel=1e-7, abs=0)


def test_particle_medium_builds_coefficients_and_mie_table():
    doc = room_doc(medium=_medium(region={"type": "box", "min": [0, 0, 1.5], "max": [5, 5, 3]}))
    scene = build_scene(spec(doc))
    med_spec = spec(doc).medium
    o = mie.particle_optics(med_spec.particles)
    n = mie.number_concentration(med_spec)
    assert isinstance(scene.medium, HomogeneousMedium) and scene.medium.bounds is not None
    assert scene.medium.sigma_s == pytest.approx(n * o.c_sca, rel=1e-12, abs=0)
    assert scene.medium.sigma_a == pytest.approx(n * (o.c_ext - o.c_sca), rel=1e-12, abs=0)
    assert 0.05 < scene.medium.sigma_t < 1.0  # 50 mg/m^3 of soot: visibility of some metres
    assert isinstance(scene.phase, MiePhase) and scene.phase.mean_cosine == pytest.approx(o.g, abs=1e-4)
    info = report.describe(med_spec)
    st = info["sigma_t"]
    assert st == pytest.approx(scene.medium.sigma_t, rel=1e-12)
    assert info["visibility_m"] == pytest.approx(KOSCHMIEDER / st)
    assert info["albedo"] == pytest.approx(scene.medium.albedo)
    assert info["g"] == o.g and abs(info["phase"]["normalisation"] - 1) < 1e-4
    assert info["phase"]["type"] == "mie" and info["phase"]["points"] == mie.DEFAULT_ANGLES
    # the same smoke as a homogeneous medium with the derived numbers and the table gives the same run
    sim = dict(algorithm=5, direction="forward", max_scattering=3, paths=4000, seed=5)
    a = simulate(spec(room_doc(medium=_medium(), **sim)))["links"][0]
    hom = {
        "type": "homogeneous",
        "sigma_a": info["sigma_a"],
        "sigma_s": info["sigma_s"],
        "phase": {"type": "tabulated", "cos_theta": o.cos_theta.tolist(), "values": o.phase.tolist()},
    }
    b = simulate(spec(room_doc(medium=hom, **sim)))["links"][0]
    assert a["dc_gain"] == pytest.approx(b["dc_gain"], rel=1e-9, abs=0)


def test_number_concentration_and_zero_concentration():
    med = ParticleMediumSpec.model_validate({"type": "particles", "particles": SOOT, "number_concentration": 1e12})
    o = mie.particle_optics(med.particles)
    assert mie.medium_coefficients(med) == pytest.approx((1e12 * o.c_abs, 1e12 * o.c_sca), rel=1e-12, abs=0)
    none = ParticleMediumSpec.model_validate({"type": "particles", "particles": SOOT, "number_concentration": 0})
    assert medium_from_spec(none) is None
    assert isinstance(phase_from_spec({"type": "mie", "particles": SOOT}), MiePhase)


@pytest.mark.parametrize(
    "doc, match",
    [
        (_medium(number_concentration=1e12), "exactly one of"),
        ({"type": "particles", "particles": SOOT, "mass_concentration": 1e-4}, "needs `particle_density`"),
        (
            {"type": "particles", "particles": SOOT, "number_concentration": 1e12, "particle_density": 1800},
            "only with `mass_concentration`",
        ),
        (_medium(particles={**SOOT, "geometric_mean_diameter": 1e-5}), "reaches size parameter"),
        (_medium(particles={**SOOT, "geometric_std": 0.9}), "greater than or equal to 1"),
        (_medium(particles={**SOOT, "refractive_index": {"real": 1.5, "imag": -0.1}}), "greater than or equal to 0"),
        (_medium(particles={**SOOT, "wavelength": 0}), "greater than 0.00000001"),
    ],
)
def test_bad_particle_media_are_refused(doc, match):
    with pytest.raises(ValidationError, match=match):
        ParticleMediumSpec.model_validate(doc)


def test_opaque_particle_medium_is_a_located_scene_error():
    med = ParticleMediumSpec.model_validate(_medium(mass_concentration=9.0))
    with pytest.raises(SceneError, match="medium: the particles give sigma_t"):
        medium_from_spec(med)


def test_size_limit_is_where_the_engine_window_ends():
    """The schema's size-parameter limit uses the upper end of the window the engine integrates over."""
    from owcsim.schemas.medium import MAX_SIZE_PARAMETER, SIZE_WINDOW_SIGMAS

    lam, sg = 8.5e-7, 1.8
    s = math.log(sg)
    dg = MAX_SIZE_PARAMETER * lam / math.pi / math.exp(2 * s * s + SIZE_WINDOW_SIGMAS * s)
    ok = {**SOOT, "geometric_std": sg, "geometric_mean_diameter": 0.99 * dg}
    ParticlesSpec.model_validate(ok)
    with pytest.raises(ValidationError, match="reaches size parameter"):
        ParticlesSpec.model_validate({**ok, "geometric_mean_diameter": 1.01 * dg})
    # the engine's window (absorbing and Rayleigh-like bounds, tail 1e-8) ends at or below that estimate
    hi = mie.size_window(0.99 * dg, sg, lam)[1]
    assert math.pi * math.exp(hi) / lam <= MAX_SIZE_PARAMETER


@pytest.mark.parametrize("name", ["light", "dense"])
def test_soot_examples_build(name):
    import json

    from tests.scenes import EXAMPLES

    doc = json.loads((EXAMPLES / f"soot_room_{name}.json").read_text())
    scene = build_scene(spec(doc))
    info = report.describe(scene.spec.medium)
    assert isinstance(scene.phase, MiePhase) and scene.medium.sigma_t == pytest.approx(info["sigma_t"], rel=1e-12)
    # 50 and 250 mg/m^3 of soot: visibility of tens of metres and of a few metres
    assert (10 < info["visibility_m"] < 40) if name == "light" else (2 < info["visibility_m"] < 8)


def test_monodisperse_particles_run_without_warnings_and_equal_one_sphere():
    """geometric_std = 1 (every particle of diameter D_g) is legitimate: no RuntimeWarning (the size window's
    Gaussian divided 0 by 0), and the optics are one sphere's (miepython, an independent implementation)."""
    p = ParticlesSpec(
        geometric_mean_diameter=1.5e-7,
        geometric_std=1.0,
        refractive_index={"real": 1.57, "imag": 0.56},
        wavelength=8.5e-7,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning fails the test
        o = mie.particle_optics(p)
        result = simulate(spec(room_doc(medium=_medium(particles=p.model_dump()), max_reflections=1, paths=512)))
    assert o.nodes == 1 and result["links"][0]["dc_gain"] > 0
    x = math.pi * 1.5e-7 / 8.5e-7
    qext, qsca, _, g = miepython.efficiencies_mx(complex(1.57, -0.56), x)
    area = math.pi * 1.5e-7**2 / 4
    assert o.c_ext == pytest.approx(qext * area, rel=1e-9)
    assert o.c_sca == pytest.approx(qsca * area, rel=1e-9)
    assert o.g == pytest.approx(g, rel=1e-9)
