"""Tests for engine.media.phase: normalization, exact sampling (chi-square), frames, limits, registry."""

from __future__ import annotations

import typing

import numpy as np
import pytest
from scipy import integrate, stats

from conftest import SEED, seeded_rng  # noqa: F401
from owcsim.engine.core.sampling import orthonormal_basis
from owcsim.engine.media import phase as ph
from owcsim.schemas import medium as sm

N_SAMPLES = 100_000
ALPHA = 0.01
N_BINS = 100  # equal-probability bins: expected count 1000 per bin


def _sidak(m: int) -> float:
    return 1.0 - (1.0 - ALPHA) ** (1.0 / m)


# ----------------------------------------------------------------------------------------
# Independent closed-form cos_theta CDFs F(c) = 2 pi int_{-1}^{c} p (derived here, checked
# against quadrature of eval below, so the chi-square tests compare samples with eval).
def _cdf(f, c):
    c = np.asarray(c, dtype=np.float64)
    if isinstance(f, (ph.Isotropic,)):
        return (1.0 + c) / 2.0
    if isinstance(f, ph.Rayleigh):
        return (c**3 + 3.0 * c + 4.0) / 8.0
    if isinstance(f, ph.Schlick):
        k = f.k
        return (1.0 - k) * (1.0 + c) / (2.0 * (1.0 - k * c))
    if isinstance(f, ph.HenyeyGreenstein):
        # F = (1-g^2)/(2g) [D^-1 - (1+g)^-1], D^2 = 1 + g^2 - 2gc; rationalized:
        # F = (1-g)(1+c) / (D (1+g+D)) (no 1/g); D^2 written without cancellation.
        g = f.g
        d2 = (1 - g) ** 2 + 2 * g * (1 - c) if g >= 0 else (1 + g) ** 2 - 2 * g * (1 + c)
        d = np.sqrt(d2)
        return (1 - g) * (1 + c) / (d * (1 + g + d))
    if isinstance(f, ph.Mixture):
        return sum(w * _cdf(p, c) for w, p in zip(f.weights, f.components))
    raise TypeError(f)


_BREAKS = sorted({-1.0, 0.0, 1.0} | {s * (1.0 - 10.0**-j) for j in range(1, 14) for s in (-1, 1)})


def _quad(fun, lo=-1.0, hi=1.0):
    """int_lo^hi fun(c) dc with geometric breakpoints towards +-1 (peaks up to g = 0.999999)."""
    pts = [lo] + [b for b in _BREAKS if lo < b < hi] + [hi]
    return sum(integrate.quad(fun, a, b, epsabs=1e-13, epsrel=1e-12, limit=200)[0] for a, b in zip(pts[:-1], pts[1:]))


def _norm(f):
    return _quad(lambda c: 2 * np.pi * float(f.eval(c)))


def _mean_quad(f):
    return _quad(lambda c: 2 * np.pi * c * float(f.eval(c)))


TWO_HG = ph.Mixture([(0.8, ph.HenyeyGreenstein(0.7)), (0.2, ph.HenyeyGreenstein(-0.3))])
ALL_MIX = ph.Mixture(
    [(1, ph.Isotropic()), (2, ph.HenyeyGreenstein(0.9)), (1.5, ph.Schlick(-0.6)), (0.5, ph.Rayleigh())]
)

NORM_CASES = (
    [ph.Isotropic(), ph.Rayleigh(), TWO_HG, ALL_MIX]
    + [ph.HenyeyGreenstein(g) for g in (0.0, 0.5, -0.5, 0.9, -0.9, 0.999, -0.999, 0.9999, -0.9999)]
    + [ph.Schlick(k) for k in (0.0, 0.5, -0.5, 0.999, -0.999)]
    + [ph.Schlick.from_g(0.7), ph.Schlick.from_g(0.999, method="exact")]
)

CHI_CASES = (
    [ph.Isotropic(), ph.Rayleigh(), TWO_HG, ALL_MIX]
    + [ph.HenyeyGreenstein(g) for g in (0.0, 0.3, -0.3, 0.5, 0.9, -0.9, 0.999, -0.999)]
    + [ph.Schlick(k) for k in (0.5, -0.5, 0.9, 0.999, -0.999)]
    + [ph.Schlick.from_g(0.7)]
)


@pytest.mark.parametrize("f", NORM_CASES, ids=repr)
def test_normalized_over_sphere(f):
    assert _norm(f) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("f", NORM_CASES, ids=repr)
def test_independent_cdf_matches_eval(f):
    # the test-side CDFs are what the chi-square uses; tie them to eval by quadrature
    for c in (-0.99, -0.5, 0.0, 0.5, 0.99, 0.999999):
        assert _cdf(f, c) == pytest.approx(_quad(lambda x: 2 * np.pi * float(f.eval(x)), hi=c), abs=1e-8)
    assert _cdf(f, 1.0) == pytest.approx(1.0, abs=1e-13)


@pytest.mark.parametrize("f", [f for f in NORM_CASES if not isinstance(f, ph.Mixture)], ids=repr)
def test_sample_cos_is_exact_inverse_cdf(f):
    # (mixtures sample by composition, not by inverting the mixture CDF: chi-square below)
    u = np.linspace(0.0, 1.0, 4001)[:-1]
    c = f.sample_cos(u)
    assert np.all(np.isfinite(c)) and np.all(np.abs(c) <= 1.0)
    assert np.all(np.diff(c) >= 0)  # inverse CDF is monotone
    # F(c) = u up to the rounding of c itself: |dF/dc| ulp(c) = 2 pi p(c) ulp(c)
    tol = 1e-13 + 2 * np.pi * f.eval(c) * np.spacing(np.abs(c) + 1e-3)
    assert np.all(np.abs(_cdf(f, c) - u) <= tol)


@pytest.mark.parametrize("f", NORM_CASES, ids=repr)
def test_mean_cosine_property_matches_quadrature(f):
    assert f.mean_cosine == pytest.approx(_mean_quad(f), abs=1e-8)


@pytest.mark.parametrize("g", (0.0, 0.2, -0.5, 0.9, -0.9, 0.999))
def test_hg_mean_cosine_is_g(g):
    f = ph.HenyeyGreenstein(g)
    assert _mean_quad(f) == pytest.approx(g, abs=1e-8)
    c = f.sample_cos(seeded_rng().random(N_SAMPLES))
    se = max(c.std(ddof=1), 1e-12) / np.sqrt(c.size)
    assert abs(c.mean() - g) < 5 * se


def _chi2_pvalue(samples_cos, f):
    """Equal-probability bins of the exact CDF of f: histogram of F(c) on [0, 1]."""
    counts, _ = np.histogram(_cdf(f, samples_cos), bins=N_BINS, range=(0.0, 1.0))
    assert counts.sum() == samples_cos.size
    return stats.chisquare(counts).pvalue  # expected counts equal: n / N_BINS = 1000 >= 5


@pytest.mark.parametrize("f", CHI_CASES, ids=repr)
def test_sampled_cos_matches_pdf_chi_square(f):
    rng = seeded_rng()
    d = rng.normal(size=(3, N_SAMPLES))
    d /= np.linalg.norm(d, axis=0)
    out = f.sample(d, rng.random(N_SAMPLES), rng.random(N_SAMPLES))
    cos = np.clip(np.einsum("ij,ij->j", d, out), -1.0, 1.0)
    assert _chi2_pvalue(cos, f) > _sidak(len(CHI_CASES))


def test_chi_square_has_power():
    c = ph.HenyeyGreenstein(0.5).sample_cos(seeded_rng().random(N_SAMPLES))
    assert _chi2_pvalue(c, ph.HenyeyGreenstein(0.5)) > _sidak(len(CHI_CASES))
    assert _chi2_pvalue(c, ph.HenyeyGreenstein(0.6)) < 1e-6


FIXED_DIRS = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0.48, -0.6, 0.64)]


@pytest.mark.parametrize("f", [ph.HenyeyGreenstein(0.8), ph.Schlick(-0.5), ph.Rayleigh(), TWO_HG], ids=repr)
def test_sample_directions_unit_cos_and_uniform_azimuth(f):
    rng = seeded_rng()
    u1, u2 = rng.random(N_SAMPLES), rng.random(N_SAMPLES)
    d = rng.normal(size=(3, N_SAMPLES))
    d[:, :4] = np.array(FIXED_DIRS, dtype=float).T
    d /= np.linalg.norm(d, axis=0)
    out = f.sample(d, u1, u2)
    assert out.shape == (3, N_SAMPLES)
    np.testing.assert_allclose(np.linalg.norm(out, axis=0), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.einsum("ij,ij->j", d, out), f.sample_cos(u1), atol=1e-12)
    # azimuth in the orthonormal_basis frame is 2 pi u2
    s, t = orthonormal_basis(d.T)
    phi = np.arctan2(np.einsum("ji,ij->j", t, out), np.einsum("ji,ij->j", s, out)) % (2 * np.pi)
    dphi = np.angle(np.exp(1j * (phi - 2 * np.pi * u2)))
    sin_t = np.sqrt(1 - f.sample_cos(u1) ** 2)
    assert np.all(np.abs(dphi[sin_t > 1e-6]) < 1e-8)
    # frame-independent: azimuth about a fixed direction against an arbitrary reference is uniform
    for dd in FIXED_DIRS:
        dd = np.array(dd, float) / np.linalg.norm(dd)
        o = f.sample(np.repeat(dd[:, None], N_SAMPLES, axis=1), u1, u2)
        ref = np.array([0.3, 0.9, -0.2]) - np.dot([0.3, 0.9, -0.2], dd) * dd
        ref /= np.linalg.norm(ref)
        az = np.arctan2(np.cross(dd, ref) @ o, ref @ o)
        counts, _ = np.histogram(az, bins=N_BINS, range=(-np.pi, np.pi))
        assert stats.chisquare(counts).pvalue > _sidak(4 * len(FIXED_DIRS))


def test_isotropic_output_uniform_on_sphere():
    rng = seeded_rng()
    d = np.repeat(np.array([[0.0], [0.0], [1.0]]), N_SAMPLES, axis=1)
    o = ph.Isotropic().sample(d, rng.random(N_SAMPLES), rng.random(N_SAMPLES))
    for axis in range(3):  # each component uniform on [-1, 1] (Archimedes)
        counts, _ = np.histogram(o[axis], bins=N_BINS, range=(-1, 1))
        assert stats.chisquare(counts).pvalue > _sidak(3)


def test_limit_g_to_zero():
    c = np.linspace(-1, 1, 1001)
    hg = ph.HenyeyGreenstein(1e-9)
    np.testing.assert_allclose(hg.eval(c), 1 / (4 * np.pi), rtol=1e-6)
    u = seeded_rng().random(1000)
    np.testing.assert_allclose(hg.sample_cos(u), 2 * u - 1, atol=1e-8)
    np.testing.assert_array_equal(ph.HenyeyGreenstein(0.0).sample_cos(u), ph.Isotropic().sample_cos(u))
    for g in (1e-3, -1e-3, 1e-12, -1e-300):
        assert np.all(np.isfinite(ph.HenyeyGreenstein(g).sample_cos(u)))


@pytest.mark.parametrize(
    "f",
    [ph.HenyeyGreenstein(0.999999), ph.HenyeyGreenstein(-0.999999), ph.Schlick(0.999999), ph.Schlick(-0.999999)],
    ids=repr,
)
def test_limit_g_to_one_is_finite(f):
    c = np.concatenate([np.linspace(-1, 1, 2001), [np.nextafter(1, 0), np.nextafter(-1, 0)]])
    p = f.eval(c)
    assert np.all(np.isfinite(p)) and np.all(p > 0)
    rng = seeded_rng()
    u = np.concatenate([[0.0, np.nextafter(1, 0), 0.5], rng.random(10_000)])
    cs = f.sample_cos(u)
    assert np.all(np.isfinite(cs)) and np.all(np.abs(cs) <= 1.0)
    d = np.tile([[0.0], [0.0], [1.0]], u.size)
    o = f.sample(d, u, rng.random(u.size))
    assert np.all(np.isfinite(o))
    np.testing.assert_allclose(np.linalg.norm(o, axis=0), 1.0, atol=1e-14)
    assert np.sign(np.median(cs)) == np.sign(f.mean_cosine)


@pytest.mark.parametrize("f", [ph.HenyeyGreenstein(0.6), ph.Schlick(0.6), ph.Schlick.from_g(0.6), TWO_HG], ids=repr)
def test_orientation_positive_is_forward(f):
    # g > 0: the new direction mostly continues along the old propagation direction
    rng = seeded_rng()
    d = np.tile([[0.0], [0.0], [1.0]], N_SAMPLES)
    o = f.sample(d, rng.random(N_SAMPLES), rng.random(N_SAMPLES))
    assert f.mean_cosine > 0 and o[2].mean() > 0.3
    assert f.eval(1.0) > f.eval(-1.0)
    mirrored = {ph.HenyeyGreenstein: lambda: ph.HenyeyGreenstein(-f.g), ph.Schlick: lambda: ph.Schlick(-f.k)}
    if type(f) in mirrored:
        b = mirrored[type(f)]()
        assert b.sample_cos(rng.random(N_SAMPLES)).mean() < -0.3 and b.eval(-1.0) > b.eval(1.0)


def test_schlick_blasi_mapping_accuracy():
    g = np.linspace(-0.9, 0.9, 18001)
    err = np.abs(ph.schlick_mean_cosine(1.55 * g - 0.55 * g**3) - g)
    # Blasi's polynomial fits the HG shape, not its first moment: ~0.075 at |g| = 0.85
    assert 0.074 < err.max() < 0.076
    assert abs(g[np.argmax(err)]) == pytest.approx(0.849, abs=0.002)
    assert ph.Schlick.from_g(0.5).k == pytest.approx(1.55 * 0.5 - 0.55 * 0.125)
    assert ph.Schlick.from_g(-0.5).k == -ph.Schlick.from_g(0.5).k  # odd in g
    for gg in (-0.999, -0.95, -0.5, -1e-4, 0.0, 0.3, 0.95, 0.999):
        assert ph.Schlick.from_g(gg, method="exact").mean_cosine == pytest.approx(gg, abs=1e-12)
    with pytest.raises(ValueError, match="method='exact'"):
        ph.Schlick.from_g(0.95)
    ph.Schlick.from_g(0.938)  # just inside


def test_schlick_mean_cosine_small_k_branch_continuous():
    k = np.array([1e-3, 0.00999999, 0.01, 0.0100001, -0.01, 0.3])
    for kk, m in zip(k, ph.schlick_mean_cosine(k)):
        assert m == pytest.approx(_mean_quad(ph.Schlick(kk)), rel=1e-9)


def test_mixture_weights_and_one_uniform():
    m = ph.Mixture([(3, ph.Isotropic()), (0, ph.Rayleigh()), (1, ph.HenyeyGreenstein(0.5))])
    np.testing.assert_allclose(m.weights, [0.75, 0.25])
    assert len(m.components) == 2
    c = np.linspace(-1, 1, 11)
    np.testing.assert_allclose(m.eval(c), 0.75 / (4 * np.pi) + 0.25 * ph.HenyeyGreenstein(0.5).eval(c))
    u = np.array([0.0, 0.3, 0.74999, 0.75, 0.9, np.nextafter(1, 0)])
    np.testing.assert_allclose(m.sample_cos(u[:3]), 2 * (u[:3] / 0.75) - 1)
    np.testing.assert_allclose(
        m.sample_cos(u[3:]), ph.HenyeyGreenstein(0.5).sample_cos((u[3:] - 0.75) / 0.25), atol=1e-12
    )
    assert np.shape(m.sample_cos(0.5)) == ()
    assert m.mean_cosine == pytest.approx(0.125)


def test_mixture_weights_near_the_float_limit_normalise_like_small_ones():
    # 1e308 + 1e308 overflows: the weights are scaled by the largest before summing.
    big = ph.Mixture([(1e308, ph.Isotropic()), (1e308, ph.HenyeyGreenstein(0.5))])
    small = ph.Mixture([(1, ph.Isotropic()), (1, ph.HenyeyGreenstein(0.5))])
    np.testing.assert_array_equal(big.weights, [0.5, 0.5])
    c = np.linspace(-1, 1, 7)
    np.testing.assert_array_equal(big.eval(c), small.eval(c))
    assert big.mean_cosine == small.mean_cosine == pytest.approx(0.25)


def _schema_type_literals():
    union, *_ = typing.get_args(sm.PhaseSpec)
    return {typing.get_args(cls.model_fields["type"].annotation)[0] for cls in typing.get_args(union)}


def test_registry_matches_schema_types():
    assert set(ph.phase_functions) == _schema_type_literals()
    assert all(issubclass(v, ph.PhaseFunction) for v in ph.phase_functions.values())


def test_phase_from_spec():
    assert isinstance(ph.phase_from_spec(sm.IsotropicPhaseSpec()), ph.Isotropic)
    assert isinstance(ph.phase_from_spec(sm.RayleighPhaseSpec()), ph.Rayleigh)
    assert ph.phase_from_spec(sm.HenyeyGreensteinPhaseSpec(g=0.7)).g == 0.7
    assert ph.phase_from_spec(sm.SchlickPhaseSpec(k=-0.4)).k == -0.4
    # a spec's g maps to the k with mean cosine exactly g (not Blasi's 1.55 g - 0.55 g^3 = 0.70625)
    schlick = ph.phase_from_spec(sm.SchlickPhaseSpec(g=0.5))
    assert schlick.mean_cosine == pytest.approx(0.5, abs=1e-10) and schlick.k != pytest.approx(0.70625)
    assert ph.phase_from_spec(sm.SchlickPhaseSpec(g=0.95)).mean_cosine == pytest.approx(0.95, abs=1e-10)
    mix = ph.phase_from_spec(
        {
            "type": "mixture",
            "components": [
                {"weight": 2, "phase": {"type": "hg", "g": 0.8}},
                {"weight": 1, "phase": {"type": "rayleigh"}},
            ],
        }
    )
    assert isinstance(mix, ph.Mixture) and mix.mean_cosine == pytest.approx(2 / 3 * 0.8)
    assert isinstance(ph.phase_from_spec(sm.HomogeneousMediumSpec(sigma_a=0, sigma_s=1).phase), ph.Isotropic)
    with pytest.raises(ValueError, match="unknown phase"):
        ph.phase_from_spec(object())


@pytest.mark.parametrize(
    "make, exc, match",
    [
        (lambda: ph.HenyeyGreenstein(1.0), ValueError, "g must lie"),
        (lambda: ph.HenyeyGreenstein(-1.0), ValueError, "g must lie"),
        (lambda: ph.HenyeyGreenstein(float("nan")), ValueError, "g must lie"),
        (lambda: ph.Schlick(1.0), ValueError, "k must lie"),
        (lambda: ph.Schlick(-1.5), ValueError, "k must lie"),
        (lambda: ph.Schlick.from_g(1.0), ValueError, "g must lie"),
        (lambda: ph.Schlick.from_g(-0.95), ValueError, "Blasi"),
        (lambda: ph.Schlick.from_g(0.5, method="fit"), ValueError, "unknown Schlick mapping"),
        (lambda: ph.Mixture([]), ValueError, "at least one"),
        (lambda: ph.Mixture([(-0.1, ph.Isotropic()), (1, ph.Rayleigh())]), ValueError, ">= 0"),
        (lambda: ph.Mixture([(0, ph.Isotropic()), (0.0, ph.Rayleigh())]), ValueError, "all zero"),
        (lambda: ph.Mixture([(float("inf"), ph.Isotropic())]), ValueError, "finite"),
        (lambda: ph.Mixture([(1, "hg")]), TypeError, "not a PhaseFunction"),
        (lambda: ph.Isotropic().sample(np.zeros((4, 3)), 0.5, 0.5), ValueError, "shape"),
    ],
)
def test_construction_errors(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


# ----------------------------------------------------------------------------------------
# The in-place forms of HG (issue 13): eval, the sine from the two sides, the azimuth from tan(psi).
@pytest.mark.parametrize("g", [0.5, -0.7, 0.95, 0.999999])
def test_hg_eval_matches_the_textbook_formula(g):
    """p = (1 - g^2) / (4 pi (1 + g^2 - 2 g c)^(3/2)) (Henyey & Greenstein 1941), in extended precision; a
    cosine rounded past +-1 gives p(+-1)."""
    c = np.concatenate([seeded_rng().uniform(-1, 1, 2000), [-1.0, 0.0, 1.0, np.nextafter(1, 0)]])
    L = np.longdouble
    gl, cl = L(g), c.astype(L)
    ref = (1 - gl * gl) / (4 * np.pi * (1 + gl * gl - 2 * gl * cl) ** L(1.5))
    rel = np.abs(ph.HenyeyGreenstein(g).eval(c) / ref - 1).astype(float)
    assert rel.max() < (1e-13 if abs(g) < 0.99 else 1e-8)  # (1 + g^2 - 2 g c rounds in the reference near the peak)
    f = ph.HenyeyGreenstein(g)
    for edge in (1.0, -1.0):  # within what one rounding of the cosine changes anyway
        p_past, p_edge, p_in = f.eval(np.array([np.nextafter(edge, 2 * edge), edge, np.nextafter(edge, 0)]))
        assert np.isfinite(p_past) and abs(p_past / p_edge - 1) <= 2 * abs(p_in / p_edge - 1) + 1e-13
    assert f.eval(0.3) == pytest.approx(f.eval(np.array([0.3]))[0], rel=0)  # scalars


@pytest.mark.parametrize("g", [0.0, 0.5, -0.7, 0.999])
def test_hg_sine_from_the_two_sides(g):
    """The sine `sample` uses, sqrt((1 - cos)(1 + cos)) from the two sides of sample_cos, agrees with the sine of
    the sampled cosine (extended precision) and with cos^2 + sin^2 = 1."""
    u = np.concatenate([seeded_rng().random(5000), [0.0, 0.5, np.nextafter(1, 0)]])
    f = ph.HenyeyGreenstein(g)
    c, s = f._sample_cos_sin(u)
    np.testing.assert_array_equal(c, f.sample_cos(u))
    cl = c.astype(np.longdouble)
    ref = np.sqrt((1 - cl) * (1 + cl))
    np.testing.assert_allclose(s, ref.astype(float), rtol=1e-7, atol=3e-8)  # (c is rounded: ~1e-16 / sin)
    far = np.abs(c) < 0.99
    np.testing.assert_allclose(s[far], ref[far].astype(float), rtol=1e-14)
    np.testing.assert_allclose(c * c + s * s, 1.0, atol=4e-16)


def test_sample_azimuth_quadrants():
    """phi = 2 pi u2 from tan(pi u2 - pi / 2): about d = z (frame s = x, t = y), u2 = 0, 1/4, 1/2, 3/4 give
    the directions +x, +y, -x, -y of the tangent plane, exactly to rounding."""
    f = ph.HenyeyGreenstein(0.3)
    u1 = np.full(4, 0.4)
    c = f.sample_cos(u1)
    sin_t = np.sqrt(1 - c * c)
    out = f.sample(np.tile([[0.0], [0.0], [1.0]], 4), u1, np.array([0.0, 0.25, 0.5, 0.75]))
    want = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], float).T * sin_t
    np.testing.assert_allclose(out[:2], want, atol=1e-15)
    np.testing.assert_allclose(out[2], c, atol=1e-15)
