"""Shared test fixtures (pytest loads this file for every test under the repository root).

`rng`: a fresh generator seeded with SEED for each test, so a test's draws do not depend on
which other tests ran before it (Mitsuba's `np_rng`).
"""

from __future__ import annotations

from pathlib import Path

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


#: The browser tests (issue 27): the only tests pytest-playwright's fixtures are for.
WEB_TESTS = Path(__file__).resolve().parent / "tests" / "web"


def pytest_configure(config: pytest.Config) -> None:
    _keep_playwright_to_the_web_tests(config)


def _keep_playwright_to_the_web_tests(config: pytest.Config) -> None:
    """pytest-playwright parametrizes by browser every test with a parameter named like its fixtures (`page`,
    `browser`, ...), also a test's own parameter (tests/test_docs.py's `page`: its ids became
    "[chromium-README.md]"). Its test generation is kept to tests/web; elsewhere the plugin is inert."""
    plugin = config.pluginmanager.get_plugin("playwright")
    for impl in config.hook.pytest_generate_tests.get_hookimpls():
        if plugin is not None and impl.plugin is plugin:
            generate = impl.function

            def only_web_tests(metafunc, generate=generate):
                if WEB_TESTS in Path(metafunc.definition.path).parents:
                    generate(metafunc)

            impl.function = only_web_tests
