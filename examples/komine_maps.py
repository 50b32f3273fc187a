"""Komine & Nakagawa 2004, figures of the 4-lamp room: illuminance, received power, RMS delay spread
and SNR over the work plane, as PNG heatmaps, from the Python API.

    .venv/bin/python examples/komine_maps.py --out out/komine            # every reflection order, 1 %
    .venv/bin/python examples/komine_maps.py --out out/komine --los      # line of sight only (Komine's maps)

Prints the min / mean / max / uniformity of each map.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import owcsim
from owcsim.formats.heatmap import heatmap_png
from owcsim.formats.maps import MapDecor, format_summary

SCENE = Path(__file__).with_name("komine_map.json")
FIGURES = ("illuminance_lx", "received_power_dbm", "rms_delay_spread_s", "snr_db")


def main(argv=None) -> list[Path]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/komine", help="folder for the PNG files")
    ap.add_argument("--los", action="store_true", help="line of sight only (as Komine's figures)")
    ap.add_argument("--spacing", type=float, help="grid step [m] (default 0.1: 50 x 50 points)")
    ap.add_argument("--target-rel-error", type=float, default=0.01, help="relative error of every point's H0")
    args = ap.parse_args(argv)
    doc = json.loads(SCENE.read_text())
    if args.spacing:
        doc["receiver_grids"][0]["spacing"] = args.spacing
    doc["simulation"] = {"max_reflections": 0} if args.los else {"target_rel_error": args.target_rel_error, "seed": 1}
    result = owcsim.simulate(doc)
    maps = result.grid_maps()
    print(format_summary(maps))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    decor = MapDecor.from_scene(owcsim.SceneSpec.model_validate(doc))
    return [heatmap_png(maps[0], q, decor, out / f"komine_{q}.png") for q in FIGURES]


if __name__ == "__main__":
    for path in main():
        print(f"wrote {path}")
