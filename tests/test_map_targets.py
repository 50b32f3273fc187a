"""benchmarks/map_targets.py: its two deterministic references are right, and the script prints every figure.

The references are checked against tests/reference_radiosity.py (written separately: one lamp, one
reflectance, FOV 90 deg, gathered by the same sub-points: equal to 1e-12), the closed-form gather against
the form factor of a differential area to a parallel rectangle at its corner (Howell's catalogue, C-11),
and the truncated recursion against the radiosity solve it converges to as k grows.
"""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import map_targets as mt  # noqa: E402

from tests.reference_radiosity import box_dc_gain  # noqa: E402


def _box(rho: float, fov: float = math.pi / 2) -> mt.Room:
    return mt.Room(
        (5.0, 5.0, 3.0),
        {"floor": rho, "ceiling": rho, "walls": rho},
        np.array([[2.5, 2.5, 3.0]]),
        np.array([[0.0, 0.0, -1.0]]),
        np.array([1.0]),
        np.array([1.0]),
        np.array([0.0, 0.0, 1.0]),
        fov,
        1e-4,
    )


RX = np.array([[1.0, 1.0, 0.0], [2.0, 3.0, 0.5]])


def test_radiosity_reference_equals_the_tests_reference_in_its_case():
    ours = mt.reference_dc_gain(mt.Reference("r", 1.25, 3, None, True, False), _box(0.5), RX)
    theirs = [
        box_dc_gain((5, 5, 3), [0.5], (2.5, 2.5, 3), (0, 0, -1), 1.0, p, (0, 0, 1), 1e-4, patch=1.25)[0][0] for p in RX
    ]
    assert np.all(np.isfinite(ours))
    np.testing.assert_allclose(ours, theirs, rtol=1e-12)
    # power: a reflectance 10 % off is seen
    off = mt.reference_dc_gain(mt.Reference("r", 1.25, 3, None, True, False), _box(0.55), RX)
    assert np.all(np.abs(off / theirs - 1) > 0.02)


def test_closed_form_gather_equals_the_corner_rectangle_form_factor():
    room = _box(0.5)
    pts, nrm, _, d_a, corners = mt.patches(room, 5.0, 1)  # one patch per face: the ceiling is patch 1
    c = 2.0  # the point 2 m below the ceiling, under its corner (0, 0)
    got = mt._to_receivers_exact(room, np.array([[0.0, 0.0, 3.0 - c]]), pts, nrm, d_a, corners)[0, 1] / room.area
    a = b = 5.0 / c
    expected = (
        a / math.sqrt(1 + a * a) * math.atan(b / math.sqrt(1 + a * a))
        + b / math.sqrt(1 + b * b) * math.atan(a / math.sqrt(1 + b * b))
    ) / (2 * math.pi)
    assert got == pytest.approx(expected, rel=1e-12)
    assert abs(got / (1.1 * expected) - 1) > 0.05  # power


def test_closed_form_gather_agrees_with_fine_sub_points_and_the_fov_band():
    """The exact gather with an 85 deg FOV against 12 x 12 sub-points per patch, at a point far from every face."""
    room = _box(0.5, math.radians(85))
    rx = np.array([[2.2, 2.9, 0.85]])
    pts, nrm, _, d_a, corners = mt.patches(room, 0.5, 12)
    exact = mt._to_receivers_exact(room, rx, pts, nrm, d_a, corners).sum()
    quad = mt._to_receivers(room, rx, pts, nrm, d_a).sum()
    assert exact == pytest.approx(quad, rel=2e-3)


def test_recursion_approaches_the_radiosity_solve():
    room = _box(0.5)
    full = mt.reference_dc_gain(mt.Reference("r", 1.0, 2, None, False, False), room, RX)
    k3 = mt.reference_dc_gain(mt.Reference("r", 1.0, 2, 3, False, False), room, RX)
    k30 = mt.reference_dc_gain(mt.Reference("r", 1.0, 2, 30, False, False), room, RX)
    assert np.all(k3 < full)  # orders above 3 left out
    np.testing.assert_allclose(k30, full, rtol=1e-6)  # 0.5^30


def test_grid_points_follow_the_engine_order():
    doc = mt.komine(3)
    p = mt.grid_points(doc)
    assert p.shape == (9, 3)
    np.testing.assert_allclose(p[1], [0.05, 2.5, 0.85])  # j runs fastest
    np.testing.assert_allclose(p[3], [2.5, 0.05, 0.85])


@pytest.mark.slow
def test_map_targets_quick_prints_every_case():
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "map_targets.py"), "--quick"],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    text = out.stdout
    for label in (
        "(a) 8 x 8",
        "(b) 8 x 8, line of sight",
        "(c) 12 x 12",
        "(d) exponent",
        "recursion k <= 3",
        "radiosity",
    ):
        assert label in text, text
    radiosity = [ln for ln in text.splitlines() if ln.strip().startswith("radiosity")]
    assert radiosity and all(abs(float(ln.split()[-2])) < 3 for ln in radiosity), text  # median % against owcsim
