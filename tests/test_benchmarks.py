"""The benchmark scripts whose figures the README and docs print still run and print them.

Timings are not asserted (they belong to the scripts' own comparisons in one run); what is asserted is
that every figure is printed, and what must hold whatever the host: ratios and costs in their physical
ranges, and the memory estimate above the measured peak of every job (engine/run/budget.py must bound it).
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(script: str, *args: str, timeout: float) -> str:
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / script), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def _row(text: str, label: str) -> float:
    """The value of the row `label` of path_cost's plain table (its last column)."""
    line = next((ln for ln in text.splitlines() if ln.startswith(label)), None)
    assert line is not None, f"no row {label!r} in:\n{text}"
    return float(line.split()[-1])


def test_path_cost_prints_the_rays_and_cost_figures():
    text = _run("path_cost.py", "--baseline", "", "--repeats", "1", "--what", "rays,cost", timeout=300)
    for room in ("shadows cast", "empty room"):
        ratio = _row(text, f"rays, {room}: pipeline / raw Embree rays/s")
        assert 0.05 < ratio < 1.5, ratio  # the pipeline casts the raw rays and does more
        assert _row(text, f"rays, {room}: pipeline Mrays/s") > 0
    for room in ("clear", "smoky"):
        assert _row(text, f"cost per path, {room} room [us]") > 0
        assert 0 < _row(text, f"rel. std per path, {room} room") < 5
        assert 1e-7 < _row(text, f"H0, {room} room (fixed paths)") < 1e-5  # ~3e-6 for a 1 cm^2 receiver
    # smoke: more events per path than the clear room, and a noisier estimate per path
    assert _row(text, "rel. std per path, smoky room") > _row(text, "rel. std per path, clear room")


@pytest.mark.slow
def test_job_memory_estimate_bounds_every_measured_peak():
    text = _run("job_memory.py", timeout=900)
    rows = [ln for ln in text.splitlines()[1:] if re.search(r"\d+M\s+\d+M", ln)]
    assert len(rows) == 7, text
    for line in rows:
        estimate, measured = (float(x) for x in re.findall(r"(\d+)M", line)[:2])
        assert estimate >= measured, line
