"""A white LED in a painted room seen by a silicon photodiode: gains and illuminance per band and combined.

The scene (5 x 5 x 3 m): a 3 W (optical) white LED at the ceiling centre, Lambertian (m = 1);
walls in a sage-green paint, a white ceiling, a light wood floor; a silicon PIN photodiode
(1 cm^2, FOV 70 deg) on a desk at (1.2, 1.5, 0.8). Eight bands of 50 nm over 380-780 nm.

- The LED's spectrum is an analytic model written here: a blue InGaN chip (Gaussian, peak
  452 nm, FWHM 22 nm) plus a YAG:Ce phosphor (a skewed Gaussian, peak 560 nm, FWHM ~120 nm,
  wider on its red side); the chip/phosphor ratio gives a cool white.
- The green paint is a table written here (a reflectance bump at 530 nm over a grey base); the
  ceiling and floor use owcsim's `white_paint` and `light_wood` tables, the photodiode its
  `silicon_pin` responsivity (docs/spectra.md says what these models are).

Prints, per band and combined: optical gain H [-], electrical gain G [A/W] (photocurrent per watt
emitted), illuminance [lx] on the photodiode's plane (all reflection orders), and the direct-only
illuminance for comparison; the photocurrent for the LED's 3 W.

Run: .venv/bin/python examples/white_led_room.py [--paths 200000]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from owcsim.engine.run.simulate import simulate
from owcsim.schemas import SceneSpec

NM = 1e-9


def led_spd(lam: np.ndarray) -> np.ndarray:
    """Relative spectral power of a cool-white phosphor LED (this example's own model)."""
    chip = np.exp(-0.5 * ((lam - 452 * NM) / (22 * NM / 2.3548)) ** 2)
    width = np.where(lam < 560 * NM, 45 * NM, 62 * NM)  # the phosphor tails off more slowly toward the red
    phosphor = np.exp(-0.5 * ((lam - 560 * NM) / width) ** 2)
    return 1.6 * chip + phosphor


def green_paint(lam: np.ndarray) -> np.ndarray:
    """Reflectance of a sage-green wall paint (this example's own table)."""
    bump = np.exp(-0.5 * ((lam - 530 * NM) / (45 * NM)) ** 2)
    return 0.18 + 0.32 * bump + 0.25 / (1 + np.exp(-(lam - 700 * NM) / (20 * NM)))


def scene(paths: int) -> SceneSpec:
    lam = np.arange(370, 791, 2.0) * NM
    doc = {
        "name": "white LED, painted room, silicon photodiode",
        "room": {
            "size": [5.0, 5.0, 3.0],
            "reflectance": {
                "ceiling": {"type": "spectral", "reflectance": {"type": "named", "name": "white_paint"}},
                "floor": {"type": "spectral", "reflectance": {"type": "named", "name": "light_wood"}},
                "walls": {
                    "type": "spectral",
                    "reflectance": {"type": "table", "wavelengths": lam.tolist(), "values": green_paint(lam).tolist()},
                },
            },
        },
        "transmitters": [
            {
                "id": "led",
                "position": [2.5, 2.5, 3.0],
                "normal": [0, 0, -1],
                "lambertian_order": 1,
                "power": 3.0,
                "spectrum": {"type": "table", "wavelengths": lam.tolist(), "values": led_spd(lam).tolist()},
            }
        ],
        "receivers": [
            {
                "id": "pd",
                "position": [1.2, 1.5, 0.8],
                "normal": [0, 0, 1],
                "area": 1e-4,
                "fov_deg": 70,
                "responsivity": {"type": "named", "name": "silicon_pin"},
            }
        ],
        "spectral": {"band_edges": (np.arange(380, 781, 50) * NM).tolist()},
        "simulation": {"algorithm": 1, "max_reflections": 6, "paths": paths, "seed": 1, "t_max_s": 1.2e-7},
    }
    return SceneSpec.model_validate(doc)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=200_000)
    args = ap.parse_args(argv)
    spec = scene(args.paths)
    res = simulate(spec)
    res = res if isinstance(res, dict) else json.loads(res.model_dump_json())  # the result document
    sp = res["spectral"]
    link, tx = sp["links"][0], sp["transmitters"][0]
    power = spec.transmitters[0].power
    print(f"{spec.name}: {args.paths} paths, K = {spec.simulation.max_reflections}")
    print(
        f"LED: {power:g} W, luminous efficacy {tx['luminous_efficacy_lm_per_w']:.1f} lm/W, "
        f"flux {tx['luminous_flux_lm']:.0f} lm"
    )
    print(f"{'band [nm]':>11s} {'power':>6s}  {'H [-]':^20s} {'G [A/W]':>10s} {'E [lx]':>7s}")
    for b, band in enumerate(sp["bands"]):
        print(
            f"{band['lower_m'] / NM:4.0f}-{band['upper_m'] / NM:<6.0f} {tx['band_power_fraction'][b]:6.1%}  "
            f"{link['dc_gain_by_band'][b]:.4e} ± {link['dc_gain_by_band_stderr'][b]:.1e} "
            f"{link['electrical_gain_by_band_a_per_w'][b]:10.3e} {link['illuminance_by_band_lx'][b]:7.2f}"
        )
    print(
        f"{'combined':11s} {'100%':>6s}  {link['optical_gain']:.4e} ± {link['optical_gain_stderr']:.1e} "
        f"{link['electrical_gain_a_per_w']:10.3e} {link['illuminance_lx']:7.2f}"
    )
    current_se = link["electrical_gain_a_per_w_stderr"] * power
    print(
        f"photocurrent {link['photocurrent_a'] * 1e6:.3f} ± {current_se * 1e6:.1g} uA; "
        f"illuminance {link['illuminance_lx']:.2f} ± {link['illuminance_lx_stderr']:.1g} lx, of which direct "
        f"{link['illuminance_direct_lx']:.2f} lx"
    )
    print(
        f"rms delay spread: optical {res['links'][0]['rms_delay_spread_s'] * 1e9:.2f} ns, electrical "
        f"{link['electrical_rms_delay_spread_s'] * 1e9:.2f} ns"
    )


if __name__ == "__main__":
    main()
