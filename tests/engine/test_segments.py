"""Equiangular sampling (segments.EquiangularFrame): the tan-of-a-sum / tan-of-a-difference forms against the
closed form of Kulla & Fajardo (2012), and the sampler against its density by plain quadrature."""

import numpy as np
import pytest
from scipy.integrate import quad

from owcsim.engine.integrator.segments import EquiangularFrame


def _geometries(rng, n):
    """Random segments o + s w, 0 <= s <= end, in and around a 5 x 5 x 3 m room, toward y = (1, 1, 0)."""
    o = rng.uniform([-1, -1, -1], [6, 6, 4], (n, 3)).T
    w = rng.normal(size=(3, n))
    w /= np.sqrt((w * w).sum(0))
    end = rng.uniform(0.05, 8.0, n)
    return o, w, np.array([[1.0], [1.0], [0.0]]), end


def _closed_form(o, w, y, a, b, xi):
    """s = D + h tan(theta_a + xi (theta_b - theta_a)) and the pdf, in extended precision (np.longdouble)."""
    L = np.longdouble
    o, w, y, a, b, xi = (np.asarray(x, L) for x in (o, w, y, a, b, xi))
    v = y - o
    D = (v * w).sum(0)
    r = v - D * w
    h = np.sqrt((r * r).sum(0))
    ta, tb = np.arctan2(a - D, h), np.arctan2(b - D, h)
    s = D + h * np.tan(ta + xi * (tb - ta))
    return s, D, h, tb - ta


def test_sample_matches_the_closed_form():
    """s - a = r2 t / (h + c t) equals D + h tan(theta_a + xi span) (Kulla & Fajardo 2012, eq. 7), segments
    starting at a = 0 and at a > 0; the reference in extended precision, away from its own cancellation."""
    rng = np.random.default_rng(3)
    n = 20_000
    o, w, y, end = _geometries(rng, n)
    xi = rng.random(n)
    for a in (0.0, rng.uniform(0.0, 2.0, n)):
        b = a + end
        got = EquiangularFrame(o, w, y, a, b).sample(None, xi)
        ref, D, h, span = _closed_form(o, w, y, a, b, xi)
        # the closed form cancels where s - a << |D| + h (ref's own error ~1e-19 (|D| + h |tan|))
        ok = np.abs(ref - np.asarray(a, np.longdouble)) > 1e-3 * (np.abs(D) + h)
        assert ok.mean() > 0.95
        err = np.abs(got - ref) / (np.abs(D) + h)
        assert float(err[ok].max()) < 1e-13
        # a wrong angle term (xi span 1e-6 relative too far) would be seen
        wrong = D + h * np.tan(np.arctan2(np.asarray(a) - D, h) + xi * span * (1 + 1e-6))
        assert float((np.abs(np.asarray(wrong, float) - got) / (np.abs(D) + h))[ok].max()) > 1e-9


def test_span_is_the_angle_difference():
    """span = atan2(L h, r2 - c L) = theta_b - theta_a, for spans below and above pi / 2."""
    rng = np.random.default_rng(4)
    o, w, y, end = _geometries(rng, 5000)
    f = EquiangularFrame(o, w, y, 0.0, end)
    _, _, _, span = _closed_form(o, w, y, 0.0, end, 0.0)
    assert (f.span > np.pi / 2).any() and (f.span < 0.1).any()
    np.testing.assert_allclose(f.span, np.asarray(span, float), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("a", [0.0, 0.7])
def test_sampler_inverts_the_cdf_of_its_density(a):
    """For each segment, the density n_E / n_per integrates to 1 over [a, b] and F(s(xi)) = xi, F the integral
    of the density (scipy quad): the sampler draws exactly the density the balance heuristic divides by."""
    rng = np.random.default_rng(5)
    n = 40
    o, w, y, end = _geometries(rng, n)
    # include segments passing within 1 cm and 1 mm of the target (sharp peaks)
    for i, miss in ((0, 1e-2), (1, 1e-3)):
        foot = y[:, 0] + miss * np.array([0.0, 0.0, 1.0]) - 2.0 * w[:, i]
        o[:, i] = foot - a * w[:, i]
        end[i] = 4.0
    b = a + end
    f = EquiangularFrame(o, w, y, a, b)
    xi = np.array([0.05, 0.3, 0.5, 0.77, 0.99])
    for i in range(n):
        seg = np.full(len(xi), i)
        s = f.sample(seg, xi)

        def pdf(t, i=i):
            return float(f.density(np.array([t]), 1, np.array([i]))[0])

        def integral(lo, hi, i=i):  # split near the peak at D (width h)
            D, h = float(f.D[i]), float(f.h[i])
            cuts = [lo] + [c for c in (D - 10 * h, D, D + 10 * h) if lo < c < hi] + [hi]
            return sum(quad(pdf, p, q, limit=200, epsabs=1e-13, epsrel=1e-11)[0] for p, q in zip(cuts, cuts[1:]))

        assert integral(a, b[i]) == pytest.approx(1.0, rel=1e-8)
        for x, si in zip(xi, s):
            cdf = integral(a, float(si))
            assert abs(cdf - x) < 1e-8, (i, x, cdf)


def test_grid_and_gathered_sampling_agree_and_empty_segments_have_no_density():
    """sample(None, xi (k, n)) broadcasts over the segments as sample(seg, xi) does with index arrays; a
    segment of length 0 has span 0 and density 0."""
    rng = np.random.default_rng(6)
    o, w, y, end = _geometries(rng, 100)
    end[7] = 0.0
    f = EquiangularFrame(o, w, y, 0.0, end)
    xi = rng.random((2, 100))
    grid = f.sample(None, xi)
    seg = np.tile(np.arange(100), 2)
    np.testing.assert_array_equal(grid.ravel(), f.sample(seg, xi.ravel()))
    np.testing.assert_array_equal(f.density(grid, 2).ravel(), f.density(grid.ravel(), 2, seg))
    assert f.span[7] == 0.0 and f.density(np.array([0.0]), 2, np.array([7]))[0] == 0.0
    assert (f.density(grid, 2)[:, np.arange(100) != 7] > 0).all()
