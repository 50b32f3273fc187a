"""The 4-luminaire office end to end, as a lighting and LiFi planner sees it (docs/tutorials/office-planner.md).

Komine & Nakagawa's office: a 5 x 5 x 3 m room (walls and ceiling 0.8, floor 0.3), four LED lamps
of 72 W and 10 031 lm (2 628 cd on axis, semi-angle 70 deg) at (1.25 | 3.75, 1.25 | 3.75, 3) m facing
down, 1 cm^2 photodiodes on the 0.85 m work plane every 0.25 m, a 1.5 x 2 m desk in the middle.
Three runs, each one `owcsim.simulate`:

1. light and signal: the four lamps carry one signal (one group); every reflection order until each
   point's illuminance and DC gain have a relative standard error of 1 %; total illuminance with U0
   over the desk and its 0.5 m surround (EN 12464-1), the SNR of the Komine receiver at 10 Mbit/s;
2. cells: each lamp its own LiFi cell (four groups); serving cell, SINR and rates at 20 MHz, the
   handover boundaries;
3. people holding their phones: the receivers tilted as sitting users hold them (Soltani et al. 2019),
   32 orientations per point, line of sight (exact): mean SNR and the outage probability at 10 Mbit/s.

Prints the figures the page quotes and draws its four figures into --out (docs/figures for the page).
Run: .venv/bin/python examples/office_planner.py --out docs/figures
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import owcsim
from owcsim import build
from owcsim.formats.cell_plots import plot_cells

#: The desk of the task area [m] (room coordinates on the 0.85 m plane) and its 0.5 m surround.
DESK = {"name": "desk", "grid": "plane", "min": [1.75, 1.5, 0.85], "max": [3.25, 3.5, 0.85]}
#: The whole work plane as a task area (no surround inside the room): the plane's own uniformity.
PLANE = {"name": "plane", "grid": "plane", "min": [0.0, 0.0, 0.85], "max": [5.0, 5.0, 0.85]}


def office(
    cells: bool = False, orientation: dict | None = None, fov_deg: float = 90.0, **simulation
) -> owcsim.SceneSpec:
    """The office scene; `cells`: each lamp its own group (a LiFi cell), else the four lamps one signal;
    `orientation`: the work plane's receivers held by people (schemas.orientation.OrientationSpec)."""
    room = build.box_room((5, 5, 3), walls=0.8, floor=0.3, ceiling=0.8)
    lamps = build.lamp_array(
        room,
        (2, 2),
        power=72.0,
        half_power_semi_angle_deg=70,
        luminous_output={"center_luminous_intensity": 2628.0},
    )
    groups = (
        [build.group(f"cell{k + 1}", [t]) for k, t in enumerate(lamps)] if cells else [build.group("ceiling", lamps)]
    )
    plane = build.work_plane(
        room,
        height=0.85,
        spacing=0.25,
        margin=0.125,
        area=1e-4,
        fov_deg=fov_deg,
        id_prefix="plane",
        orientation=orientation,
    )
    return build.scene(
        room,
        lamps,
        grids=[plane],
        groups=groups,
        link_budget={"responsivity": 0.53, "bit_rate": 10e6} if not cells else {"bandwidth": 20e6},
        name="Komine office" + (", four cells" if cells else ""),
        seed=1,
        **simulation,
    )


def light_and_signal(target: float) -> owcsim.Result:
    spec = office(target_rel_error=target).model_copy(
        update={"lighting": owcsim.schemas.lighting.LightingSpec(task_areas=[DESK, PLANE], surround_width=0.5)}
    )
    return owcsim.simulate(spec)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/office-planner"), help="folder of the figures")
    ap.add_argument("--target", type=float, default=0.01, help="relative standard error per point (run 1)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    t = time.perf_counter()
    light = light_and_signal(args.target)
    m = light.grid_maps()[0]
    print(
        f"1. light and signal: {m.shape[0]} x {m.shape[1]} points, every reflection order, "
        f"{light.run.paths_total:,} paths"
    )
    for area in light.lighting.areas:
        for part in ("task", "surround"):
            a = getattr(area, part)
            if a is None or not a.points:
                continue
            print(
                f"   {area.name} {part}: E_avg {a.illuminance_avg_lx:.0f} ± {a.illuminance_avg_lx_stderr:.0f} lx, "
                f"E_min {a.illuminance_min_lx:.0f} ± {a.illuminance_min_lx_stderr:.0f} lx, "
                f"U0 {a.uniformity_u0:.3f} ± {a.uniformity_u0_stderr:.3f}"
            )
    e, e_dir = np.asarray(m.values["illuminance_lx"]), np.asarray(m.values["illuminance_direct_lx"])
    print(f"   reflected share of the illuminance: {np.nanmean((e - e_dir) / e):.1%} on average")
    snr = np.asarray(m.values["snr_db"])
    print(f"   SNR at 10 Mbit/s: {np.nanmin(snr):.1f} to {np.nanmax(snr):.1f} dB")
    rel = np.asarray(m.values["dc_gain_rel_error"]) if "dc_gain_rel_error" in m.values else None
    if rel is not None:
        print(f"   worst point's relative error of H0: {np.nanmax(rel):.2%}")
    light.plot_map(
        "illuminance_lx", contours=[1300, 1400, 1500, 1600], path=args.out / "office-planner-illuminance.png"
    )
    light.plot_map("snr_db", path=args.out / "office-planner-snr.png")

    cells = owcsim.simulate(office(cells=True, target_rel_error=0.02))
    c = cells.cells
    serving = np.asarray(c.maps[0].serving_cell, float)
    shares = [float(np.mean(serving == k)) for k in range(len(c.cells))]
    print(f"2. cells {c.cells}: each serves {', '.join(f'{s:.0%}' for s in shares)} of the plane")
    sinr = np.asarray(c.maps[0].values["sinr_db"], float)
    shannon = np.asarray(c.maps[0].values["rate_shannon_bps"], float) / 1e6
    print(
        f"   SINR {np.nanmin(sinr):.1f} to {np.nanmax(sinr):.1f} dB, "
        f"Shannon rate {np.nanmin(shannon):.0f} to {np.nanmax(shannon):.0f} Mbit/s, "
        f"{len(c.maps[0].boundaries)} handover boundary segments"
    )
    plot_cells(cells, args.out / "office-planner-cells.png", quantity="sinr_db")

    tilted = owcsim.simulate(office(orientation={"model": "sitting", "samples": 32}, fov_deg=60, max_reflections=0))
    tm = tilted.grid_maps()[0]
    out = np.asarray(tm.values["outage_probability"], float)
    print(
        f"3. sitting users, 32 orientations per point: outage at 10 Mbit/s "
        f"{np.nanmin(out):.1%} to {np.nanmax(out):.1%}, "
        f"mean SNR {np.nanmin(np.asarray(tm.values['snr_mean_db'], float)):.1f} dB at the worst point"
    )
    tilted.plot_map("outage_probability", path=args.out / "office-planner-outage.png")
    print(f"   figures in {args.out} ({time.perf_counter() - t:.0f} s)")


if __name__ == "__main__":
    main()
