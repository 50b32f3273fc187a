"""Tabulated phase functions whose values carry a large (or tiny) common factor (issue 25, item 7).

The schema lets `values` carry any common factor. The engine divides by the table's largest power
of two first, so values up to the float max give the phase function of the unscaled table:
the same bits for a power-of-two factor, to 1e-12 for any other; before, values near 1e308
overflowed the integral and every value became 0 (no scattering: a silently low H0).

References: the isotropic table's closed form 1 / (4 pi) and mean cosine 0; the unscaled table.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from owcsim.engine.media import phase as ph
from owcsim.schemas.medium import TabulatedPhaseSpec
from tests.engine.test_tabulated_phase import _h0, _hg_table

FLOAT_MAX = sys.float_info.max
C_ISO = np.linspace(-1.0, 1.0, 11)


def _to_max(v: np.ndarray) -> np.ndarray:
    """The table scaled so that its largest value is the float max (to rounding)."""
    return v / v.max() * FLOAT_MAX


@pytest.mark.parametrize(
    "scale", [1.0, 1e-300, 1e300, FLOAT_MAX, 2.0**-1074], ids=["1", "1e-300", "1e300", "max", "smallest"]
)
def test_a_scaled_isotropic_table_is_the_closed_form(scale):
    f = ph.Tabulated(C_ISO, np.full(len(C_ISO), scale))
    assert np.allclose(f.values, 1.0 / (4.0 * np.pi), rtol=1e-12, atol=0.0), f.values
    assert abs(f.mean_cosine) < 1e-15
    u = np.linspace(0.0, 1.0, 101)
    assert np.allclose(f.sample_cos(u), 2.0 * u - 1.0, rtol=0.0, atol=1e-12)  # uniform in cos(theta)
    if scale >= 1e-300:  # (4 pi x the smallest subnormal is rounded to a subnormal: only the phase is exact)
        assert f.normalisation == pytest.approx(4.0 * np.pi * scale, rel=1e-12)


@pytest.mark.parametrize("g", [0.9, -0.4])
@pytest.mark.parametrize("scaling", ["2^1000", "2^-1000", "1e300", "1e-300", "max"])
def test_a_scaled_hg_table_gives_the_unscaled_phase_function(g, scaling):
    c, v = _hg_table(g, 801)
    scaled = {
        "2^1000": np.ldexp(v, 1000),
        "2^-1000": np.ldexp(v, -1000),
        "1e300": v * 1e300,
        "1e-300": v * 1e-300,
        "max": _to_max(v),
    }[scaling]
    ref, f = ph.Tabulated(c, v), ph.Tabulated(c, scaled)
    u = np.random.default_rng(7).random(20_000)
    x = np.linspace(-1.0, 1.0, 2001)
    if scaling.startswith("2^"):  # an exact factor: the same bits
        assert np.array_equal(f.values, ref.values)
        assert np.array_equal(f.sample_cos(u), ref.sample_cos(u))
        assert f.mean_cosine == ref.mean_cosine
    else:  # the table itself is rounded once by the factor
        assert np.allclose(f.values, ref.values, rtol=1e-12, atol=0.0)
        assert np.allclose(f.eval(x), ref.eval(x), rtol=1e-12, atol=1e-300)
        assert np.allclose(f.sample_cos(u), ref.sample_cos(u), rtol=0.0, atol=1e-12)
        assert f.mean_cosine == pytest.approx(ref.mean_cosine, rel=1e-12)
    # the normalisation reported is the factor times the unscaled one, or None past the float max
    expected = ref.normalisation / float(np.max(v)) * float(np.max(scaled))  # Python floats: inf, no warning
    if math.isfinite(expected):
        assert f.describe()["normalisation"] == pytest.approx(expected, rel=1e-12)
    else:
        assert f.normalisation == math.inf and f.describe()["normalisation"] is None


def test_the_schema_takes_values_up_to_the_float_max():
    c, v = _hg_table(0.6, 101)
    TabulatedPhaseSpec(cos_theta=c.tolist(), values=_to_max(v).tolist())


def _table(values, c):
    return {"type": "tabulated", "cos_theta": c.tolist(), "values": values.tolist()}


def test_scaled_tables_give_the_same_channel_through_algorithm_5():
    """The same seed: a table x 2^1000 gives the same bits; one scaled to the float max the same H0 to
    1e-9 (the table is rounded once; the paths are the same). Before, the latter lost every scattered path:
    H0 fell to the line of sight (-49 % here)."""
    c, v = _hg_table(0.6)
    h_ref, e_ref = _h0(_table(v, c), paths=20_000, seed=5)
    h_pow2, e_pow2 = _h0(_table(np.ldexp(v, 1000), c), paths=20_000, seed=5)
    assert (h_pow2, e_pow2) == (h_ref, e_ref)
    h_max, e_max = _h0(_table(_to_max(v), c), paths=20_000, seed=5)
    assert h_max == pytest.approx(h_ref, rel=1e-9) and e_max == pytest.approx(e_ref, rel=1e-6)
    # power: a slightly different table (HG 0.62 instead of 0.6) is far outside this tolerance
    h_other, _ = _h0(_table(_hg_table(0.62)[1], c), paths=20_000, seed=5)
    assert abs(h_other - h_ref) > 1e-4 * h_ref
