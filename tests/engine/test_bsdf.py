"""Surface materials (engine/surfaces/bsdf.py): Lambertian, modified Phong, mirror.

References: closed forms (Lambertian, mirror), hemisphere quadrature written here for the
albedo and moments of the BRDF, swapped arguments for reciprocity, and chi-square tests of
sampled directions against the pdf integrated by quadrature.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from owcsim.engine.surfaces.bsdf import Materials, mirror_direction
from owcsim.engine.surfaces.lobes import Phong

N = np.array([0.0, 0.0, 1.0])


def _mat(rho_d=0.0, rho_s=0.0, n=0.0, rho_m=0.0, size=1):
    f = lambda x: np.full(size, float(x))  # noqa: E731
    return Materials.mix(lambertian=f(rho_d), phong=Phong(f(rho_s), f(n)), mirror=f(rho_m))


def _incoming(theta_deg, size):
    t = math.radians(theta_deg)
    d = np.array([math.sin(t), 0.0, -math.cos(t)])  # arriving, pointing into the surface
    return np.repeat(d[:, None], size, axis=1), np.repeat(N[:, None], size, axis=1)


def _hemisphere_grid(n_theta=800, n_phi=800):
    """Midpoint grid on the upper hemisphere: directions (3, M) and solid angles (M,)."""
    th = (np.arange(n_theta) + 0.5) * (np.pi / 2) / n_theta
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    T, P = np.meshgrid(th, ph, indexing="ij")
    w = np.stack((np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T))).reshape(3, -1)
    dw = (np.sin(T) * (np.pi / 2 / n_theta) * (2 * np.pi / n_phi)).ravel()
    return w, dw


def phong_reference(rho_d, rho_s, n, d_in, w_o):
    """The model written out independently: rho_d/pi + rho_s (n+1)/(2pi) cos^n a / max(cos_i, cos_o)."""
    cos_i, cos_o = -d_in[2], w_o[2]
    r = np.array([d_in[0], d_in[1], -d_in[2]])  # mirror about z
    cos_a = np.clip(np.einsum("i...,i...->...", r, w_o), 0, None)
    return np.where(cos_o > 0, rho_d / np.pi + rho_s * (n + 1) / (2 * np.pi) * cos_a**n / np.maximum(cos_i, cos_o), 0)


def test_lambertian_eval_sample_and_pdf():
    m = _mat(rho_d=0.7, size=5000)
    d_in, nrm = _incoming(30, 5000)
    rng = np.random.default_rng(1)
    w, weight = m.sample(d_in, nrm, rng.random(5000), rng.random(5000))
    assert np.all(weight == 0.7)
    np.testing.assert_allclose(m.eval(d_in, nrm, w), 0.7 / np.pi)
    np.testing.assert_allclose(m.pdf(d_in, nrm, w), w[2] / np.pi)


def test_eval_matches_the_written_out_model():
    rng = np.random.default_rng(2)
    m = _mat(rho_d=0.2, rho_s=0.5, n=17.0, size=2000)
    d_in, nrm = _incoming(40, 2000)
    w = rng.normal(size=(3, 2000))
    w /= np.linalg.norm(w, axis=0)
    np.testing.assert_allclose(m.eval(d_in, nrm, w), phong_reference(0.2, 0.5, 17.0, d_in, w), rtol=1e-12)


@pytest.mark.parametrize("n", [0.0, 5.0, 80.0])
def test_phong_reciprocity(n):
    """f(w_i, w_o) = f(w_o, w_i): swap the roles of incoming and outgoing directions."""
    rng = np.random.default_rng(3)
    size = 5000
    m = _mat(rho_d=0.1, rho_s=0.8, n=n, size=size)
    a, b = rng.normal(size=(2, 3, size))
    a[2], b[2] = np.abs(a[2]), np.abs(b[2])  # both above the surface
    a /= np.linalg.norm(a, axis=0)
    b /= np.linalg.norm(b, axis=0)
    nrm = np.repeat(N[:, None], size, axis=1)
    f_ab = m.eval(-a, nrm, b)  # light from a, leaving toward b
    f_ba = m.eval(-b, nrm, a)
    np.testing.assert_allclose(f_ab, f_ba, rtol=1e-12)
    assert np.ptp(f_ab) > 0.1 * f_ab.max()  # the pairs are not trivially equal


@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0, 85.0])
@pytest.mark.parametrize("n", [1.0, 10.0, 100.0])
def test_white_furnace_energy_and_sampled_weights(theta, n):
    """rho = 1: the albedo int f cos dw <= 1 (quadrature) and the mean sampled weight equals it."""
    size = 200_000
    m = _mat(rho_d=0.3, rho_s=0.7, n=n, size=size)
    d_in, nrm = _incoming(theta, size)
    w, dw = _hemisphere_grid()
    albedo = float((phong_reference(0.3, 0.7, n, d_in[:, :1], w) * w[2] * dw).sum())
    assert albedo <= 1.0 + 1e-3
    rng = np.random.default_rng(4)
    _, weight = m.sample(d_in, nrm, rng.random(size), rng.random(size))
    assert weight.max() <= 1.0 + 1e-12  # energy never created, sample by sample
    se = weight.std() / math.sqrt(size)
    assert abs(weight.mean() - albedo) < 4 * se + 2e-3 * albedo, (weight.mean(), albedo, se)


def test_sampling_reproduces_a_moment_of_the_brdf_and_has_power():
    """E[weight h(w)] = int f cos h dw for h = max(r.w, 0)^30 (quadrature); a 5 % wrong exponent fails."""
    size, n = 400_000, 25.0
    d_in, nrm = _incoming(35, size)
    r = mirror_direction(d_in[:, :1], nrm[:, :1])
    h = lambda v: np.clip(np.einsum("ij,ij->j", np.broadcast_to(r, v.shape), v), 0, None) ** 30  # noqa: E731
    w, dw = _hemisphere_grid()
    ref = float((phong_reference(0.25, 0.6, n, d_in[:, :1], w) * w[2] * h(w) * dw).sum())
    rng = np.random.default_rng(5)
    u1, u2 = rng.random(size), rng.random(size)
    wo, weight = _mat(0.25, 0.6, n, size=size).sample(d_in, nrm, u1, u2)
    x = weight * h(wo)
    se = x.std() / math.sqrt(size)
    assert abs(x.mean() - ref) < 4 * se + 1e-3 * ref
    wrong = _mat(0.25, 0.6, n * 1.05, size=size).sample(d_in, nrm, u1, u2)
    xw = wrong[1] * h(wrong[0])
    assert abs(xw.mean() - ref) > 4 * se + 1e-3 * ref


def test_glossy_directions_chi_square_against_pdf():
    """Bins in the angle alpha to the mirror direction: counts against int pdf over each bin."""
    size, n = 300_000, 12.0
    m = _mat(rho_s=1.0, n=n, size=size)
    d_in, nrm = _incoming(20, size)
    rng = np.random.default_rng(6)
    wo, _ = m.sample(d_in, nrm, rng.random(size), rng.random(size))
    r = mirror_direction(d_in[:, :1], nrm[:, :1])[:, 0]
    alpha = np.degrees(np.arccos(np.clip(r @ wo, -1, 1)))
    edges = np.linspace(0, 60, 31)
    counts = np.histogram(alpha, edges)[0]
    # the lobe (n+1)/(2 pi) cos^n(alpha) over the full sphere: P(a0 < alpha < a1) = cos^(n+1) a0 - cos^(n+1) a1
    c = np.cos(np.radians(edges)) ** (n + 1)
    expected = (c[:-1] - c[1:]) * size
    keep = expected > 20
    res = stats.chisquare(counts[keep], expected[keep] * counts[keep].sum() / expected[keep].sum())
    assert res.pvalue > 1e-3


def test_mirror_sampling_and_weights():
    size = 1000
    d_in, nrm = _incoming(50, size)
    rng = np.random.default_rng(7)
    m = _mat(rho_d=0.2, rho_m=0.6, size=size)
    wo, weight = m.sample(d_in, nrm, rng.random(size), rng.random(size))
    is_mirror = np.all(np.isclose(wo, mirror_direction(d_in, nrm)), axis=0)
    assert abs(is_mirror.mean() - 0.75) < 4 * math.sqrt(0.75 * 0.25 / size)
    np.testing.assert_allclose(weight, 0.8)
    np.testing.assert_allclose(m.eval(d_in, nrm, wo), 0.2 / np.pi)  # the delta part is not evaluated


def test_large_exponent_tends_to_the_mirror():
    """int f cos h dw -> rho_s h(r) as n grows (h smooth), by quadrature.

    The error falls like n^(-1/2): the factor cos th_o / max(cos th_i, cos th_o) < 1 on the
    half of the lobe that leans toward grazing, whose width is ~ n^(-1/2)."""
    d_in, nrm = _incoming(30, 1)
    w, dw = _hemisphere_grid(2000, 2000)
    r = mirror_direction(d_in, nrm)[:, 0]
    h = lambda v: 1 + v[0] + 0.5 * v[2] ** 2  # noqa: E731
    errs = []
    for n in (50.0, 500.0, 2000.0):
        val = float((phong_reference(0.0, 1.0, n, d_in, w) * w[2] * h(w) * dw).sum())
        errs.append(abs(val - h(r)))
    assert errs[2] < errs[1] < errs[0] and errs[2] < 1e-2 * h(r)
    assert errs[2] / errs[0] < 1.5 * math.sqrt(50 / 2000)


def test_glossy_lobe_frame_unit_vectors_and_mean_direction():
    """Samples are unit vectors and E[w] = E[cos alpha] r = (n+1)/(n+2) r (uniform azimuth, orthonormal frame)."""
    from owcsim.engine.surfaces.lobes import _lobe_about_soa

    rng = np.random.default_rng(11)
    size, n = 400_000, 7.0
    for axis in ([0.3, -0.5, 0.81], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]):
        r = np.asarray(axis) / np.linalg.norm(axis)
        w = _lobe_about_soa(np.repeat(r[:, None], size, axis=1), np.full(size, n), rng.random(size), rng.random(size))
        np.testing.assert_allclose(np.einsum("ij,ij->j", w, w), 1.0, atol=1e-6)
        mean = w.mean(axis=1)
        se = w.std(axis=1) / math.sqrt(size)
        assert np.all(np.abs(mean - (n + 1) / (n + 2) * r) < 5 * se + 1e-6), (mean, r)


def test_pdf_is_the_density_of_the_sampled_directions():
    """Importance-sampling identity: E[g(w) / pdf(w)] = int g dw (= 2 pi / 3 for g = max(cos th_o, 0)^2)."""
    size = 400_000
    m = _mat(rho_d=0.3, rho_s=0.5, n=15.0, size=size)
    d_in, nrm = _incoming(50, size)
    rng = np.random.default_rng(12)
    w, _ = m.sample(d_in, nrm, rng.random(size), rng.random(size))
    g = np.maximum(w[2], 0) ** 2
    x = g / m.pdf(d_in, nrm, w)
    se = x.std() / math.sqrt(size)
    assert abs(x.mean() - 2 * math.pi / 3) < 4 * se + 1e-3
    # power: a pdf that forgets the lobe's share fails
    wrong = g / (0.3 / 0.8 * np.maximum(w[2], 0) / np.pi + _mat(rho_s=1.0, n=15.0, size=size).pdf(d_in, nrm, w))
    assert abs(wrong.mean() - 2 * math.pi / 3) > 4 * se + 1e-3
