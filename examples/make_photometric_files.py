"""Write the example photometric files (synthetic luminaires, not any manufacturer's data).

- `downlight_batwing.ies` (IES LM-63-2002): a recessed LED office luminaire, 3600 lm module, ~3060 lm out,
  quadrant symmetric (C 0..90), a batwing distribution that peaks near gamma = 35 deg and
  is slightly wider across the C90 plane than along C0, nothing above the ceiling
  (gamma 0..90 in 2.5 deg steps).
- `pendant_direct_indirect.ldt` (EULUMDAT): a linear suspended luminaire, 2 x 2200 lm lamps,
  LOR 92 %, symmetric about the C0-C180 plane (Isym 2, C every 15 deg), 70 % of the light
  downward in a cos^1.5 lobe widened across the luminaire, 30 % upward (gamma 0..180 in
  5 deg steps): it lights the ceiling too.

Run: .venv/bin/python examples/make_photometric_files.py  (rewrites the two files here)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _rows(values, per_line=10):
    values = [f"{v:.1f}" for v in values]
    return "\n".join(" ".join(values[k : k + per_line]) for k in range(0, len(values), per_line))


def batwing_candela(gamma_deg: np.ndarray, c_deg: np.ndarray) -> np.ndarray:
    """I(gamma, C) [cd] of the downlight, (n_c, n_g)."""
    g, c = np.meshgrid(np.radians(gamma_deg), np.radians(c_deg))
    spread = 1.0 + 0.12 * np.sin(c) ** 2  # a little wider across the luminaire (C90)
    x = g / spread
    lobe = np.cos(np.minimum(x, np.pi / 2)) ** 1.2 * (1.0 + 1.4 * np.sin(np.minimum(x, np.pi / 2)) ** 2)
    cutoff = np.clip((np.radians(88.0) - g) / np.radians(8.0), 0.0, 1.0)  # cut-off near the ceiling plane
    return 606.0 * lobe * cutoff  # luminaire flux ~3060 lm: 85 % of the lamp lumens


def write_ies(path: Path) -> None:
    gamma = np.arange(0.0, 90.01, 2.5)
    c = np.arange(0.0, 90.01, 15.0)
    cd = batwing_candela(gamma, c)
    lines = [
        "IESNA:LM-63-2002",
        "[TEST] OWCSIM-EX-001 (synthetic)",
        "[TESTLAB] owcsim examples",
        "[ISSUEDATE] 2026-12-01",
        "[MANUFAC] owcsim (fictitious luminaire)",
        "[LUMCAT] OW-DL-600-BW",
        "[LUMINAIRE] recessed LED downlight 600 x 600, batwing optic",
        "[LAMP] LED module 3600 lm",
        "[OTHER] written by examples/make_photometric_files.py",
        "TILT=NONE",
        # lamps, lm/lamp, multiplier, n vertical, n horizontal, type C, metres, width, length, height
        f"1 3600 1.0 {len(gamma)} {len(c)} 1 2 0.6 0.6 0.08",
        "1.0 1.0 34",  # ballast factor, file generation type (2019) / future use, input watts
        _rows(gamma),
        _rows(c),
    ]
    lines += [_rows(row) for row in cd]
    path.write_text("\r\n".join(lines) + "\r\n", encoding="ascii")


def pendant_cd_per_klm(gamma_deg: np.ndarray, c_deg: np.ndarray) -> np.ndarray:
    """I(gamma, C) [cd/klm] of the pendant, (n_c, n_g), C planes 0..180."""
    g, c = np.meshgrid(np.radians(gamma_deg), np.radians(c_deg))
    across = np.abs(np.sin(c))  # 1 across the luminaire (C90), 0 along it (C0/C180)
    down = np.where(g < np.pi / 2, np.cos(np.minimum(g, np.pi / 2)) ** (1.5 - 0.6 * across), 0.0)
    up = np.where(g > np.pi / 2, np.abs(np.cos(g)) ** 1.0, 0.0)
    return 222.6 * down + 81.3 * up  # integrates to ~LOR x 1000 lm


def write_ldt(path: Path) -> None:
    mc, dc, ng, dg = 24, 15.0, 37, 5.0
    c_all = np.arange(mc) * dc
    gamma = np.arange(ng) * dg
    stored = pendant_cd_per_klm(gamma, c_all[: mc // 2 + 1])  # Isym 2: C0 .. C180
    lines = [
        "owcsim examples (fictitious manufacturer)",
        "2",
        "2",
        str(mc),
        f"{dc:g}",
        str(ng),
        f"{dg:g}",
        "OWCSIM-EX-002 (synthetic)",
        "Linear pendant, direct/indirect",
        "OW-PD-1500-DI",
        "pendant_direct_indirect.ldt",
        "2026-12-01 / owcsim",
        "1500",
        "60",
        "50",
        "1480",
        "50",
        "0",
        "0",
        "0",
        "0",
        "70",
        "92",
        "1.0",
        "0",
        "1",
        "2",
        "LED 2 x 2200 lm",
        "4400",
        "4000 K",
        "1B",
        "38",
    ]
    lines += ["0.45", "0.52", "0.58", "0.63", "0.69", "0.73", "0.77", "0.80", "0.84", "0.86"]  # direct ratios
    lines += [f"{c:g}" for c in c_all] + [f"{g:g}" for g in gamma]
    lines += [f"{v:.1f}" for v in stored.ravel()]
    path.write_text("\r\n".join(lines) + "\r\n", encoding="latin-1")


if __name__ == "__main__":
    write_ies(HERE / "downlight_batwing.ies")
    write_ldt(HERE / "pendant_direct_indirect.ldt")
    print("wrote downlight_batwing.ies and pendant_direct_indirect.ldt")
