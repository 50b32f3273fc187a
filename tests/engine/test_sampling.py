"""Tests for engine.core.sampling: frames, exact samplers, pdfs and goodness of fit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, stats
from scipy.stats import chisquare

from conftest import SEED, seeded_rng  # noqa: F401
from owcsim.engine.core import sampling as smp

N_SAMPLES = 100_000
ALPHA = 0.01
M_VALUES = (0, 1, 5, 1000)
CONE_DEGREES = (0.01, 1.0, 30.0, 85.0, 90.0)


def _uniforms(n=N_SAMPLES):
    rng = seeded_rng()
    return rng.random(n), rng.random(n)


def _cos_max(deg):
    return np.cos(np.radians(deg))


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# --------------------------------------------------------------------------
# Orthonormal basis / to_world
# --------------------------------------------------------------------------


def _special_normals():
    tiny = [1e-8, 1e-12, 1e-20, 1e-300]
    rows = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (1, 0, -0.0), (0, 1, -0.0)]
    for e in tiny:
        for sz in (1.0, -1.0):
            rows += [(e, e, sz), (-e, e, sz), (e, -3 * e, sz), (e, 0, sz)]
    return _unit(np.array(rows, dtype=np.float64))


def _random_normals(n=20_000):
    return _unit(seeded_rng().standard_normal((n, 3)))


@pytest.mark.parametrize("normals", [_special_normals(), _random_normals()], ids=["special", "random"])
def test_basis_orthonormal_and_right_handed(normals):
    s, t = smp.orthonormal_basis(normals)
    assert s.shape == t.shape == normals.shape
    assert s.dtype == t.dtype == np.float64
    assert np.all(np.isfinite(s)) and np.all(np.isfinite(t))
    atol = 1e-13
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0, atol=atol, rtol=0)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=atol, rtol=0)
    for a, b in ((s, t), (s, normals), (t, normals)):
        np.testing.assert_allclose(np.einsum("ij,ij->i", a, b), 0.0, atol=atol, rtol=0)
    # right-handed: s x t = n, det[s, t, n] = +1
    np.testing.assert_allclose(np.cross(s, t), normals, atol=atol, rtol=0)
    det = np.linalg.det(np.stack((s, t, normals), axis=1))
    np.testing.assert_allclose(det, 1.0, atol=atol, rtol=0)


def test_basis_single_normal_shape():
    s, t = smp.orthonormal_basis(np.array([0.0, 0.0, 1.0]))
    assert s.shape == t.shape == (3,)
    np.testing.assert_allclose(np.cross(s, t), [0, 0, 1], atol=1e-15)


def test_to_world_maps_z_to_normal_and_preserves_angles():
    normals = np.concatenate([_special_normals(), _random_normals(1000)])
    n = len(normals)
    ez = np.tile([0.0, 0.0, 1.0], (n, 1))
    np.testing.assert_allclose(smp.to_world(ez, normals), normals, atol=1e-15, rtol=0)
    s, t = smp.orthonormal_basis(normals)
    np.testing.assert_allclose(smp.to_world(np.tile([1.0, 0, 0], (n, 1)), normals), s, atol=1e-15)
    np.testing.assert_allclose(smp.to_world(np.tile([0, 1.0, 0], (n, 1)), normals), t, atol=1e-15)

    rng = seeded_rng()
    a = _unit(rng.standard_normal((n, 3)))
    b = _unit(rng.standard_normal((n, 3)))
    wa, wb = smp.to_world(a, normals), smp.to_world(b, normals)
    np.testing.assert_allclose(np.einsum("ij,ij->i", wa, wb), np.einsum("ij,ij->i", a, b), atol=1e-13, rtol=0)
    np.testing.assert_allclose(np.linalg.norm(wa, axis=1), 1.0, atol=1e-13, rtol=0)
    # local z-component = cosine to the normal
    np.testing.assert_allclose(np.einsum("ij,ij->i", wa, normals), a[:, 2], atol=1e-13, rtol=0)
    # orientation preserved: (a x b) -> (wa x wb)
    np.testing.assert_allclose(smp.to_world(np.cross(a, b), normals), np.cross(wa, wb), atol=1e-13, rtol=0)


def test_to_world_broadcasts_single_normal():
    normal = _unit(np.array([0.3, -0.5, -0.8]))
    local = smp.sample_cosine_hemisphere(*_uniforms(500))
    world = smp.to_world(local, normal)
    assert world.shape == (500, 3)
    np.testing.assert_allclose(
        world, smp.to_world(local, np.tile(normal, (500, 1))), atol=1e-15, rtol=0
    )  # one matrix product vs per-row sums: rounding only
    np.testing.assert_allclose(world @ normal, local[:, 2], atol=1e-14, rtol=0)


# --------------------------------------------------------------------------
# Known points, unit length, support, numerical robustness
# --------------------------------------------------------------------------

EXTREME_U = np.array([0.0, 5e-324, 1e-300, 1e-16, 1e-8, 0.25, 0.5, 1 - 1e-8, 1 - 1e-16, np.nextafter(1.0, 0.0), 1.0])


def _all_samplers():
    for m in M_VALUES:
        yield f"lambert m={m}", lambda u1, u2, m=m: smp.sample_generalized_lambertian(m, u1, u2)
    for deg in CONE_DEGREES:
        yield f"cone {deg} deg", lambda u1, u2, d=deg: smp.sample_cosine_cone(_cos_max(d), u1, u2)
    yield "cosine hemisphere", smp.sample_cosine_hemisphere
    yield "uniform sphere", smp.sample_uniform_sphere


@pytest.mark.parametrize("name,sampler", list(_all_samplers()), ids=lambda x: x if isinstance(x, str) else "")
def test_unit_length_finite_float64(name, sampler):
    u1, u2 = _uniforms()
    u1 = np.concatenate([u1, EXTREME_U, EXTREME_U])
    u2 = np.concatenate([u2, EXTREME_U, EXTREME_U[::-1]])
    with np.errstate(divide="raise", invalid="raise", over="raise"):  # underflow is benign
        d = sampler(u1, u2)
    assert d.shape == (len(u1), 3) and d.dtype == np.float64
    assert np.all(np.isfinite(d)), name
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=4e-16, rtol=0)


def test_lambertian_known_points():
    for m in (0, 1, 5, 1000, 1e6):
        pole = smp.sample_generalized_lambertian(m, np.array([1.0]), np.array([0.3]))
        np.testing.assert_array_equal(pole, [[0.0, 0.0, 1.0]])
        horizon = smp.sample_generalized_lambertian(m, np.array([0.0]), np.array([0.25]))
        np.testing.assert_allclose(horizon, [[0.0, 1.0, 0.0]], atol=1e-15)
    # m = 0: cos theta = u1 ; m = 1: cos theta = sqrt(u1)
    u = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(smp.sample_generalized_lambertian(0, u, u)[:, 2], u, rtol=1e-15)
    np.testing.assert_allclose(smp.sample_generalized_lambertian(1, u, u)[:, 2], np.sqrt(u), rtol=1e-15)
    # u1 = 1 - 1e-16 with m = 1000: essentially the pole, with a tiny but exact sin theta
    u_hi = np.array([1 - 1e-16])  # rounds to 1 - 2**-53
    d = smp.sample_generalized_lambertian(1000, u_hi, np.array([0.0]))
    sin_expected = np.sqrt(-2 * np.log(u_hi[0]) / 1001)
    np.testing.assert_allclose(d[0, 0], sin_expected, rtol=1e-6)
    assert d[0, 2] == 1.0


def test_cone_known_points_and_support():
    for deg in CONE_DEGREES:
        cm = _cos_max(deg)
        np.testing.assert_array_equal(smp.sample_cosine_cone(cm, np.array([0.0]), np.array([0.7])), [[0.0, 0.0, 1.0]])
        rim = smp.sample_cosine_cone(cm, np.array([1.0]), np.array([0.0]))
        np.testing.assert_allclose(rim[0, 2], cm, rtol=1e-15, atol=1e-16)
        # relative accuracy limited by the rounding of cos_max itself: ~eps / sin^2(theta_max)
        rtol = max(1e-12, 2.5e-16 / np.sin(np.radians(deg)) ** 2)
        np.testing.assert_allclose(rim[0, 0], np.sin(np.radians(deg)), rtol=rtol)
        d = smp.sample_cosine_cone(cm, *_uniforms(10_000))
        sin2 = d[:, 0] ** 2 + d[:, 1] ** 2
        assert np.all(sin2 <= np.sin(np.radians(deg)) ** 2 * (1 + 1e-12))
        assert np.all(d[:, 2] > 0)


def test_cosine_hemisphere_is_cone_with_cos_max_zero():
    u1, u2 = _uniforms(1000)
    np.testing.assert_array_equal(smp.sample_cosine_hemisphere(u1, u2), smp.sample_cosine_cone(0.0, u1, u2))
    c = np.linspace(-1, 1, 101)
    np.testing.assert_allclose(smp.cosine_cone_pdf(0.0, c), smp.generalized_lambertian_pdf(1, c), rtol=1e-15)


def test_uniform_sphere_known_points():
    d = smp.sample_uniform_sphere(np.array([0.0, 0.5, 1.0]), np.array([0.0, 0.25, 0.0]))
    np.testing.assert_allclose(d, [[0, 0, 1], [0, 1, 0], [0, 0, -1]], atol=1e-15)
    assert smp.uniform_sphere_pdf() == pytest.approx(1 / (4 * np.pi), rel=1e-15)


def test_pdfs_zero_outside_support_and_no_warnings():
    c = np.array([-1.0, -0.5, -1e-300, 0.0])
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        for m in (0, 1, 5, 1000, 2.5):
            np.testing.assert_array_equal(smp.generalized_lambertian_pdf(m, c), 0.0)
        for deg in CONE_DEGREES:
            cm = _cos_max(deg)
            np.testing.assert_array_equal(smp.cosine_cone_pdf(cm, c), 0.0)
            below = np.nextafter(cm, -1.0) if deg > 1 else np.cos(np.radians(deg * 1.001))
            assert smp.cosine_cone_pdf(cm, below) == 0.0
            assert smp.cosine_cone_pdf(cm, 1.0) > 0.0
    assert smp.generalized_lambertian_pdf(0, 1.0) == pytest.approx(1 / (2 * np.pi))
    assert smp.generalized_lambertian_pdf(1000, 1.0) == pytest.approx(1001 / (2 * np.pi))


# --------------------------------------------------------------------------
# Normalization (quadrature over theta)
# --------------------------------------------------------------------------


def _theta_integral(pdf_of_cos, lo, hi, points=None):
    val, _ = integrate.quad(
        lambda th: pdf_of_cos(np.cos(th)) * 2 * np.pi * np.sin(th),
        lo,
        hi,
        points=points,
        limit=500,
        epsabs=1e-13,
        epsrel=1e-11,
    )
    return val


@pytest.mark.parametrize("m", M_VALUES + (2.5,))
def test_lambertian_pdf_integrates_to_one(m):
    width = 1.0 / np.sqrt(m + 1.0)  # angular width of the cos^m lobe
    pts = [p for p in (width, 3 * width, 10 * width) if p < np.pi / 2]
    total = _theta_integral(lambda c: smp.generalized_lambertian_pdf(m, c), 0, np.pi, pts + [np.pi / 2])
    assert total == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize("deg", CONE_DEGREES)
def test_cone_pdf_integrates_to_one(deg):
    cm, th = _cos_max(deg), np.radians(deg)
    pdf = lambda c: smp.cosine_cone_pdf(cm, c)  # noqa: E731
    inside = _theta_integral(pdf, 0.0, th)
    outside = _theta_integral(pdf, th * (1 + 1e-9), np.pi, [np.pi / 2] if deg < 90 else None)
    assert inside == pytest.approx(1.0, abs=1e-8)
    assert outside == 0.0


def test_uniform_sphere_pdf_integrates_to_one():
    assert _theta_integral(lambda c: np.full_like(c, smp.uniform_sphere_pdf()), 0, np.pi) == pytest.approx(
        1.0, abs=1e-12
    )


# --------------------------------------------------------------------------
# Moments
# --------------------------------------------------------------------------


def _assert_mean(x, expected, var, k=5.0):
    se = np.sqrt(var / len(x))
    assert abs(x.mean() - expected) < k * se, (x.mean(), expected, se)


@pytest.mark.parametrize("m", M_VALUES)
def test_lambertian_moments(m):
    c = smp.sample_generalized_lambertian(m, *_uniforms())[:, 2]
    e1, e2 = (m + 1) / (m + 2), (m + 1) / (m + 3)  # E[cos], E[cos^2]
    e4 = (m + 1) / (m + 5)
    _assert_mean(c, e1, e2 - e1**2)
    _assert_mean(c**2, e2, e4 - e2**2)


@pytest.mark.parametrize("deg", CONE_DEGREES)
def test_cone_moments(deg):
    d = smp.sample_cosine_cone(_cos_max(deg), *_uniforms())
    s2max = np.sin(np.radians(deg)) ** 2
    # sin^2 theta ~ U(0, sin^2 theta_max); E[cos] = 2 (1 - cm^3) / (3 sin^2 theta_max)
    _assert_mean((d[:, 0] ** 2 + d[:, 1] ** 2) / s2max, 0.5, 1 / 12)
    if deg >= 30:
        cm = _cos_max(deg)
        e1 = 2 * (1 - cm**3) / (3 * s2max)
        e2 = (1 - cm**4) / (2 * s2max)
        _assert_mean(d[:, 2], e1, e2 - e1**2)


def test_uniform_sphere_moments():
    d = smp.sample_uniform_sphere(*_uniforms())
    for k in range(3):
        _assert_mean(d[:, k], 0.0, 1 / 3)
        _assert_mean(d[:, k] ** 2, 1 / 3, 1 / 5 - 1 / 9)


# --------------------------------------------------------------------------
# Chi-square goodness of fit against the exact pdfs
# --------------------------------------------------------------------------


def _lambert_case(m):
    return dict(
        sample=lambda u1, u2: smp.sample_generalized_lambertian(m, u1, u2),
        pdf=lambda c: smp.generalized_lambertian_pdf(m, c),
        quantile=lambda q: q ** (1.0 / (m + 1)),
        lo=0.0,
    )


def _cone_case(deg):
    cm = _cos_max(deg)
    s2 = (1 - cm) * (1 + cm)
    return dict(
        sample=lambda u1, u2: smp.sample_cosine_cone(cm, u1, u2),
        pdf=lambda c: smp.cosine_cone_pdf(cm, c),
        quantile=lambda q: np.sqrt(1 - (1 - q) * s2),
        lo=cm,
    )


def _sphere_case():
    return dict(
        sample=smp.sample_uniform_sphere,
        pdf=lambda c: np.full_like(np.asarray(c, float), smp.uniform_sphere_pdf()),
        quantile=lambda q: 2 * q - 1,
        lo=-1.0,
    )


DISTRIBUTIONS = (
    {f"lambert_m{m}": _lambert_case(m) for m in M_VALUES}
    | {f"cone_{deg}deg": _cone_case(deg) for deg in CONE_DEGREES}
    | {"uniform_sphere": _sphere_case()}
)
CHI2_CASES = [(name, var) for name in DISTRIBUTIONS for var in ("cos", "phi")]
ALPHA_CASE = 1 - (1 - ALPHA) ** (1 / len(CHI2_CASES))  # Sidak correction
N_BINS = 20


def _chi2_pvalue(counts, probs):
    expected = counts.sum() * probs
    assert np.all(expected >= 5)
    stat = np.sum((counts - expected) ** 2 / expected)
    return stats.chi2.sf(stat, len(counts) - 1)


def _cos_bins_probs(case, k=N_BINS):
    """Inner edges at (approximate) equiprobable cos quantiles; exact bin
    probabilities from quadrature of the pdf: P = int 2 pi pdf(c) dc."""
    edges = np.concatenate([[case["lo"]], case["quantile"](np.arange(1, k) / k), [1.0]])
    probs = np.array(
        [
            integrate.quad(lambda c: 2 * np.pi * case["pdf"](c), a, b, epsabs=0, epsrel=1e-10, limit=200)[0]
            for a, b in zip(edges[:-1], edges[1:])
        ]
    )
    return edges[1:-1], probs


def _cos_pvalue(case, d):
    inner, probs = _cos_bins_probs(case)
    counts = np.bincount(np.searchsorted(inner, d[:, 2]), minlength=len(probs))
    return _chi2_pvalue(counts, probs)


@pytest.mark.parametrize("name,var", CHI2_CASES)
def test_chi_square_goodness_of_fit(name, var):
    case = DISTRIBUTIONS[name]
    d = case["sample"](*_uniforms())
    if var == "cos":
        p = _cos_pvalue(case, d)
    else:
        phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
        counts = np.bincount(np.minimum((phi / (2 * np.pi) * 16).astype(int), 15), minlength=16)
        p = _chi2_pvalue(counts, np.full(16, 1 / 16))
    assert p > ALPHA_CASE, f"{name}/{var}: p = {p:.3g} <= {ALPHA_CASE:.3g}"


@pytest.mark.parametrize(
    "sampled,claimed",
    [
        (_lambert_case(6), _lambert_case(5)),
        (_lambert_case(1000), _lambert_case(950)),
        (_cone_case(29.0), _cone_case(30.0)),
        (_lambert_case(1), _cone_case(85.0)),
    ],
)
def test_chi_square_has_power(sampled, claimed):
    """The goodness-of-fit check rejects slightly wrong distributions."""
    d = sampled["sample"](*_uniforms())
    assert _cos_pvalue(claimed, d) < ALPHA_CASE


def test_cosine_about_normal_matches_cosine_law():
    """World-space cosine sampling (normal + uniform sphere point): chi-square of cos, azimuth, moments."""
    rng = np.random.default_rng(12345)
    n = 100_000
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    u = rng.random((n, 2))
    d = smp.sample_cosine_about(normals, u[:, 0], u[:, 1])
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-14)
    c = np.einsum("ij,ij->i", d, normals)
    assert c.min() > 0
    # cos^2 is uniform on [0, 1] under the cosine law: chi-square on 20 equal bins
    counts, _ = np.histogram(c**2, bins=20, range=(0, 1))
    assert chisquare(counts).pvalue > 0.001
    # azimuth about the normal is uniform
    s, t = smp.orthonormal_basis(normals)
    phi = np.arctan2(np.einsum("ij,ij->i", d, t), np.einsum("ij,ij->i", d, s))
    counts, _ = np.histogram(phi, bins=16, range=(-np.pi, np.pi))
    assert chisquare(counts).pvalue > 0.001
    # power: uniform-hemisphere directions would fail the same test
    uh = smp.sample_uniform_sphere(u[:, 0], u[:, 1])
    counts, _ = np.histogram(np.abs(uh[:, 2]) ** 2, bins=20, range=(0, 1))
    assert chisquare(counts).pvalue < 1e-6


def test_polar_about_soa_by_hand():
    """Directions about one normal on component rows: about +z they are (sin t cos phi, sin t sin phi, cos t)
    with phi = 2 pi u2 (written out here); about any normal, unit vectors at angle t from it whose azimuths
    in the normal's frame are 2 pi u2."""
    from owcsim.engine.core.sampling import orthonormal_basis, polar_about_soa

    rng = np.random.default_rng(3)
    u1, u2 = rng.random((2, 2000))
    cos_t = 1.0 - u1
    sin_t = np.sqrt(1.0 - cos_t**2)
    phi = 2.0 * np.pi * u2
    d = polar_about_soa(cos_t, sin_t, u2, np.array([0.0, 0.0, 1.0]))
    expected = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t])
    s, t = orthonormal_basis(np.array([0.0, 0.0, 1.0]))
    expected = expected[0] * s[:, None] + expected[1] * t[:, None] + expected[2] * np.array([0, 0, 1.0])[:, None]
    assert np.abs(d - expected).max() < 1e-9
    for n in ([0.0, 0.0, -1.0], [0.6, 0.0, 0.8], [0.0, 1.0, 0.0]):
        n = np.asarray(n)
        d = polar_about_soa(cos_t, sin_t, u2, n)
        s, t = orthonormal_basis(n)
        assert np.abs(np.linalg.norm(d, axis=0) - 1.0).max() < 1e-12
        assert np.abs(n @ d - cos_t).max() < 1e-12
        az = np.mod(np.arctan2(t @ d, s @ d), 2 * np.pi)
        ok = sin_t > 1e-3  # the azimuth is defined off the pole
        err = np.abs(np.angle(np.exp(1j * (az[ok] - phi[ok]))))
        assert err.max() < 1e-8


def test_azimuth_matches_cos_and_sin():
    """sampling.azimuth (one float64 tangent) against numpy's cosine and sine of 2 pi u, extremes included."""
    u = np.concatenate([np.random.default_rng(8).random(200_000), EXTREME_U[:-1], [0.125, 0.375, 0.625, 0.875]])
    c, s = smp.azimuth(u)
    assert np.all(np.isfinite(c)) and np.all(np.isfinite(s))
    np.testing.assert_allclose(c, np.cos(2 * np.pi * u), rtol=0, atol=1e-15)
    np.testing.assert_allclose(s, np.sin(2 * np.pi * u), rtol=0, atol=2e-8)  # sqrt(1 - c^2) near sin = 0
    np.testing.assert_allclose(c * c + s * s, 1.0, rtol=0, atol=4e-16)
    far = np.abs(np.sin(2 * np.pi * u)) > 1e-3  # away from the poles the sine is as exact as the cosine
    np.testing.assert_allclose(s[far], np.sin(2 * np.pi * u[far]), rtol=0, atol=2e-13)
    np.testing.assert_array_equal(np.sign(s[far]), np.sign(np.sin(2 * np.pi * u[far])))
    np.testing.assert_allclose(smp.azimuth(np.array([0.0, 0.25, 0.5, 0.75]))[0], [1, 0, -1, 0], atol=1e-15)


def test_scalar_uniforms_give_scalar_shaped_directions():
    """The samplers and the azimuth take scalar uniforms as before (shape () in, (3,) or () out)."""
    c, s = smp.azimuth(0.3)
    assert np.shape(c) == () and np.isclose(c, np.cos(0.6 * np.pi)) and np.isclose(s, np.sin(0.6 * np.pi))
    for d in (
        smp.sample_generalized_lambertian(1.0, 0.3, 0.2),
        smp.sample_uniform_sphere(0.3, 0.2),
        smp.sample_cosine_cone(0.5, 0.3, 0.2),
    ):
        assert d.shape == (3,) and np.isclose(np.linalg.norm(d), 1.0)
