"""engine/core/allocator.py: after tune_allocator, numpy temporaries of the kernel's size reuse heap memory.

Measured by minor page faults (deterministic counts, not timings): a loop that allocates and frees
1.6 MB arrays faults every page in again under glibc's defaults (the power check: the same loop in a
process that skips the tuning), and almost never after the tuning.
"""

import os
import subprocess
import sys

import pytest

LOOP = """
import resource, numpy as np
from owcsim.engine.core.allocator import tune_allocator
applied = tune_allocator()
for _ in range(3):
    x = np.ones(200_000); y = x * 2.0; z = y + x; del x, y, z
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(40):
    x = np.ones(200_000); y = x * 2.0; z = y + x; del x, y, z
print(applied, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(extra_env: dict) -> tuple[bool, int]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")} | extra_env
    out = subprocess.run([sys.executable, "-c", LOOP], env=env, capture_output=True, text=True, check=True)
    applied, faults = out.stdout.split()
    return applied == "True", int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_tuned_heap_reuses_pages():
    applied, faults = _faults({})
    if not applied:
        pytest.skip("mallopt not available (not glibc)")
    # 40 rounds x 3 arrays x 1.6 MB = 4.7e4 pages if every array were faulted in again
    assert faults < 2_000
    # power check: glibc's defaults (the tuning skips itself when MALLOC_* variables are set)
    skipped, untuned = _faults({"MALLOC_ARENA_MAX": "8"})
    assert not skipped
    assert untuned > 10 * max(faults, 100)


def test_tune_allocator_once():
    from owcsim.engine.core.allocator import tune_allocator

    tune_allocator()
    assert tune_allocator() is False  # a second call does nothing
