"""The spectral and Mie examples run (small path counts) and print what their docstrings promise."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(script: str, *args: str) -> str:
    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / script), *args], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def test_white_led_room_prints_bands_and_combined():
    text = _run("white_led_room.py", "--paths", "3000")
    rows = [line for line in text.splitlines() if re.match(r"\s*\d{3}-\d{3}\s", line)]
    assert len(rows) == 8  # one line per 50 nm band over 380-780 nm
    combined = next(line for line in text.splitlines() if line.strip().startswith("combined"))
    h, se, g, e_v = (float(x) for x in combined.replace("±", " ").split()[2:6])
    assert 0 < se < 0.05 * h and g > 0 and e_v > 0
    total, direct = (
        float(x) for x in re.search(r"illuminance ([\d.]+) ± \S+ lx, of which direct ([\d.]+) lx", text).groups()
    )
    assert direct < total  # reflections add light
    # per-band illuminances add up to the combined one (printed to 0.01 lx)
    assert sum(float(r.split()[-1]) for r in rows) == pytest.approx(e_v, abs=0.06)


def test_soot_room_prints_the_derived_optics_and_plots(tmp_path):
    text = _run("soot_room.py", "--paths", "600", "--out", str(tmp_path))
    assert len(re.findall(r"visibility = [\d.]+ m", text)) == 2
    assert len(re.findall(r"two-HG fit: ", text)) == 2
    assert (tmp_path / "soot_room_cir.png").stat().st_size > 10_000
