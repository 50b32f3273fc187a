"""Tests of the deterministic LOS / first-bounce reference (tests/reference.py) itself."""

import math

import numpy as np
import pytest

from tests.reference import SPEED_OF_LIGHT, _cut_fraction, first_bounce_box, first_bounce_box_dc_gain, los_gain

A = 1e-4
DEG = math.pi / 180
WALLS = ("wall_x_min", "wall_x_max", "wall_y_min", "wall_y_max")
# Barry et al. 1993, configuration A (the engine's Monte Carlo tests use it too)
BARRY_RHO = {"floor": 0.3, "ceiling": 0.8, **{w: 0.8 for w in WALLS}}
BARRY_TX = ((2.5, 2.5, 3.0), (0.0, 0.0, -1.0), 1)
BARRY_A = ((5.0, 5.0, 3.0), BARRY_RHO, *BARRY_TX, (0.5, 1.0, 0.0), (0.0, 0.0, 1.0), A, 85 * DEG)
BARRY_A_RX11 = ((5.0, 5.0, 3.0), BARRY_RHO, *BARRY_TX, (1.0, 1.0, 0.0), (0.0, 0.0, 1.0), A, 90 * DEG)


# ---------------------------------------------------------------- LOS
@pytest.mark.parametrize("m, d", [(1, 3.0), (2.7, 1.3)])
def test_los_normal_incidence(m, d):
    h, t = los_gain((0, 0, d), (0, 0, -1), m, (0, 0, 0), (0, 0, 1), A, 60 * DEG)
    assert h == pytest.approx((m + 1) * A / (2 * math.pi * d**2), rel=1e-12)
    assert t == pytest.approx(d / SPEED_OF_LIGHT, rel=1e-12)


def test_los_fov_cutoff_and_back_side():
    x = 3.0 * math.tan(30 * DEG)  # phi = psi = 30 deg, d = 3 / cos 30
    d2 = 9.0 + x**2
    expected = 3 / (2 * math.pi) * math.cos(30 * DEG) ** 2 * A * math.cos(30 * DEG) / d2
    args = ((0, 0, 3), (0, 0, -1), 2, (x, 0, 0), (0, 0, 1), A)
    assert los_gain(*args, 30.1 * DEG)[0] == pytest.approx(expected, rel=1e-12)
    assert los_gain(*args, 29.9 * DEG)[0] == 0.0
    assert los_gain((0, 0, 3), (0, 0, 1), 2, (x, 0, 0), (0, 0, 1), A, 80 * DEG)[0] == 0.0
    assert los_gain((0, 0, 3), (1, 0, 0), 2, (x, 0, 0), (0, 0, 1), A, 80 * DEG)[0] > 0.0
    assert los_gain((0, 0, 3), (-1, 0, 0), 2, (x, 0, 0), (0, 0, 1), A, 80 * DEG)[0] == 0.0


def test_los_attenuation_filter_and_concentrator():
    args = ((1, 2, 3), (0.1, 0, -1), 1.5, (2, 1.5, 0.2), (0, 0.2, 1), A, 50 * DEG)
    h0, _ = los_gain(*args)
    d = math.dist((1, 2, 3), (2, 1.5, 0.2))
    assert h0 > 0
    assert los_gain(*args, sigma_t=0.7)[0] == pytest.approx(h0 * math.exp(-0.7 * d), rel=1e-12)
    g = 1.5**2 / math.sin(50 * DEG) ** 2
    assert los_gain(*args, filter_gain=0.6, concentrator_index=1.5)[0] == pytest.approx(h0 * 0.6 * g, rel=1e-12)


# ---------------------------------------------------------------- first bounce
def test_cut_fraction_against_grid_count():
    n = 2000
    x = (np.arange(n) + 0.5) / n * 2 - 1  # fine grid on [-1, 1]^2, half-edges a = 0.3, b = 0.1
    X, Y = np.meshgrid(0.3 * x, 0.1 * x)
    for gu, gv, delta in [(0.8, 0.6, 0.05), (-0.8, 0.6, -0.2), (1.0, 0.0, 0.1), (0.3, -2.0, 0.0)]:
        exact = np.mean(gu * X + gv * Y <= delta)
        assert _cut_fraction(delta, abs(gu) * 0.3, abs(gv) * 0.1) == pytest.approx(exact, abs=2e-3)
    assert _cut_fraction(10.0, 0.3, 0.1) == 1.0 and _cut_fraction(-10.0, 0.3, 0.1) == 0.0


def test_single_patch_against_hand_computation():
    """One 2 m x 2 m ceiling patch (centre (1, 1, 3)), plain midpoint rule, all factors on."""
    sigma, ts, nc = 0.2, 0.9, 1.5
    d1, d2 = math.sqrt(0.5**2 + 2.5**2), math.sqrt(0.5**2 + 2.0**2)
    cos_phi = cos_in = 2.5 / d1  # Tx (0.5, 1, 0.5) facing up, ceiling normal (0, 0, -1)
    cos_out = cos_psi = 2.0 / d2  # Rx (1.5, 1, 1) facing up
    irradiance = 3 / (2 * math.pi) * cos_phi**2 * cos_in / d1**2  # m = 2, per watt
    radiance = 0.7 / math.pi * irradiance
    a_eff = A * cos_psi * ts * nc**2 / math.sin(math.pi / 2) ** 2
    expected = radiance * 4.0 * cos_out * a_eff / d2**2 * math.exp(-sigma * (d1 + d2))
    t0 = (d1 + d2) / SPEED_OF_LIGHT
    h, hist = first_bounce_box(
        (2, 2, 3),
        {"ceiling": 0.7},
        (0.5, 1, 0.5),
        (0, 0, 1),
        2,
        (1.5, 1, 1),
        (0, 0, 1),
        A,
        math.pi / 2,
        filter_gain=ts,
        concentrator_index=nc,
        sigma_t=sigma,
        patch_size=10.0,
        refine_depth=0,
        t_edges=[0, t0 - 1e-12, t0 + 1e-12, 1e-6],
    )
    assert h == pytest.approx(expected, rel=1e-12)
    assert hist[1] == h and hist[0] == hist[2] == 0.0


def test_histogram_sums_to_dc_gain():
    edges = np.arange(0, 60e-9, 0.25e-9)  # longest first-bounce path < 2 x room diagonal
    h, hist = first_bounce_box(*BARRY_A, patch_size=0.05, t_edges=edges)
    assert hist.sum() == pytest.approx(h, rel=1e-12)
    t_los = los_gain(*BARRY_A[2:])[1]  # triangle inequality: d1 + d2 >= d_los
    assert np.all(hist[edges[1:] <= t_los] == 0)
    _, early = first_bounce_box(*BARRY_A, patch_size=0.05, t_edges=edges[:61])  # up to 15 ns
    assert np.allclose(early, hist[:60], rtol=1e-12, atol=0) and early.sum() < 0.9 * h


def test_origin_translation_and_face_names():
    shift = np.array([1.0, -2.0, 0.5])
    room, rho, tx, nt, m, rx, nr, area, fov = BARRY_A
    h0, _ = first_bounce_box(*BARRY_A, patch_size=0.1)
    h1, _ = first_bounce_box(room, rho, tx + shift, nt, m, rx + shift, nr, area, fov, origin=shift, patch_size=0.1)
    assert h1 == pytest.approx(h0, rel=1e-9)
    with pytest.raises(ValueError):
        first_bounce_box(room, {"roof": 0.5}, tx, nt, m, rx, nr, area, fov)


def test_reciprocity():
    """m = 1, FOV = 90 deg, Ts = 1, no concentrator: R(phi) = cos(phi) / pi, so f(P) is
    symmetric in the two devices; exact relation: H(a -> b, area A) == H(b -> a, area A)."""
    room, rho = (
        (5.0, 4.0, 3.0),
        {"floor": 0.2, "ceiling": 0.7, "wall_x_min": 0.5, "wall_x_max": 0.9, "wall_y_min": 0.6, "wall_y_max": 0.4},
    )
    a = ((1.2, 0.7, 2.1), (0.3, 0.2, -1.0))
    b = ((4.97, 2.2, 0.8), (-1.0, 0.3, 0.4))  # 3 cm from a wall: graded refinement active
    kw = dict(sigma_t=0.3, patch_size=0.05)
    h_ab, _ = first_bounce_box(room, rho, *a, 1, *b, A, math.pi / 2, **kw)
    h_ba, _ = first_bounce_box(room, rho, *b, 1, *a, A, math.pi / 2, **kw)
    assert h_ab > 0 and h_ab == pytest.approx(h_ba, rel=1e-6)


@pytest.mark.parametrize("m, fov, nc", [(1, 90 * DEG, None), (3, 40 * DEG, 1.5)])
def test_colocated_devices_over_a_plane_closed_form(m, fov, nc):
    """Tx and Rx at height z above the only reflecting face, both facing it: polar integral
    H = (m+1) rho A g / (pi (m+5) z^2) * (1 - cos^(m+5) FOV)  (disk psi <= FOV on the floor);
    the 10 m x 10 m floor truncates the infinite plane by < (1 + (5/z)^2)^(-3) = 1e-6."""
    z, rho = 0.5, 0.6
    g = 1.0 if nc is None else nc**2 / math.sin(fov) ** 2
    expected = (m + 1) * rho * A * g / (math.pi * (m + 5) * z**2) * (1 - math.cos(fov) ** (m + 5))
    pos, down = (5.0, 5.0, z), (0.0, 0.0, -1.0)
    h = first_bounce_box_dc_gain(
        (10.0, 10.0, 3.0), {"floor": rho}, pos, down, m, pos, down, A, fov, concentrator_index=nc
    )
    assert h == pytest.approx(expected, rel=1e-4)


def test_against_scipy_adaptive_quadrature():
    """Barry A with Rx (1, 1, 0), FOV 90 deg (only the walls count: the devices lie in the floor
    and ceiling planes): QUADPACK dblquad of a scalar integrand written out here."""
    dblquad = pytest.importorskip("scipy.integrate").dblquad
    tx, rx = np.array([2.5, 2.5, 3.0]), np.array([1.0, 1.0, 0.0])
    walls = [
        (lambda a, b: np.array([0.0, a, b]), np.array([1.0, 0, 0])),
        (lambda a, b: np.array([5.0, a, b]), np.array([-1.0, 0, 0])),
        (lambda a, b: np.array([a, 0.0, b]), np.array([0, 1.0, 0])),
        (lambda a, b: np.array([a, 5.0, b]), np.array([0, -1.0, 0])),
    ]

    def f(b, a, point, n):
        v1, v2 = point(a, b) - tx, rx - point(a, b)
        d1, d2 = np.linalg.norm(v1), np.linalg.norm(v2)
        cosines = (-v1[2] / d1, -(v1 @ n) / d1, (v2 @ n) / d2, -v2[2] / d2)
        if min(cosines) <= 0:
            return 0.0
        return cosines[0] / math.pi * cosines[1] / d1**2 * 0.8 / math.pi * cosines[2] * A * cosines[3] / d2**2

    expected = sum(dblquad(f, 0, 5, 0, 3, args=w, epsabs=0, epsrel=1e-9)[0] for w in walls)
    assert first_bounce_box_dc_gain(*BARRY_A_RX11) == pytest.approx(expected, rel=1e-4)
    assert first_bounce_box(*BARRY_A_RX11)[0] == pytest.approx(expected, rel=1e-3)


@pytest.mark.parametrize(
    "config",
    [
        BARRY_A,
        # Rx on the floor 2 cm from a wall, narrow FOV: near-singular wall term plus FOV edge
        ((5.0, 5.0, 3.0), BARRY_RHO, *BARRY_TX, (0.02, 1.0, 0.0), (0.0, 0.0, 1.0), A, 60 * DEG),
    ],
)
def test_richardson_convergence(config):
    r, plain, rich = first_bounce_box_dc_gain(*config, full_output=True)
    fine, _ = first_bounce_box(*config, patch_size=0.01)
    assert fine == pytest.approx(r, rel=1e-3)  # finest plain value vs extrapolated value
    assert plain[-1] == pytest.approx(r, rel=1e-3)
    ratio = (plain[-2] - plain[-3]) / (plain[-1] - plain[-2])
    assert 3.0 < ratio < 5.0  # observed order 2: the error really is ~ c h^2


def test_barry_configuration_a_figures():
    """Figures the engine's Monte Carlo tests compare against (printed with -s).
    LOS: d^2 = 2^2 + 1.5^2 + 3^2, H = (2 / 2 pi) (3/d) A (3/d) / d^2 = 9 A / (pi d^4).
    First-bounce values pinned from this reference (regression guard, 1e-4)."""
    for config, d2, h1_pinned in [(BARRY_A, 15.25, 5.04925e-07), (BARRY_A_RX11, 13.5, 5.042529e-07)]:
        h_los, t_los = los_gain(*config[2:])
        assert h_los == pytest.approx(9 * A / (math.pi * d2**2), rel=1e-12)
        r, plain, rich = first_bounce_box_dc_gain(*config, rel_tol=1e-6, full_output=True)
        print(
            f"\nRx {config[5]} FOV {config[8] / DEG:.0f} deg: H_los = {h_los:.7e} "
            f"(t = {t_los * 1e9:.4f} ns), H_1 = {r:.7e}\n  plain (h = 0.1/2^k m) "
            f"{[f'{p:.7e}' for p in plain]}\n  Richardson {[f'{x:.7e}' for x in rich]}"
        )
        assert r == pytest.approx(h1_pinned, rel=1e-4)
