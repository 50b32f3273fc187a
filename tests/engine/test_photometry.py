"""Photometric files (IES LM-63, EULUMDAT): parsing, symmetry, normalisation and exact sampling.

References are independent of engine/sources/photometry.py: closed forms (cos^m, constant
intensity), a plain bilinear interpolation and a fine midpoint quadrature written here,
and chi-square tests of the sampled directions against probabilities computed that way.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy import stats

from owcsim.engine.sources.photometry import PhotometryError, luminaire_frame
from owcsim.engine.sources.photometry_files import parse_ies, parse_ldt


# ----------------------------------------------------------------------------- writers (test fixtures)
def _rows(values, per_line=8):
    values = list(values)
    return "\n".join(" ".join(f"{v:.6g}" for v in values[k : k + per_line]) for k in range(0, len(values), per_line))


def ies_text(gamma_deg, c_deg, candela, *, version="IESNA:LM-63-2002", lumens=-1.0, multiplier=1.0, tilt="NONE") -> str:
    """An LM-63 file: `candela` (n_c, n_g) [cd] at horizontal angles c_deg, vertical gamma_deg."""
    cd = np.asarray(candela, float)
    head = [version] if version else []
    head += ["[TEST] synthetic", "[MANUFAC] owcsim tests", "[LUMINAIRE] test pattern", f"TILT={tilt}"]
    if tilt == "INCLUDE":
        head += ["1", "3", "0 45 90", "1.0 0.95 0.9"]
    head += [
        f"1 {lumens:g} {multiplier:g} {len(gamma_deg)} {len(c_deg)} 1 2 0.1 0.1 0.02",
        "1.0 1.0 12.5",
        _rows(gamma_deg),
        _rows(c_deg),
    ]
    head += [_rows(row) for row in cd]
    return "\r\n".join(head) + "\r\n"


def ldt_text(gamma_deg, c_all_deg, stored_cd, isym, *, lamp_flux=1000.0, lor=100.0, factor=1.0) -> str:
    """A EULUMDAT file; `stored_cd` (planes stored for isym, n_g) [cd/klm]."""
    mc, ng = len(c_all_deg), len(gamma_deg)
    dc = c_all_deg[1] - c_all_deg[0] if mc > 1 else 0
    lines = [
        "owcsim tests",
        "1",
        str(isym),
        str(mc),
        f"{dc:g}",
        str(ng),
        f"{gamma_deg[1] - gamma_deg[0]:g}",
        "report",
        "test luminaire",
        "T-1",
        "test.ldt",
        "2026-12-01",
        "600",
        "600",
        "80",
        "580",
        "580",
        "0",
        "0",
        "0",
        "0",
        "100",
        f"{lor:g}".replace(".", ","),
        f"{factor:g}",
        "0",
        "1",
        "1",
        "LED",
        f"{lamp_flux:g}",
        "4000",
        "80",
        "30",
    ]
    lines += ["0.5"] * 10
    lines += [f"{c:g}" for c in c_all_deg] + [f"{g:g}" for g in gamma_deg]
    lines += [f"{v:.6g}" for v in np.asarray(stored_cd, float).ravel()]
    return "\n".join(lines) + "\n"


def as_written(table):
    """The table as the writers store it (6 significant digits)."""
    return np.vectorize(lambda v: float(f"{v:.6g}"))(np.asarray(table, float))


def cos_power_table(m, gamma_deg, c_deg, scale=1000.0):
    g = np.radians(gamma_deg)
    row = scale * np.where(g < np.pi / 2, np.cos(np.minimum(g, np.pi / 2)) ** m, 0.0)
    return np.tile(np.maximum(row, 0.0), (len(c_deg), 1))


def tilted_lobe(gamma_deg, c_deg, tilt_deg=25.0, c_tilt_deg=60.0, m=6.0, back=0.05):
    """An asymmetric pattern: a cos^m lobe about an axis tilted by tilt_deg toward C = c_tilt_deg, plus a
    uniform backward glow `back` for gamma > 90 deg (an uplight component)."""
    g, c = np.meshgrid(np.radians(gamma_deg), np.radians(c_deg))
    d = np.stack((np.sin(g) * np.cos(c), np.sin(g) * np.sin(c), np.cos(g)), -1)
    t, ct = math.radians(tilt_deg), math.radians(c_tilt_deg)
    axis = np.array([math.sin(t) * math.cos(ct), math.sin(t) * math.sin(ct), math.cos(t)])
    cos_a = d @ axis
    return 1000.0 * (np.maximum(cos_a, 0.0) ** m + back * (g > np.pi / 2))


# ----------------------------------------------------------------------------- independent references
def bilinear(gamma_deg, c_deg, table, g, c):
    """Plain bilinear interpolation on a full (C from 0 to 360) table at angles g, c [deg]."""
    out = np.zeros(np.shape(g))
    for k in np.ndindex(np.shape(g)):
        gg, cc = g[k], c[k] % 360.0
        if gg < gamma_deg[0] or gg > gamma_deg[-1]:
            continue
        i = min(np.searchsorted(gamma_deg, gg, side="right") - 1, len(gamma_deg) - 2)
        j = min(np.searchsorted(c_deg, cc, side="right") - 1, len(c_deg) - 2)
        s = (gg - gamma_deg[i]) / (gamma_deg[i + 1] - gamma_deg[i])
        t = (cc - c_deg[j]) / (c_deg[j + 1] - c_deg[j])
        out[k] = (
            (1 - s) * (1 - t) * table[j, i]
            + (1 - s) * t * table[j + 1, i]
            + s * (1 - t) * table[j, i + 1]
            + s * t * table[j + 1, i + 1]
        )
    return out


def midpoint_masses(gamma_deg, c_deg, table, sub=24):
    """Probability of each table cell under I sin(gamma) by a sub x sub midpoint rule per cell."""
    gamma_deg, c_deg = np.asarray(gamma_deg, float), np.asarray(c_deg, float)
    u = (np.arange(sub) + 0.5) / sub
    s, t = np.meshgrid(u, u, indexing="ij")  # s along gamma, t along C
    masses = np.zeros((len(c_deg) - 1, len(gamma_deg) - 1))
    for j in range(len(c_deg) - 1):
        for i in range(len(gamma_deg) - 1):
            g = np.radians(gamma_deg[i] + s * (gamma_deg[i + 1] - gamma_deg[i]))
            val = (
                (1 - s) * (1 - t) * table[j, i]
                + (1 - s) * t * table[j + 1, i]
                + s * (1 - t) * table[j, i + 1]
                + s * t * table[j + 1, i + 1]
            )
            area = math.radians(gamma_deg[i + 1] - gamma_deg[i]) * math.radians(c_deg[j + 1] - c_deg[j])
            masses[j, i] = (val * np.sin(g)).mean() * area
    return masses


G5 = np.arange(0.0, 90.01, 5.0)
G180 = np.arange(0.0, 180.01, 5.0)
C_FULL = np.arange(0.0, 360.01, 15.0)


def _random_dirs(n, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# ----------------------------------------------------------------------------- parsing and evaluation
@pytest.mark.parametrize("version", ["IESNA:LM-63-1995", "IESNA:LM-63-2002", "IES:LM-63-2019", None])
def test_cos_power_ies_matches_generalized_lambertian(version):
    """R = (m+1)/(2 pi) cos^m within the bilinear interpolation error (m = 3, 5 deg steps)."""
    m = 3.0
    c = np.array([0.0])
    ph = parse_ies(ies_text(G5, c, cos_power_table(m, G5, c), version=version).encode())
    assert ph.symmetry == "rotational"
    dirs = _random_dirs(4000, 1)
    exact = (m + 1) / (2 * np.pi) * np.maximum(dirs[:, 2], 0) ** m
    # |bilinear - f| <= h^2 / 8 max|f''| with h = 5 deg, f = (m+1)/(2 pi) cos^m gamma: |f''| <= m^2 (m+1)/(2 pi)
    bound = math.radians(5) ** 2 / 8 * m * m * (m + 1) / (2 * np.pi)
    err = np.abs(ph.eval_local(dirs) - exact)
    assert err.max() < bound
    assert err.max() > 0.05 * bound  # the comparison is not vacuous
    # the flux of the interpolated table is that of cos^m within the same error: 2 pi / (m + 1) x 1000 cd
    assert ph.flux == pytest.approx(1000 * 2 * np.pi / (m + 1), rel=2e-3)


def test_flux_of_constant_and_linear_tables_closed_form():
    c = np.array([0.0, 90.0])
    one = parse_ies(ies_text(G5, c, np.ones((2, len(G5))), lumens=500, multiplier=2.0).encode())
    assert one.flux == pytest.approx(2 * 2 * np.pi, rel=1e-12)  # 2 cd over the hemisphere
    assert one.declared_flux == pytest.approx(1000.0)
    g2 = np.array([0.0, 180.0])  # I = gamma (linear in the angle, exact for the interpolation)
    lin = parse_ies(ies_text(g2, [0.0], [[0.0, 180.0]]).encode())
    # int_0^pi (180/pi) x sin x dx 2 pi = (180/pi) pi 2 pi
    assert lin.flux == pytest.approx(180.0 * 2 * np.pi, rel=1e-12)


@pytest.mark.parametrize(
    "symmetry,c_stored",
    [
        ("quadrant", np.arange(0.0, 90.01, 15.0)),
        ("bilateral_c0_c180", np.arange(0.0, 180.01, 15.0)),
        ("bilateral_c90_c270", np.arange(90.0, 270.01, 15.0)),
    ],
)
def test_symmetric_ies_files_equal_the_full_file(symmetry, c_stored):
    """A quadrant-symmetric pattern written in each symmetric form and in full gives one distribution."""

    def pattern(cs):  # symmetric about both the C0-C180 and the C90-C270 planes
        g, c = np.meshgrid(np.radians(G180), np.radians(cs))
        return 100 * (1 + 0.6 * np.cos(2 * c) * np.sin(g)) * (1.2 + np.cos(g))

    full = parse_ies(ies_text(G180, C_FULL, pattern(C_FULL)).encode())
    part = parse_ies(ies_text(G180, c_stored, pattern(c_stored)).encode())
    assert full.symmetry == "none" and part.symmetry == symmetry
    dirs = _random_dirs(3000, 2)
    np.testing.assert_allclose(part.eval_local(dirs), full.eval_local(dirs), rtol=1e-12)
    assert part.flux == pytest.approx(full.flux, rel=1e-12)


def test_eulumdat_equals_ies_for_every_symmetry():
    c_all = np.arange(0.0, 360.0, 15.0)  # Mc = 24 planes, as EULUMDAT lists them
    g = G180
    full = tilted_lobe(g, np.append(c_all, 360.0), tilt_deg=0.0)  # rotationally symmetric here
    ref = parse_ies(ies_text(g, np.append(c_all, 360.0), full).encode())
    dirs = _random_dirs(2000, 3)
    for isym, stored in (
        (0, np.arange(24)),
        (1, [0]),
        (2, np.arange(13)),
        (3, (18 + np.arange(13)) % 24),
        (4, np.arange(7)),
    ):
        ph = parse_ldt(ldt_text(g, c_all, full[stored], isym).encode())
        np.testing.assert_allclose(ph.eval_local(dirs), ref.eval_local(dirs), rtol=1e-9, atol=1e-15)
    # an asymmetric one: Isym 3 stores C270 .. C0 .. C90 (EULUMDAT: Mc1 = 3 Mc / 4 + 1)
    lobe = tilted_lobe(g, np.append(c_all, 360.0), c_tilt_deg=0.0)  # symmetric about C0-C180 only... and
    ph2 = parse_ldt(ldt_text(g, c_all, lobe[np.arange(13)], 2).encode())
    ref2 = parse_ies(ies_text(g, np.append(c_all, 360.0), lobe).encode())
    np.testing.assert_allclose(ph2.eval_local(dirs), ref2.eval_local(dirs), rtol=1e-9, atol=1e-15)
    lobe90 = tilted_lobe(g, np.append(c_all, 360.0), c_tilt_deg=90.0)  # symmetric about C90-C270
    ph3 = parse_ldt(ldt_text(g, c_all, lobe90[(18 + np.arange(13)) % 24], 3).encode())
    ref3 = parse_ies(ies_text(g, np.append(c_all, 360.0), lobe90).encode())
    np.testing.assert_allclose(ph3.eval_local(dirs), ref3.eval_local(dirs), rtol=1e-9, atol=1e-15)


def test_eval_against_plain_bilinear_interpolation_and_flux_by_quadrature():
    table = as_written(tilted_lobe(G180, C_FULL))
    ph = parse_ies(ies_text(G180, C_FULL, table, tilt="INCLUDE").encode())
    rng = np.random.default_rng(4)
    g, c = rng.uniform(0, 180, 500), rng.uniform(0, 360, 500)
    ref = bilinear(G180, C_FULL, table, g, c)
    flux = midpoint_masses(G180, C_FULL, table).sum()
    assert ph.flux == pytest.approx(flux, rel=1e-5)
    np.testing.assert_allclose(ph.eval_angles(np.radians(g), np.radians(c)) * ph.flux, ref, rtol=1e-9, atol=1e-9)


# ----------------------------------------------------------------------------- sampling
def _chi2_pvalue(ph, gamma_deg, c_deg, table, n, seed):
    rng = np.random.default_rng(seed)
    g, c = ph.sample_angles(rng.random(n), rng.random(n))
    p = midpoint_masses(gamma_deg, c_deg, table)
    p = p / p.sum()
    i = np.clip(np.searchsorted(np.radians(gamma_deg), g, side="right") - 1, 0, len(gamma_deg) - 2)
    j = np.clip(np.searchsorted(np.radians(c_deg), c, side="right") - 1, 0, len(c_deg) - 2)
    counts = np.bincount(j * (len(gamma_deg) - 1) + i, minlength=p.size)
    # sub-cell check too: the upper and lower halves of each gamma cell (tests the inversion inside cells)
    mid = np.radians(0.5 * (gamma_deg[i] + gamma_deg[i + 1]))
    keep = p.ravel() * n > 20
    observed, expected = counts[keep], p.ravel()[keep] * n
    stat = stats.chisquare(observed, expected * observed.sum() / expected.sum())
    return stat.pvalue, g, mid


def test_sampled_directions_chi_square_against_table():
    table = as_written(tilted_lobe(G180, C_FULL))
    ph = parse_ies(ies_text(G180, C_FULL, table).encode())
    pvalue, g, _ = _chi2_pvalue(ph, G180, C_FULL, table, 400_000, 5)
    assert pvalue > 1e-3
    # within-cell shape: gamma fine bins of 1 deg against the quadrature of the interpolant
    fine_g = np.arange(0.0, 180.01, 1.0)
    fine_tab = np.array([bilinear(G180, C_FULL, table, fine_g, np.full(len(fine_g), cc)) for cc in C_FULL])
    p = midpoint_masses(fine_g, C_FULL, fine_tab, sub=8).sum(axis=0)
    counts = np.histogram(np.degrees(g), bins=fine_g)[0]
    keep = p / p.sum() * len(g) > 20
    res = stats.chisquare(counts[keep], p[keep] / p[keep].sum() * counts[keep].sum())
    assert res.pvalue > 1e-3


def test_chi_square_has_power():
    """Sampling the cos^m table and testing against cos^(m+0.15) (a ~2 % change of the spread) fails."""
    c = np.array([0.0, 360.0])
    ph = parse_ies(ies_text(G5, c, cos_power_table(4.0, G5, c)).encode())
    pvalue, _, _ = _chi2_pvalue(ph, G5, c, cos_power_table(4.15, G5, c), 400_000, 6)
    assert pvalue < 1e-6


def test_sampled_directions_in_world_frame():
    """The frame: aim -z, C0 along +x -> C90 along +y; rotation turns C0 toward C90."""
    f = luminaire_frame((0, 0, -1))
    np.testing.assert_allclose(f, [[1, 0, 0], [0, 1, 0], [0, 0, -1]], atol=1e-15)
    f = luminaire_frame((0, 0, -1), rotation_deg=90.0)
    np.testing.assert_allclose(f[0], [0, 1, 0], atol=1e-15)
    f = luminaire_frame((1, 0, 0), c0_direction=(0, 0, 1))
    np.testing.assert_allclose(f, [[0, 0, 1], [0, 1, 0], [1, 0, 0]], atol=1e-15)  # e_C90 = e_C0 x aim


# ----------------------------------------------------------------------------- bad files
GOOD = ies_text(G5, [0.0], cos_power_table(1, G5, [0.0]))


@pytest.mark.parametrize(
    "mutate,message",
    [
        (lambda t: t.replace("TILT=NONE", "TILT=lamp.tlt"), "line 5: TILT=LAMP.TLT names an external tilt file"),
        (lambda t: t.replace("1 -1 1 19 1 1 2", "1 -1 1 19 1 2 2"), "photometric type 2 (B) is not supported"),
        (
            lambda t: t.replace("1 -1 1 19 1", "1 -1 1 19 x"),
            "line 6: the number of horizontal angles should be a number",
        ),
        (lambda t: t.rsplit(" ", 3)[0], "the file ends (line 13) before candela values (16 of 19)"),
        (lambda t: t + "42\r\n", "line 15: unexpected value '42' after the 1 x 19 candela table"),
        (lambda t: t.replace("0 5 10 15", "0 10 5 15"), "vertical angles must increase strictly"),
        (lambda t: t.replace("IESNA:LM-63-2002", "IESNA:LM-63-2042"), "line 1: unknown IES version tag"),
        (lambda t: t.replace("TILT=NONE", "NOTILT"), "no TILT= line"),
    ],
)
def test_bad_ies_files_have_located_errors(mutate, message):
    with pytest.raises(PhotometryError, match=re.escape(message)):
        parse_ies(mutate(GOOD).encode(), "transmitters[0].photometry")


def test_bad_ies_values():
    bad_h = ies_text(G5, [0.0, 45.0, 120.0], np.ones((3, len(G5))))
    with pytest.raises(PhotometryError, match="horizontal angles 0..120 deg"):
        parse_ies(bad_h.encode())
    with pytest.raises(PhotometryError, match="negative candela"):
        parse_ies(ies_text(G5, [0.0], -np.ones((1, len(G5)))).encode())
    with pytest.raises(PhotometryError, match="emits nothing"):
        parse_ies(ies_text(G5, [0.0], np.zeros((1, len(G5)))).encode())


def test_bad_ldt_files_have_located_errors():
    c_all = np.arange(0.0, 360.0, 30.0)
    good = ldt_text(G5, c_all, np.ones((12, len(G5))), 0)
    parse_ldt(good.encode())
    lines = good.split("\n")
    with pytest.raises(PhotometryError, match="line 3: Isym must be 0..4, found 7"):
        parse_ldt("\n".join(lines[:2] + ["7"] + lines[3:]).encode())
    with pytest.raises(PhotometryError, match="line 4: Mc \\(number of C planes\\) should be a number"):
        parse_ldt("\n".join(lines[:3] + ["twelve"] + lines[4:]).encode())
    with pytest.raises(PhotometryError, match="ends .* before intensities"):
        parse_ldt("\n".join(lines[:-20]).encode())
    with pytest.raises(PhotometryError, match="Isym = 2 the stored C planes must run from 0 to 180"):
        parse_ldt(ldt_text(G5, np.arange(0.0, 360.0, 30.0) + 5, np.ones((7, len(G5))), 2).encode())


def test_gamma_inversion_is_exact_on_hard_cells():
    """F(x) = v F(g1), F by numerical quadrature; cells with zero density at an end, a 0.06 deg cell.

    (Cells far smaller than any file's step lose digits to cancellation in F: 1e-7 relative
    at 1e-3 rad, 1e-13 at 0.1 rad.)"""
    from scipy import integrate

    from owcsim.engine.sources.photometry import _invert_gamma_cdf

    rng = np.random.default_rng(9)
    cases = [
        (0.0, 1.0, 0.0, 0.1),
        (1.0, -10.0, 0.0, 0.1),
        (2.0, 0.0, 3.0, math.pi),
        (0.0, 5.0, 1.5, 1.501),
        (3.0, -3.0 / 0.5, 1.0, 1.5),
    ]
    for a, b, g0, g1 in cases:
        v = np.concatenate([[0.0, 1.0, 1e-9, 1 - 1e-9], rng.random(50)])
        x = _invert_gamma_cdf(np.full(len(v), a), np.full(len(v), b), np.full(len(v), g0), np.full(len(v), g1), v)
        assert np.all((x >= g0) & (x <= g1))
        dens = lambda t, a=a, b=b, g0=g0: (a + b * (t - g0)) * math.sin(t)  # noqa: E731
        total = integrate.quad(dens, g0, g1, epsabs=0, epsrel=1e-13)[0]
        for xi, vi in zip(x[:20], v[:20]):
            got = integrate.quad(dens, g0, xi, epsabs=0, epsrel=1e-13)[0]
            assert got == pytest.approx(vi * total, rel=1e-7, abs=1e-10 * total)
