"""A luminaire's own output and orientation (issue 22, item 9).

- Illuminance from a photometric file needed `luminous_output` by hand. A transmitter with a file and
  no `luminous_output` now lights with the file's own candela (IES: table x candela multiplier x
  ballast factor, in relative and absolute photometry; EULUMDAT: cd/klm x lamp flux / 1000); a given
  `luminous_output` wins. References: E = I(gamma) cos(psi) / d^2 with I from the numbers written in
  the file, at the file's own angles (where the interpolation is exact).
- `rotation_deg` turns C = 0 toward C = 90: counter-clockwise seen from behind the luminaire (from
  above a downlight, from below an uplight). Reference: a pattern I = I0 (1 + cos C) / 2 cos(gamma),
  whose line-of-sight gains toward four receivers are in the closed-form ratios 1 : 1/2 : 0 : 1/2.
"""

import base64
import math

import numpy as np
import pytest

from owcsim.api import simulate
from tests.scenes import room_doc

GAMMA = np.arange(0.0, 90.0 + 1e-9, 5.0)


def _b64(text: str) -> str:
    return base64.b64encode(text.encode()).decode("ascii")


def _ies(c_deg, candela, *, lamps=2, lumens=1800.0, multiplier=1.5, ballast=0.9) -> str:
    """An LM-63-2002 file, type C, `candela` (n_c, n_g) at GAMMA and `c_deg` (values written with repr)."""
    rows = [" ".join(repr(float(v)) for v in row) for row in np.atleast_2d(candela)]
    return (
        "\r\n".join(
            [
                "IESNA:LM-63-2002",
                "[TEST] owcsim item 9",
                "TILT=NONE",
                f"{lamps} {lumens:g} {multiplier:g} {len(GAMMA)} {len(c_deg)} 1 2 0.1 0.1 0.02",
                f"{ballast:g} 1.0 20",
                " ".join(f"{g:g}" for g in GAMMA),
                " ".join(f"{c:g}" for c in c_deg),
                *rows,
            ]
        )
        + "\r\n"
    )


def _ldt(cd_per_klm, *, lamp_flux=2000.0, lor=80.0) -> str:
    """A rotationally symmetric EULUMDAT file (Isym 1), intensities [cd/klm] at GAMMA."""
    lines = ["owcsim item 9", "1", "1", "1", "0", str(len(GAMMA)), "5", "report", "lum", "T-9", "t.ldt", "2026"]
    lines += ["600", "600", "80", "580", "580", "0", "0", "0", "0", "100", f"{lor:g}", "1", "0", "1", "1", "LED"]
    lines += [f"{lamp_flux:g}", "4000", "80", "30"] + ["0.5"] * 10 + ["0"] + [f"{g:g}" for g in GAMMA]
    lines += [repr(float(v)) for v in cd_per_klm]
    return "\n".join(lines) + "\n"


def _scene(text: str, fmt: str, receivers, *, aim=(0, 0, -1), tx=(5.0, 5.0, 3.0), rotation_deg=0.0, output=None):
    doc = room_doc(size=(10.0, 10.0, 3.0), tx=tx, tx_normal=aim, max_reflections=0, paths=64)
    t = {
        "id": "lum",
        "position": list(tx),
        "normal": list(aim),
        "photometry": {"data_base64": _b64(text), "format": fmt, "rotation_deg": rotation_deg},
    }
    if output is not None:
        t["luminous_output"] = output
    doc["transmitters"] = [t]
    doc["receivers"] = [
        {"id": f"r{k}", "position": list(p), "normal": list(n), "area": 1e-4, "fov_deg": 90.0}
        for k, (p, n) in enumerate(receivers)
    ]
    return doc


# Receivers on the floor of a 10 x 10 x 3 m room, 3 m below a ceiling downlight at (5, 5, 3), at the table's
# angles gamma = 0, 30, 45 deg.
FLOOR = [((5.0 + 3.0 * math.tan(math.radians(g)), 5.0, 0.0), (0, 0, 1)) for g in (0.0, 30.0, 45.0)]


def _direct(intensity_at, receivers, tx=(5.0, 5.0, 3.0)):
    """E = I(gamma) cos(psi) / d^2 [lx] for a downlight at tx (gamma = psi for receivers facing up)."""
    out = []
    for p, _ in receivers:
        v = np.subtract(p, tx)
        d = float(np.linalg.norm(v))
        cos = -v[2] / d
        out.append(intensity_at(math.degrees(math.acos(cos))) * cos / d**2)
    return np.array(out)


def _illuminance(doc):
    return np.array([link.illuminance_lx for link in simulate(doc).links])


def test_ies_file_lights_with_its_own_candela():
    cd = 400.0 * np.cos(np.radians(GAMMA))
    cd[-1] = 0.0  # cos(90 deg) written as 0
    e = _illuminance(_scene(_ies([0.0], cd), "ies", FLOOR))
    expected = _direct(lambda g: 400.0 * math.cos(math.radians(g)) * 1.5 * 0.9, FLOOR)  # x multiplier x ballast
    np.testing.assert_allclose(e, expected, rtol=1e-9)
    assert not np.allclose(e, expected / 0.9, rtol=1e-3)  # the ballast factor is applied
    # absolute photometry (lumens -1): the candela are the luminaire's, the same illuminance
    absolute = _illuminance(_scene(_ies([0.0], cd, lumens=-1.0), "ies", FLOOR))
    np.testing.assert_allclose(absolute, e, rtol=1e-12)


def test_ldt_file_lights_with_its_intensities_times_the_lamp_flux():
    per_klm = 300.0 * np.cos(np.radians(GAMMA))
    per_klm[-1] = 0.0
    e = _illuminance(_scene(_ldt(per_klm), "ldt", FLOOR))
    expected = _direct(lambda g: 300.0 * math.cos(math.radians(g)) * 2000.0 / 1000.0, FLOOR)
    np.testing.assert_allclose(e, expected, rtol=1e-9)


def _table_flux(cd: np.ndarray) -> float:
    """int I dOmega of the table interpolated linearly in gamma (midpoint rule, 200 000 points)."""
    g = (np.arange(200_000) + 0.5) * (math.pi / 2) / 200_000
    return float(2 * math.pi * np.sum(np.interp(g, np.radians(GAMMA), cd) * np.sin(g)) * (math.pi / 2) / 200_000)


@pytest.mark.parametrize("output", [{"luminous_flux": 1000.0}, {"center_luminous_intensity": 250.0}])
def test_a_given_luminous_output_wins_over_the_file(output):
    cd = 400.0 * np.cos(np.radians(GAMMA))
    cd[-1] = 0.0
    e = _illuminance(_scene(_ies([0.0], cd), "ies", FLOOR, output=output))
    if "luminous_flux" in output:  # the file's shape, scaled to the given flux
        shape = _direct(lambda g: float(np.interp(g, GAMMA, cd)), FLOOR) / _table_flux(cd)
        np.testing.assert_allclose(e, 1000.0 * shape, rtol=1e-6)
    else:  # the file's shape, scaled to the given intensity on the axis
        np.testing.assert_allclose(e, _direct(lambda g: 250.0 * math.cos(math.radians(g)), FLOOR), rtol=1e-9)


# ----------------------------------------------------------------------------- the sense of rotation_deg
C_FULL = np.arange(0.0, 360.0, 15.0)
#: I = 1000 (1 + cos C) / 2 cos(gamma): brightest toward C = 0, dark toward C = 180.
ONE_SIDED = np.outer(500.0 * (1.0 + np.cos(np.radians(C_FULL))), np.cos(np.radians(GAMMA)))
ONE_SIDED[:, -1] = 0.0


def _four_gains(aim, tx, z_rx, rotation_deg):
    """LOS gains of receivers at +x, +y, -x, -y of the luminaire (45 deg off its axis), facing it."""
    rx_normal = (0, 0, 1) if aim[2] < 0 else (0, 0, -1)
    offsets = [(1, 0), (0, 1), (-1, 0), (0, -1)]
    h = abs(tx[2] - z_rx)
    receivers = [((tx[0] + h * a, tx[1] + h * b, z_rx), rx_normal) for a, b in offsets]
    doc = _scene(_ies(C_FULL, ONE_SIDED), "ies", receivers, aim=aim, tx=tx, rotation_deg=rotation_deg)
    g = np.array([link.los_gain for link in simulate(doc).links])
    return g / g.max()


@pytest.mark.parametrize(
    "rotation_deg, brightest",
    [(0.0, "+x"), (90.0, "+y"), (-90.0, "-y"), (180.0, "-x")],
)
def test_rotation_turns_c0_counter_clockwise_seen_from_above_a_downlight(rotation_deg, brightest):
    """Aimed down: default C = 0 along +x; +90 deg (counter-clockwise seen from above) puts it along +y."""
    gains = _four_gains((0, 0, -1), (5.0, 5.0, 3.0), 0.0, rotation_deg)
    order = ["+x", "+y", "-x", "-y"]
    k = order.index(brightest)
    np.testing.assert_allclose(np.roll(gains, -k), [1.0, 0.5, 0.0, 0.5], atol=1e-9)  # then 90, 180, 270 deg ccw


def test_rotation_turns_c0_counter_clockwise_seen_from_below_an_uplight():
    """Aimed up (from behind = from below): C = 90 is e_C0 x aim = +x x +z = -y, and +90 deg turns C = 0 to -y."""
    gains = _four_gains((0, 0, 1), (5.0, 5.0, 0.0), 3.0, 90.0)
    np.testing.assert_allclose(gains, [0.5, 0.0, 0.5, 1.0], atol=1e-9)  # +x, +y, -x, -y
