"""Shared test fixtures (pytest loads this file for every test under the repository root).

`rng`: a fresh generator seeded with SEED for each test, so a test's draws do not depend on
which other tests ran before it (Mitsuba's `np_rng`).
"""

from __future__ import annotations

import numpy as np
import pytest

#: The seed of every test's `rng` (tests that need several streams derive them from it).
SEED = 12345


def seeded_rng() -> np.random.Generator:
    """A generator seeded with SEED (for helpers called outside a fixture)."""
    return np.random.default_rng(SEED)


@pytest.fixture
def rng() -> np.random.Generator:
    return seeded_rng()
