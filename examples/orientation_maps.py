"""Maps of a LiFi office under random device orientation (docs/orientation.md).

Komine's 5 x 5 x 3 m office with four access points of 1 W optical each (100 Mbit/s, 60 deg FOV
receivers at desk height), in line of sight: the SNR of a receiver facing up, and the mean SNR and
outage probability of one held by a walking user (Soltani et al. 2019), side by side in room
coordinates. Prints the figures the page quotes and writes orientation-outage.png to --out.

Run: .venv/bin/python examples/orientation_maps.py --out docs/figures [--spacing 0.25] [--samples 32]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import owcsim  # noqa: E402

HERE = Path(__file__).resolve().parent


def office(spacing: float, samples: int, model: str = "walking") -> dict:
    doc = json.loads((HERE / "komine_map.json").read_text())
    for t in doc["transmitters"]:
        t["power"] = 1.0
    doc["link_budget"]["bit_rate"] = 1e8
    doc["receiver_grids"][0].update(spacing=spacing, fov_deg=60, orientation={"model": model, "samples": samples})
    doc["simulation"] = {"max_reflections": 0}
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--spacing", type=float, default=0.25)
    ap.add_argument("--samples", type=int, default=32)
    args = ap.parse_args()
    result = owcsim.simulate(office(args.spacing, args.samples))
    m = result.maps[0]
    nu, nv = m.shape
    x = m.origin[0] + m.spacing * np.arange(nu)
    y = m.origin[1] + m.spacing * np.arange(nv)
    panels = [
        ("snr_db", "SNR facing up [dB]"),
        ("snr_mean_db", "mean SNR, walking user [dB]"),
        ("outage_probability", f"outage P(SNR < {result.orientation[0].outage_snr_db:.1f} dB)"),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), constrained_layout=True)
    for ax, (q, title) in zip(axes, panels):
        values = np.array(m.values[q], float)  # [i][j]: i along x, j along y
        im = ax.pcolormesh(
            x, y, values.T, shading="nearest", cmap="viridis_r" if q == "outage_probability" else "viridis"
        )
        for t in result.scene.transmitters:
            ax.plot(t.position[0], t.position[1], "w+", ms=10, mew=2)
        ax.set(title=title, xlabel="x [m]", ylabel="y [m]", aspect="equal")
        fig.colorbar(im, ax=ax)
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / "orientation-outage.png", dpi=90)
    outage = np.array(m.values["outage_probability"], float)
    up = np.array(m.values["snr_db"], float)
    print(f"{nu} x {nv} points x {args.samples} orientations, {len(result.receivers)} receivers")
    print(
        f"facing up: SNR below the threshold at {np.mean(up < result.orientation[0].outage_snr_db):.0%} of the points"
    )
    print(
        f"walking user: outage above 10 % at {np.mean(outage > 0.1):.0%} of the points, mean outage {outage.mean():.3f}"
    )
    print(f"wrote {args.out / 'orientation-outage.png'}")


if __name__ == "__main__":
    main()
