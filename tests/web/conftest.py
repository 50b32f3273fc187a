"""Browser tests of the service's pages (issue 27): `owcsim serve` in a child process, driven by Playwright
in headless Chromium. Playwright's own browser downloads fail offline: the system's Chromium is used
(`apt-get install chromium`; CI installs it, see the README). Without it these tests fail, they do not skip.
"""

from __future__ import annotations

import os

import pytest

from tests.server.helpers import ServerProcess

#: The system's Chromium (Debian's package); OWCSIM_CHROMIUM overrides it.
CHROMIUM = os.environ.get("OWCSIM_CHROMIUM", "/usr/bin/chromium")
#: Two API keys: two tenants, each seeing only its own jobs.
KEYS = ("web-key-a", "web-key-b")
#: Flags for a closed network and a root user (no sandbox); without the background-networking ones Chromium
#: keeps trying to reach Google's hosts.
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args):
    """pytest-playwright's launch options with the system's Chromium."""
    return {**browser_type_launch_args, "executable_path": CHROMIUM, "args": CHROMIUM_ARGS, "headless": True}


@pytest.fixture(scope="module")
def web_server(tmp_path_factory):
    """A server with API keys on and its dispatcher running jobs; `.url` is its base address."""
    db = tmp_path_factory.mktemp("web") / "jobs.sqlite"
    with ServerProcess(db, api_keys=",".join(KEYS), progress_interval_s=0.1) as srv:
        yield srv
