"""A fire at the end of a corridor: the smoke fills the ceiling layer while a person walks out (docs/fire-timeline.md).

An 8 x 2.5 x 3 m corridor lit by four luminaires on its centre line (1 W optical each, one signal: the
transmitter group "ceiling"), a fire at its x = 8 m end. The smoke is built analytically on a 0.5 m grid
(16 x 5 x 6 cells): a ceiling layer that spreads from the fire at 0.1 m/s and deepens by 1.2 cm/s from
0.2 m, its extinction rising linearly to 2 1/m at 120 s (albedo 0.5, Henyey-Greenstein g = 0.6). A
receiver at 0.85 m (1 cm^2, 60 deg FOV, facing up) is carried from near the fire (x = 7.5 m) to the far
end (x = 0.5 m) at 0.06 m/s. The timeline evaluates the channel every 10 s from 0 to 120 s, with an
outage at a BER of OOK-NRZ above 1e-6 at 10 Mbit/s. Prints the figures the page quotes and writes
fire-timeline.png (H0 and BER against time with the outage bands) to --out.

Run: .venv/bin/python examples/fire_timeline.py --out docs/figures
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

import owcsim  # noqa: E402

SIZE = (8.0, 2.5, 3.0)
SHAPE = (16, 5, 6)
FRAME_TIMES = np.arange(0.0, 121.0, 10.0)


def smoke(t: float) -> np.ndarray:
    """Extinction sigma_t [1/m] of every cell (nx, ny, nz) at time t [s]: the ceiling layer."""
    x = (np.arange(SHAPE[0]) + 0.5) * SIZE[0] / SHAPE[0]
    z = (np.arange(SHAPE[2]) + 0.5) * SIZE[2] / SHAPE[2]
    front = SIZE[0] - 0.1 * t  # the ceiling jet's front [m]
    depth = 0.2 + 0.012 * t  # the layer's depth below the ceiling [m]
    inside = (x[:, None, None] >= front) & (z[None, None, :] >= SIZE[2] - depth)
    return np.broadcast_to(np.where(inside, 2.0 * t / 120.0, 0.0), SHAPE)


def corridor(paths: int) -> dict:
    lamps = [
        {"id": f"lamp{i + 1}", "position": [x, 1.25, 3.0], "normal": [0, 0, -1], "lambertian_order": 1, "power": 1.0}
        for i, x in enumerate((1.0, 3.0, 5.0, 7.0))
    ]
    sigma = [smoke(t).ravel() for t in FRAME_TIMES]
    return {
        "name": "corridor fire",
        "room": {"size": list(SIZE), "reflectance": {"floor": 0.3, "ceiling": 0.7, "walls": 0.6}},
        "transmitters": lamps,
        "transmitter_groups": [{"name": "ceiling", "transmitters": [lamp["id"] for lamp in lamps]}],
        "receivers": [
            {"id": "walker", "position": [7.5, 1.25, 0.85], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 60}
        ],
        "link_budget": {"bit_rate": 5e7},
        "simulation": {
            "algorithm": 5,
            "max_reflections": 1,
            "max_scattering": 2,
            "time_bin_s": 1e-9,
            "t_max_s": 6e-8,
            "paths": paths,
            "seed": 26,
        },
        "timeline": {
            "frames": {
                "type": "inline",
                "times": FRAME_TIMES.tolist(),
                "min": [0.0, 0.0, 0.0],
                "max": list(SIZE),
                "shape": list(SHAPE),
                "sigma_a": [(0.5 * s).tolist() for s in sigma],
                "sigma_s": [(0.5 * s).tolist() for s in sigma],
                "phase": {"type": "hg", "g": 0.6},
            },
            "trajectories": [
                {"device": "walker", "waypoints": [[7.5, 1.25, 0.85], [0.5, 1.25, 0.85]], "speed_m_s": 0.06}
            ],
            "outage": {"quantity": "ber", "threshold": 1e-6},
        },
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--paths", type=int, default=4_000, help="paths per time")
    args = ap.parse_args()
    result = owcsim.simulate(corridor(args.paths))
    tl = result.timeline
    assert tl is not None
    link = tl.link("ceiling", "walker")
    print(f"{len(tl.times_s)} times, {tl.method} runs, {args.paths} paths each")
    for t, h, se, ber in zip(tl.times_s, link.dc_gain, link.dc_gain_stderr, link.ber or []):
        print(f"t = {t:5.1f} s: H0 = {h:.3e} ± {se:.1e}, BER = {ber:.1e}")
    for o in link.outages:
        end = "the end" if o.end_s is None else f"{o.end_s:.1f} s"
        print(f"outage from {o.start_s:.1f} s to {end}" + (" (uncertain)" if o.uncertain else ""))
    first = link.time_to_first_outage_s
    print("no outage" if first is None else f"time to first outage: {first:.1f} s")
    args.out.mkdir(parents=True, exist_ok=True)
    result.plot_timeline(args.out / "fire-timeline.png")
    print(f"wrote {args.out / 'fire-timeline.png'}")


if __name__ == "__main__":
    main()
