import os

import pytest


@pytest.fixture(autouse=True)
def _no_settings_from_the_environment(monkeypatch):
    """OWCSIM_* variables of the shell (server settings, a client's key) must not leak into the tests."""
    for name in [n for n in os.environ if n.startswith("OWCSIM_")]:
        monkeypatch.delenv(name)
