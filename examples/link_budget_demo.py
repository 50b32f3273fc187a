"""Worked example of docs/link-budget.md: Komine & Nakagawa 2004's room, line of sight only.

5 x 5 x 3 m room, 4 luminaires at (1.25|3.75, 1.25|3.75, 3) facing down, each 60 x 60 LEDs of
0.73 cd and 20 mW (semi-angle 70 deg); receivers 1 cm^2 facing up on the plane z = 0.85 m.
Prints the photometry, the received power, the noise terms, the SNR and BER at 10 Mbit/s, and
the signal / ISI split of a two-arrival CIR at 100 Mbit/s, one `name = value unit` per line.
The tests (tests/engine/test_link_budget.py) run this script and check each line by hand.

Run: .venv/bin/python examples/link_budget_demo.py
"""

from __future__ import annotations

import math

import numpy as np

from owcsim.engine.results.link_budget import (
    IsiSplit,
    LinkBudget,
    ber_ook,
    illuminance_los,
    isi_split,
    luminous_flux_from_intensity,
    max_bit_rate,
    noise_variances,
    power_dbm,
    received_power,
    snr,
    to_db,
)

LEDS = np.array([[1.25, 1.25, 3.0], [1.25, 3.75, 3.0], [3.75, 1.25, 3.0], [3.75, 3.75, 3.0]])
PLANE_Z = 0.85
N_LED, LED_CD, LED_W = 60 * 60, 0.73, 0.020
M = -math.log(2.0) / math.log(math.cos(math.radians(70.0)))
AREA, FOV_DEG = 1e-4, 85.0


def geometry(points):
    """cos_phi, cos_psi, d of every (luminaire, point): luminaires face down, receivers face up."""
    to = points[None, :, :] - LEDS[:, None, :]
    d = np.linalg.norm(to, axis=-1)
    cos = -to[..., 2] / d  # both normals are vertical, so cos_phi = cos_psi
    return cos, cos, d


def dc_gain(cos_phi, cos_psi, d):
    """LOS DC gain (m+1) A / (2 pi d^2) cos^m(phi) cos(psi), psi <= FOV (no filter, no concentrator)."""
    inside = cos_psi >= math.cos(math.radians(FOV_DEG))
    return np.where(inside, (M + 1) * AREA / (2 * math.pi * d**2) * cos_phi**M * cos_psi, 0.0)


def show(name, value, unit=""):
    print(f"{name} = {value:.6g} {unit}".rstrip())


def main() -> None:
    i0 = N_LED * LED_CD
    p_t = N_LED * LED_W
    show("lambertian_order", M)
    show("center_luminous_intensity", i0, "cd")
    show("luminous_flux", luminous_flux_from_intensity(i0, M), "lm")
    show("transmit_power", p_t, "W")

    named = {"center": (2.5, 2.5), "corner": (0.0, 0.0), "under_led": (1.25, 1.25)}
    pts = np.array([[x, y, PLANE_Z] for x, y in named.values()])
    e = illuminance_los(i0, M, *geometry(pts))
    for (name, _), lux in zip(named.items(), e):
        show(f"illuminance_{name}", lux, "lx")
    xs = np.linspace(0.0, 5.0, 101)
    grid = np.array([[x, y, PLANE_Z] for x in xs for y in xs])
    e_grid = illuminance_los(i0, M, *geometry(grid))
    show("illuminance_min", e_grid.min(), "lx")
    show("illuminance_max", e_grid.max(), "lx")
    show("illuminance_uniformity", e_grid.min() / e_grid.mean())

    p_r = received_power(np.full(4, p_t), dc_gain(*geometry(pts)))
    budget = LinkBudget(noise_bandwidth=10e6, bit_rate=10e6)  # Komine's receiver, B = R_b = 10 Mbit/s
    shot, thermal = noise_variances(budget, AREA, p_r)
    s = snr(budget, AREA, p_r)
    for k, name in enumerate(named):
        show(f"received_power_{name}", p_r[k], "W")
        show(f"received_power_{name}_dbm", power_dbm(p_r[k]), "dBm")
        show(f"shot_noise_{name}", shot[k], "A^2")
        show(f"thermal_noise_{name}", thermal[k], "A^2")
        show(f"snr_{name}_db", to_db(s[k]), "dB")
        show(f"ber_{name}", ber_ook(s[k]))

    # ISI at 100 Mbit/s: the centre's LOS power in bin 0 of a LOS-relative CIR (dt = 0.5 ns) plus an
    # echo of 20 % of it in bin 10, i.e. arriving 5 to 5.5 ns after the LOS.
    fast = LinkBudget(noise_bandwidth=100e6, bit_rate=100e6)
    dt, cir = 0.5e-9, np.zeros(40)
    cir[0], cir[10] = p_r[0], 0.2 * p_r[0]
    for rule in IsiSplit:
        p_sig, p_isi = isi_split(cir, dt, fast.bit_period, rule=rule)
        s_isi = snr(fast, AREA, p_sig, p_isi)
        show(f"{rule.value}_signal_fraction", p_sig / cir.sum())
        show(f"{rule.value}_isi_fraction", p_isi / cir.sum())
        show(f"{rule.value}_snr_100mbps_db", to_db(s_isi), "dB")
        show(f"{rule.value}_ber_100mbps", ber_ook(s_isi))
    t = dt * (np.arange(cir.size) + 0.5)
    mean = (cir * t).sum() / cir.sum()
    tau_rms = math.sqrt((cir * (t - mean) ** 2).sum() / cir.sum())
    show("rms_delay_spread", tau_rms, "s")
    show("max_bit_rate", max_bit_rate(tau_rms), "bit/s")


if __name__ == "__main__":
    main()
