"""The office fire of FDS 6.9.1, read with fdsreader: four luminaires, a walk to the door (docs/fire-timeline.md).

The smoke is real fire-simulation output: a 250 kW propane fire (soot yield 0.05) in a 6 x 4 x 3 m office,
its soot extinction coefficient K written by FDS every 5 s on the room's 0.2 m cells (EXT_3D_CELL, 19
frames, 0 to 90 s; the data's README is in ../shared/data/fds). K at 632.8 nm becomes sigma_t; the albedo
0.25 and a Henyey-Greenstein phase g = 0.7 are given (soot's albedo is small; see docs/fds-input.md for the
Mie alternative). Four 1 W luminaires on the ceiling form one signal (the group "ceiling"); the FDS desk is
furniture. A receiver (1 cm^2, 60 deg FOV, facing up) at 0.85 m is carried from beside the desk to the
door at 0.04 m/s; a second one lies on the desk. Outage: BER of OOK-NRZ above 1e-6 at 50 Mbit/s. Prints
the figures the page quotes and writes office-fire-timeline.png to --out.

Run: .venv/bin/python examples/office_fire_timeline.py --out docs/figures
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import owcsim  # noqa: E402

REPO = Path(__file__).resolve().parent.parent


def fds_case() -> Path:
    """The office_fire case: $OWCSIM_FDS_DATA, else ../shared/data/fds beside the repository, else /work/shared."""
    for root in (os.environ.get("OWCSIM_FDS_DATA"), REPO.parent / "shared" / "data" / "fds", "/work/shared/data/fds"):
        if root and (Path(root) / "office_fire" / "office_fire.smv").is_file():
            return Path(root) / "office_fire"
    raise SystemExit("the FDS office_fire case is not here: set OWCSIM_FDS_DATA to the folder holding office_fire/")


def office(case: Path, paths: int) -> dict:
    lamps = [
        {"id": f"lamp{i + 1}", "position": [x, y, 3.0], "normal": [0, 0, -1], "lambertian_order": 1, "power": 1.0}
        for i, (x, y) in enumerate(((1.5, 1.0), (4.5, 1.0), (1.5, 3.0), (4.5, 3.0)))
    ]
    return {
        "name": "office fire (FDS)",
        "room": {"size": [6.0, 4.0, 3.0], "reflectance": {"floor": 0.3, "ceiling": 0.7, "walls": 0.6}},
        "furniture": [{"name": "desk", "min": [3.0, 0.0, 0.6], "max": [4.2, 0.8, 0.8], "reflectance": 0.5}],
        "transmitters": lamps,
        "transmitter_groups": [{"name": "ceiling", "transmitters": [lamp["id"] for lamp in lamps]}],
        "receivers": [
            {"id": "walker", "position": [2.5, 1.2, 0.85], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 60},
            {"id": "desk", "position": [3.6, 0.4, 0.81], "normal": [0, 0, 1], "area": 1e-4, "fov_deg": 60},
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
                "type": "fds",
                "path": str(case),
                "slice_id": "EXT_3D_CELL",
                "albedo": 0.25,
                "phase": {"type": "hg", "g": 0.7},
                "origin": [0.0, 0.0, 0.0],
            },
            "trajectories": [
                {"device": "walker", "waypoints": [[2.5, 1.2, 0.85], [5.6, 1.9, 0.85]], "speed_m_s": 0.04}
            ],
            "outage": {"quantity": "ber", "threshold": 1e-6},
        },
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--paths", type=int, default=4_000, help="paths per time")
    args = ap.parse_args()
    case = fds_case()
    result = owcsim.simulate(office(case, args.paths))
    tl = result.timeline
    assert tl is not None and tl.frames_report is not None
    print(tl.frames_report.text().replace(str(case.parent) + "/", ""))  # the case's folder differs between machines
    print(f"{len(tl.times_s)} times, {tl.method} runs, {args.paths} paths each")
    for rx in ("walker", "desk"):
        link = tl.link("ceiling", rx)
        for t, h, se, ber in list(zip(tl.times_s, link.dc_gain, link.dc_gain_stderr, link.ber or []))[::3]:
            print(f"{rx} t = {t:4.1f} s: H0 = {h:.3e} ± {se:.1e}, BER = {ber:.1e}")
        for o in link.outages:
            end = "the end" if o.end_s is None else f"{o.end_s:.1f} s"
            print(f"{rx}: outage from {o.start_s:.1f} s to {end}" + (" (uncertain)" if o.uncertain else ""))
        first = link.time_to_first_outage_s
        print(f"{rx}: " + ("no outage" if first is None else f"time to first outage {first:.1f} s"))
    args.out.mkdir(parents=True, exist_ok=True)
    result.plot_timeline(args.out / "office-fire-timeline.png")
    print(f"wrote {args.out / 'office-fire-timeline.png'}")


if __name__ == "__main__":
    main()
