import os

import pytest

from .helpers import app_client


@pytest.fixture(autouse=True)
def _no_settings_from_the_environment(monkeypatch):
    """The tests give every setting they need; OWCSIM_* variables of the shell must not leak in."""
    for name in [n for n in os.environ if n.startswith("OWCSIM_")]:
        monkeypatch.delenv(name)


@pytest.fixture
def api(tmp_path):
    """The app in-process, dispatcher off: jobs stay queued."""
    with app_client(tmp_path) as client:
        yield client


@pytest.fixture
def live(tmp_path):
    """The app in-process with its dispatcher: jobs run in worker processes."""
    with app_client(tmp_path, run_jobs=True) as client:
        yield client
