"""Shared set-up of the benchmarks: the Barry room document and timing helpers."""

from __future__ import annotations

import json
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def barry_doc(**simulation) -> dict:
    doc = json.loads((ROOT / "examples" / "barry_config_a.json").read_text())
    doc["simulation"].update(simulation)
    return doc


def best_of(repeats: int, fn):
    """(best wall time [s], last return value) over `repeats` calls."""
    best, value = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - t)
    return best, value


def rss_mb(pid: int) -> float:
    """Resident memory of process `pid` [MB] (Linux /proc), 0 when it is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0
